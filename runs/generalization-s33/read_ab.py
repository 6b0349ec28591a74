"""Session 33 (issue 27): the deep reader with the predictor's undo in torch (the default where torch is loaded)
against numpy's (the codec's path without torch), alternating in one process under the command line's allocator
and thread policy; each read timed whole (decode threads included), and the write once per round for reference.
Usage: python read_ab.py FRAME.exr [ROUNDS]"""
import importlib
import sys
import time

importlib.import_module("ranad_cli.main")   # the CLI's allocator and thread policy, as `ranad denoise` runs
import torch  # noqa: E402

from ranad_core.exr import compression, read_deep


def timed_read(path: str) -> float:
    t = time.perf_counter()
    read_deep(path)
    return time.perf_counter() - t


def main() -> None:
    path, rounds = sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 5
    timed_read(path)   # warm: the file in the page cache, the heap grown
    res = {"torch": [], "numpy": []}
    for _ in range(rounds):
        for name, fn in (("torch", lambda: torch), ("numpy", lambda: None)):
            compression._torch = fn
            res[name].append(timed_read(path))
    for name, ts in res.items():
        ts = sorted(ts)
        print(f"{name}: min {ts[0]:.3f} s, median {ts[len(ts) // 2]:.3f} s, max {ts[-1]:.3f} s ({len(ts)} reads)")


if __name__ == "__main__":
    main()
