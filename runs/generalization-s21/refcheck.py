"""Flat FLIP of the noisy input, flat OIDN and the default model against a 1024-spp and an 8192-spp reference of one
scene, and the two references against each other (is the glass family's score bound by its reference's noise?).

Usage: python runs/generalization-s21/refcheck.py SCENE_1024 SCENE_8192 [MODEL] (scene folders, 16-spp deep-Z files;
the second rendered by the first's `ranad synth` command with `--spp 16 --ref-spp 8192 --scenes 1`)
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core.exr import read_deep
from ranad_core.metrics import deep_scores, flat_rgb, flip
from ranad_core.baselines import oidn_flat
from ranad_core.model.store import load_model
from ranad_core.denoise import denoise_frame
a, b = sys.argv[1], sys.argv[2]   # scene folders (1024-spp ref, 8192-spp ref), deepz, 16 spp
noisy = read_deep(f"{a}/deepz/noisy_spp16.0000.exr")
r1 = read_deep(f"{a}/deepz/reference_spp16.0000.exr")
r8 = read_deep(f"{b}/deepz/reference_spp16.0000.exr")
out = denoise_frame(load_model(sys.argv[3] if len(sys.argv) > 3 else None).model, noisy).image
oi = oidn_flat(noisy)
f1, f8 = flat_rgb(r1), flat_rgb(r8)
print("ref1024 vs ref8192", round(flip(f8, f1), 4))
for name, img in (("noisy", flat_rgb(noisy)), ("oidn", np.asarray(oi)), ("ranad", flat_rgb(out))):
    print(name, "vs ref1024", round(flip(f1, img), 4), "vs ref8192", round(flip(f8, img), 4))
for name, img in (("noisy", noisy), ("ranad", out)):
    print("edit", name, "vs ref1024", round(deep_scores(r1, img)["comp_flip"], 4), "vs ref8192",
          round(deep_scores(r8, img)["comp_flip"], 4))
print("edit ref1024 vs ref8192", round(deep_scores(r8, r1)["comp_flip"], 4))
