"""The bundled example frame (examples/synth_shot, 16 spp): flat HDR-FLIP of the noisy input and of the default
model with darkness off and on. usage: python runs/dark-s16/example.py"""
from pathlib import Path

import flip_evaluator
import numpy as np

from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.metrics import flat_rgb
from ranad_core.model.store import load_model

shot = Path(__file__).resolve().parents[2] / "examples" / "synth_shot"
noisy = read_deep(shot / "noisy_spp16.0001.exr")
ref = np.ascontiguousarray(flat_rgb(read_deep(shot / "reference_spp16.0001.exr")), np.float32)
model = load_model(None).model


def flip(img):
    return float(flip_evaluator.evaluate(ref, np.ascontiguousarray(np.maximum(img, 0), np.float32), "HDR",
                                         applyMagma=False)[1])


print(f"noisy {flip(flat_rgb(noisy)):.4f}")
for radius in (0, 1):
    print(f"--dark-radius {radius}: {flip(flat_rgb(denoise_window(model, [noisy], 0, dark_radius=radius).image)):.4f}")
