"""Session 32: where the shipped default's error lies on a held-out set's frames, against flat OIDN's: the mean
absolute error of the tone-mapped flat colour (x / (1 + x)) against the reference in single-bin and multi-bin pixels,
and ranad's flat FLIP / OIDN's per scene from an evaluation of the same files, side by side.

Usage: python pixels.py SET SPP EVAL_FOLDER   (run in the data folder; denoises each scene's deep-Z frame with the
       default model into a temporary folder)"""
import csv
import os
import subprocess
import sys
import tempfile

import numpy as np

from ranad_core import baselines
from ranad_core.exr import read_deep
from ranad_core.metrics import flat_rgb


def tonemapped(x: np.ndarray) -> np.ndarray:
    x = np.clip(x[..., :3], 0, None)
    return x / (1 + x)


def main() -> None:
    folder, spp, ev = sys.argv[1], sys.argv[2], sys.argv[3]
    flip = {}
    with open(os.path.join(ev, "eval.csv")) as f:
        for r in csv.DictReader(f):
            if r["kind"] == "deepz" and r["exposure"] == "0" and r["spp"] == spp:
                flip.setdefault(r["scene"], {})[r["method"]] = float(r["flip"])
    print("| scene | flat FLIP ratio | L1 ratio, 1-bin pixels | L1 ratio, 2+ bins | 2+-bin pixels | their share of "
          "ranad's L1 |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for scene in sorted(d for d in os.listdir(folder) if d.startswith("scene_")):
            src = os.path.join(folder, scene, "deepz")
            noisy_path = os.path.join(src, f"noisy_spp{spp}.0000.exr")
            out = os.path.join(tmp, f"{scene}.exr")
            subprocess.run(["ranad", "denoise", noisy_path, "-o", out], check=True, capture_output=True)
            noisy = read_deep(noisy_path)
            ref = tonemapped(flat_rgb(read_deep(os.path.join(src, f"reference_spp{spp}.0000.exr"))))
            er = np.abs(tonemapped(flat_rgb(read_deep(out))) - ref).mean(-1)
            eo = np.abs(tonemapped(baselines.oidn_flat(noisy)) - ref).mean(-1)
            multi = (np.diff(noisy.offsets) >= 2).reshape(er.shape)
            one = (np.diff(noisy.offsets) == 1).reshape(er.shape)
            fr = flip.get(scene, {})
            ratio = f"{fr['ranad'] / fr['oidn']:.3f}" if "ranad" in fr and "oidn" in fr else "n/a"
            print(f"| {scene} | {ratio} | {er[one].mean() / eo[one].mean():.3f} | "
                  f"{er[multi].mean() / eo[multi].mean():.3f} | {int(multi.sum())} | "
                  f"{er[multi].sum() / er.sum():.2f} |")


if __name__ == "__main__":
    main()
