"""Deep EXR I/O speed: ranad's fast codec vs OpenImageIO's Python path, in the same run.

Generates a deep frame (default 1920x1080, ~3 bins per pixel, 15 half/float channels + 1 uint id), writes
and reads it both ways, checks that all four files decode to the same data, and prints times and ratios.
Usage: python bench/io.py [--width 1920 --height 1080 --bins 3]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
from ranad_core.deep import DeepImage  # noqa: E402
from ranad_core.exr import read_deep, write_deep  # noqa: E402

CHANNELS = ["R", "G", "B", "A", "Z", "ZBack", "diffuse.R", "diffuse.G", "diffuse.B",
            "specular.R", "specular.G", "specular.B", "albedo.R", "albedo.G", "albedo.B"]


def make_frame(width: int, height: int, mean_bins: float, seed: int = 0) -> DeepImage:
    """A render-like deep frame: smooth colour fields plus noise, 0..2*mean bins per pixel, sorted depths."""
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, int(2 * mean_bins) + 1, size=width * height)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    n = int(offsets[-1])
    pix = np.repeat(np.arange(width * height), counts)
    b = np.arange(n) - np.repeat(offsets[:-1], counts)
    y, x = np.divmod(pix, width)
    base = 0.5 + 0.4 * np.sin(x / 97.0)[:, None] * np.cos(y / 61.0)[:, None]
    values = np.empty((n, len(CHANNELS)), dtype=np.float32)
    values[:] = (base * rng.uniform(0.5, 1.5, size=(n, len(CHANNELS)))).astype(np.float32)
    values[:, 3] = rng.uniform(0.2, 1.0, size=n)
    values[:, 4] = 1.0 + b + 0.01 * x / width
    values[:, 5] = values[:, 4] + 0.5
    types = {c: ("float" if c in ("Z", "ZBack") else "half") for c in CHANNELS}
    ids = {"id": (pix % 7 + b * 11).astype(np.uint32)}
    return DeepImage(values=values, offsets=offsets, channels=CHANNELS, ids=ids,
                     data_window=(0, 0, width - 1, height - 1), channel_types=types)


def timed(fn):
    t = time.perf_counter()
    out = fn()
    return out, time.perf_counter() - t


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--width", type=int, default=1920)
    ap.add_argument("--height", type=int, default=1080)
    ap.add_argument("--bins", type=float, default=3.0)
    args = ap.parse_args()
    img = make_frame(args.width, args.height, args.bins)
    # half channels are what the file will hold: round once so every decode is comparable bit for bit
    for j, c in enumerate(img.channels):
        if img.channel_types[c] == "half":
            img.values[:, j] = img.values[:, j].astype(np.float16).astype(np.float32)
    n, c = img.num_bins, len(img.channels) + len(img.ids)
    print(f"frame {args.width}x{args.height}, {n} samples ({n / img.num_pixels:.2f}/pixel), {c} channels, "
          f"{os.cpu_count()} CPUs")
    with tempfile.TemporaryDirectory() as d:
        fast_path, oiio_path = os.path.join(d, "fast.exr"), os.path.join(d, "oiio.exr")
        _, t_fast_w = timed(lambda: write_deep(fast_path, img, io="fast"))
        _, t_oiio_w = timed(lambda: write_deep(oiio_path, img, io="oiio"))
        a, t_fast_r = timed(lambda: read_deep(oiio_path, io="fast"))
        b, t_oiio_r = timed(lambda: read_deep(fast_path, io="oiio"))
        for other in (a, b):
            assert np.array_equal(other.offsets, img.offsets)
            for name in img.channels:
                assert np.array_equal(other.channel(name).view(np.uint32), img.channel(name).view(np.uint32))
            assert np.array_equal(other.ids["id"], img.ids["id"])
        sizes = os.path.getsize(fast_path), os.path.getsize(oiio_path)
    print(f"{'':6s} {'ranad fast':>12s} {'OpenImageIO':>12s} {'ratio':>8s}")
    print(f"{'write':6s} {t_fast_w:11.2f}s {t_oiio_w:11.2f}s {t_oiio_w / t_fast_w:7.1f}x"
          f"   ({n / t_fast_w / 1e6:.2f} vs {n / t_oiio_w / 1e6:.2f} M samples/s)")
    print(f"{'read':6s} {t_fast_r:11.2f}s {t_oiio_r:11.2f}s {t_oiio_r / t_fast_r:7.1f}x"
          f"   ({n / t_fast_r / 1e6:.2f} vs {n / t_oiio_r / 1e6:.2f} M samples/s)")
    print(f"file size: ranad {sizes[0] / 1e6:.1f} MB, OpenImageIO {sizes[1] / 1e6:.1f} MB; all decodes bit-exact")


if __name__ == "__main__":
    main()
