"""Holdout objects in ranad's own sets (runs/dark-s16/README.md, section 2): for every deep-OID noisy file of the
given sets, the objects with no lit bin (darkness.holdout_bins), and the default's flat HDR-FLIP with the whole rule
against the rule without its holdout part (those bins' colours as with --dark-radius 0).
usage: python runs/dark-s16/holdouts.py SET [SET ...]"""
import sys
from dataclasses import replace
from pathlib import Path

import flip_evaluator
import numpy as np

from ranad_core import darkness, metrics
from ranad_core.channels import detect
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

model = load_model(None).model


def flip(ref, img):
    return float(flip_evaluator.evaluate(np.ascontiguousarray(ref, np.float32),
                                         np.ascontiguousarray(np.maximum(metrics.flat_rgb(img), 0), np.float32),
                                         "HDR", applyMagma=False)[1])


files = sorted(f for s in sys.argv[1:] for f in Path(s).glob("scene_*/deepoid/noisy_spp*.0000.exr"))
found = 0
for path in files:
    noisy = read_deep(path)
    m = detect(noisy)
    lit = darkness._lit_bins(noisy.values, [noisy.channel_index(c) for c in darkness.colour_channels(m)])
    held = darkness.holdout_bins(noisy, lit)
    if held is None:
        continue
    found += 1
    ref = metrics.flat_rgb(read_deep(str(path).replace("noisy_", "reference_")))
    on = denoise_window(model, [noisy], 0).image
    off = denoise_window(model, [noisy], 0, dark_radius=0).image
    windows = darkness.dark_bins(replace(noisy, ids={}), m)   # the rule without ids: its windows alone
    only_held = held if windows is None else held & ~windows
    vals = on.values.copy()
    vals[only_held] = off.values[only_held]
    print(f"{path}: {int(held.sum())} holdout bins; flat FLIP {flip(ref, on):.4f} with the whole rule, "
          f"{flip(ref, on.with_values(vals)):.4f} without its holdout part")
print(f"{found} of {len(files)} deep-OID files have an object with no lit bin")
