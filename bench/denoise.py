"""End-to-end `ranad denoise` time and peak memory on a 1920x1080 deep frame and on a real file.

The 1080p frame is a render from ranad's own generator (a deep-heavy scene, 128x128, 16 spp, seed 7; about
3 bins per pixel) tiled to 1920x1080, so its bins, channels and noise are those of a real render. Every run is
a separate `ranad denoise` process (model load, read, denoise, write), so the peak memory is the process's. The
same run measures two baselines on the same frame: reading and writing it without denoising (the I/O floor),
and flat OIDN on the flattened frame (what a flat denoiser costs).

Usage: python bench/denoise.py [--threads 2] [--real ../shared/data/deep-real/LeftView_Trunks.exr] [--model M]
           [--frame SRC.exr] [--args "--max-memory 4G" --args "--halo 16" ...] [--device cuda]
`--frame` tiles that deep frame to 1920x1080 instead of rendering one (e.g. a held-out 16-spp deep-Z frame of
`ranad synth --preset glass`); each `--args` adds one more `ranad denoise` run with those options (peak memory
and time side by side with the default run; `--profile` in them prints the stage table). `--device cuda` runs
ranad and the flat OIDN baseline on the GPU.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
sys.path.insert(0, ROOT)
from ranad_core.deep import DeepImage, gather_bins  # noqa: E402
from ranad_core.exr import read_deep, write_deep  # noqa: E402

RUNNER = """
import json, resource, sys, time
t = time.perf_counter()
code = 0
try:
    exec(sys.argv[1])
except SystemExit as e:
    code = e.code or 0
# VmHWM: this process's peak (ru_maxrss would carry over the parent's from before the exec)
hwm = [int(l.split()[1]) for l in open("/proc/self/status") if l.startswith("VmHWM")]
peak = hwm[0] / 1024 if hwm else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
print(json.dumps({"seconds": time.perf_counter() - t, "peak_mb": peak, "code": code}), file=sys.stderr)
"""


def run_measured(code: str, *args: str, threads: int) -> dict:
    # the baselines run under the numpy page and BLAS-thread policy ranad's command line sets for itself
    # (ranad_cli/main.py)
    env = dict(os.environ, OMP_NUM_THREADS=str(threads),
               NUMPY_MADVISE_HUGEPAGE=os.environ.get("NUMPY_MADVISE_HUGEPAGE", "0"),
               OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    p = subprocess.run([sys.executable, "-c", RUNNER, code, *args], capture_output=True, text=True, env=env, cwd=ROOT)
    last = [ln[ln.index('{"seconds"'):] for ln in p.stderr.splitlines() if '{"seconds"' in ln]  # after tqdm's codes
    if p.returncode or not last:
        raise SystemExit(f"run failed:\n{p.stdout}\n{p.stderr}")
    res = json.loads(last[-1])
    if res["code"]:
        raise SystemExit(f"run exited {res['code']}:\n{p.stdout}\n{p.stderr}")
    res["output"] = p.stdout
    return res


def tile_to(img: DeepImage, width: int, height: int) -> DeepImage:
    """`img` repeated to width x height (cropped at the right and bottom edges)."""
    w, h = img.width, img.height
    ys, xs = np.divmod(np.arange(width * height), width)
    src = (ys % h) * w + (xs % w)
    counts = img.counts[src]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    rows = np.repeat(img.offsets[:-1][src] - offsets[:-1], counts) + np.arange(offsets[-1])
    out = gather_bins(img, rows, offsets, (0, 0, width - 1, height - 1))
    out.display_window = (0, 0, width - 1, height - 1)
    return out


def make_1080p(folder: str, source: str | None = None) -> str:
    path = os.path.join(folder, "frame1080.exr")
    if source:
        write_deep(path, tile_to(read_deep(source), 1920, 1080))
        return path
    from ranad_core.synth import dataset

    cfg = dataset.SynthConfig(out=os.path.join(folder, "synth"), scenes=1, size=128, frames=1, spp=(16,),
                              ref_spp=16, seed=7, presets=("deep-heavy",), kinds=("deepz",))
    dataset.run(cfg, 1)
    src = read_deep(os.path.join(folder, "synth", "scene_0000", "deepz", "noisy_spp16.0000.exr"))
    write_deep(path, tile_to(src, 1920, 1080))
    return path


DENOISE = "from ranad_cli.main import main; sys.argv = ['ranad', 'denoise', *sys.argv[2:]]; main()"
IO_ONLY = ("from ranad_core.exr import read_deep, write_deep; img = read_deep(sys.argv[2]); "
           "write_deep(sys.argv[3], img)")
FLAT = ("import numpy as np, pyoidn; from ranad_core.exr import read_deep; from ranad_core import metrics; "
        "img = read_deep(sys.argv[2]); flat = np.ascontiguousarray(metrics.flat_rgb(img), np.float32); ")
OIDN = FLAT + "pyoidn.denoise(np.maximum(flat, 0), hdr=True)"
# flat OIDN on the GPU (pyoidn's CUDA device takes torch CUDA tensors), the upload and download included
OIDN_CUDA = FLAT + "import torch; pyoidn.denoise(torch.from_numpy(np.maximum(flat, 0)).cuda(), hdr=True).cpu()"


def bench(path: str, label: str, folder: str, threads: int, model: str | None, variants=(), device="cpu") -> None:
    img = read_deep(path)
    out = os.path.join(folder, "out.exr")
    args = [path, "-o", out, "--threads", str(threads), "--device", device] + (["--model", model] if model else [])
    den = run_measured(DENOISE, *args, threads=threads)
    others = []
    for v in variants:  # a variant may be refused (a --max-memory too small for the frame): its error is the result
        try:
            others.append((v, run_measured(DENOISE, *args, *v.split(), threads=threads)))
        except SystemExit as e:
            lines = [ln for ln in str(e).splitlines() if "ranad: error:" in ln]
            others.append((v, {"error": lines[-1].split("ranad: error:", 1)[1].strip() if lines else str(e)[-300:]}))
    io = run_measured(IO_ONLY, path, os.path.join(folder, "io.exr"), threads=threads)
    try:
        import pyoidn  # noqa: F401
        oidn = run_measured(OIDN_CUDA if device == "cuda" else OIDN, path, threads=threads)
    except ImportError:
        oidn = None
    print(f"\n{label}: {img.width}x{img.height}, {img.num_bins} bins ({img.num_bins / img.num_pixels:.2f}/pixel), "
          f"{len(img.channels)} channels, {threads} threads, device {device}")
    print(f"  ranad denoise     {den['seconds']:7.1f} s   peak {den['peak_mb']:7.0f} MB")
    print(f"  read+write only   {io['seconds']:7.1f} s   peak {io['peak_mb']:7.0f} MB   "
          f"(denoise = {den['seconds'] / io['seconds']:.1f}x the I/O floor)")
    if oidn:
        print(f"  flat OIDN         {oidn['seconds']:7.1f} s   peak {oidn['peak_mb']:7.0f} MB   "
              f"(denoise = {den['seconds'] / oidn['seconds']:.1f}x flat OIDN incl. read)")
    print(f"  {1e6 * den['seconds'] / max(img.num_bins, 1):.1f} us per bin end to end")
    for v, r in others:
        if "error" in r:
            print(f"  ranad denoise {v}: refused: {r['error']}")
            continue
        ratio = f"   ({r['seconds'] / oidn['seconds']:.1f}x flat OIDN)" if oidn else ""
        print(f"  ranad denoise {v}: {r['seconds']:7.1f} s   peak {r['peak_mb']:7.0f} MB{ratio}")
        if "| stage |" in r["output"]:
            print("    " + r["output"][r["output"].index("| stage |"):].strip().replace("\n", "\n    "))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--real", default=os.path.join(ROOT, "..", "shared", "data", "deep-real", "LeftView_Trunks.exr"))
    ap.add_argument("--model", default=None)
    ap.add_argument("--skip-1080p", action="store_true")
    ap.add_argument("--frame", default=None, help="a deep frame to tile to 1080p instead of rendering one")
    ap.add_argument("--args", action="append", default=[], help="options of one more ranad denoise run")
    ap.add_argument("--device", choices=("cpu", "cuda"), default="cpu",
                    help="where ranad denoise and the flat OIDN baseline run")
    a = ap.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        if not a.skip_1080p:
            t = time.perf_counter()
            path = make_1080p(folder, a.frame)
            print(f"made the 1080p frame in {time.perf_counter() - t:.1f} s")
            label = f"1080p tiled from {a.frame}" if a.frame else "1080p synth (deep-heavy, 16 spp)"
            bench(path, label, folder, a.threads, a.model, a.args, a.device)
        if a.real and os.path.isfile(a.real):
            bench(a.real, os.path.basename(a.real), folder, a.threads, a.model, a.args, a.device)


if __name__ == "__main__":
    main()
