"""Cross-frame cost per frame: `ranad denoise` on a shot with the cross-frame model against the single-frame model,
in the same run (issue 27's "cross-frame per-frame cost <= 1.5x single-frame").

The shot is the bundled example's three frames (`examples/synth_shot`, with per-bin motion) tiled to --size and
played forth and back (0 1 2 1 0) so that most frames have a full window of three; the motion of the returning
frames points the wrong way, which changes what the temporal step finds but not what it costs. Every run is a
separate `ranad denoise` process over the whole shot (model load, reads, denoise, writes); the ratio is of the
whole runs, so the per-shot overheads count too. With --repeat N the models run in N interleaved rounds (single,
cross, ..., single, cross, ...) and each model's median is used: one run each was at the mercy of the order
(the first run of a process tree pays for cold caches; this machine's runs vary by 20%).

Usage: python bench/shot.py [--size 960x540] [--threads 2] [--single MODEL] [--cross MODEL]
           [--cross ANOTHER ...] [--repeat 3] [--args "--profile"]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from denoise import DENOISE, run_measured, tile_to  # noqa: E402

from ranad_core.exr import read_deep, write_deep  # noqa: E402
from ranad_core.model.store import DEFAULT_CROSS_MODEL, DEFAULT_MODEL  # noqa: E402

SHOT = os.path.join(ROOT, "examples", "synth_shot", "noisy_spp16.{:04d}.exr")
ORDER = (0, 1, 2, 1, 0)


def make_shot(folder: str, width: int, height: int) -> str:
    for k, src in enumerate(ORDER):
        write_deep(os.path.join(folder, f"shot.{k:04d}.exr"), tile_to(read_deep(SHOT.format(src)), width, height))
    return os.path.join(folder, "shot.####.exr")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", default="960x540")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--single", default=DEFAULT_MODEL, help="default: the shipped single-frame default")
    ap.add_argument("--cross", action="append", default=[], help="default: the shipped cross-frame default")
    ap.add_argument("--repeat", type=int, default=3, help="interleaved rounds; each model's median counts")
    ap.add_argument("--args", default="", help="options added to every ranad denoise run (e.g. --profile)")
    a = ap.parse_args()
    width, height = (int(v) for v in a.size.lower().split("x"))
    crosses = a.cross or [DEFAULT_CROSS_MODEL]
    with tempfile.TemporaryDirectory() as folder:
        t = time.perf_counter()
        pattern = make_shot(folder, width, height)
        img = read_deep(pattern.replace("####", "0001"))
        print(f"made the shot ({len(ORDER)} frames, {img.width}x{img.height}, {img.num_bins} bins per frame) in "
              f"{time.perf_counter() - t:.1f} s")

        def run(model: str, tag: str) -> dict:
            out = os.path.join(folder, tag, "d.####.exr")
            res = run_measured(DENOISE, pattern, "-o", out, "--model", model, "--threads", str(a.threads),
                               *a.args.split(), threads=a.threads)
            if "| stage |" in res["output"]:
                print(f"  {model}:\n    " + res["output"][res["output"].index("| stage |"):].strip()
                      .replace("\n", "\n    "))
            return res

        models = [(a.single, "single")] + [(m, f"cross{k}") for k, m in enumerate(crosses)]
        runs = {tag: [] for _, tag in models}
        for _ in range(max(1, a.repeat)):
            for model, tag in models:
                runs[tag].append(run(model, tag))
        seconds = {tag: statistics.median(r["seconds"] for r in rs) for tag, rs in runs.items()}
        peak = {tag: max(r["peak_mb"] for r in rs) for tag, rs in runs.items()}
        each = lambda tag: " / ".join(f"{r['seconds']:.1f}" for r in runs[tag])  # noqa: E731
        single = seconds["single"]
        print(f"  single-frame {a.single}: median {single:7.1f} s ({single / len(ORDER):.1f} s per frame; runs "
              f"{each('single')} s), peak {peak['single']:.0f} MB")
        for model, tag in models[1:]:
            s = seconds[tag]
            print(f"  cross-frame {model}: median {s:7.1f} s ({s / len(ORDER):.1f} s per frame, {s / single:.2f}x "
                  f"single-frame; runs {each(tag)} s), peak {peak[tag]:.0f} MB")


if __name__ == "__main__":
    main()
