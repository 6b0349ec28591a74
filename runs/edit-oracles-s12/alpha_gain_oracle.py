"""Potential of a per-bin alpha gain: model alpha times a per-class factor (class: single / front / mid / last
bin of multi-bin pixels), factors fitted as ref-mean/model-mean on a fitting set, applied on a test set.

Usage: python runs/edit-oracles-s12/alpha_gain_oracle.py FIT_SET TEST_SET [MODEL]   (deep-Z, 16 spp)"""
import sys
import numpy as np
from ranad_core.channels import ALPHA
from ranad_core.metrics import composite_edit, flip, split_depth
from ranad_core.model.store import load_model

from common import scenes
model = load_model(sys.argv[3] if len(sys.argv) > 3 else "cpu-small-pd-v4").model
CLASSES = ("single", "front", "mid", "last")

def classes(img):
    cnt = np.repeat(np.diff(img.offsets), np.diff(img.offsets)); bi = img.bin_index()
    return {"single": cnt == 1, "front": (cnt > 1) & (bi == 0), "mid": (cnt > 1) & (bi > 0) & (bi < cnt - 1),
            "last": (cnt > 1) & (bi == cnt - 1)}

def run(dataset, spp="16", kind="deepz"):
    return [(noisy, ref, out, base) for _, noisy, ref, out, base, _ in scenes(dataset, model, spp, kind)]

def fit(res):
    num = {c: 0.0 for c in CLASSES}; den = {c: 0.0 for c in CLASSES}
    for noisy, ref, out, base in res:
        for c, m in classes(ref).items():
            num[c] += ref.channel(ALPHA)[m].sum(); den[c] += out.channel(ALPHA)[m].sum()
    return {c: num[c] / max(den[c], 1e-9) for c in CLASSES}

def score(res, f):
    tot = {}
    for noisy, ref, out, base in res:
        v = out.values.copy(); a = out.channel(ALPHA).copy()
        for c, m in classes(ref).items():
            a[m] = np.clip(a[m] * f[c], 0, 1)
        v[:, out.channels.index(ALPHA)] = a
        z = split_depth(ref); t = composite_edit(ref, z)
        row = {"recolour": flip(t, composite_edit(base, z)), "model": flip(t, composite_edit(out, z)),
               "gain": flip(t, composite_edit(out.with_values(v), z))}
        for k, x in row.items(): tot[k] = tot.get(k, 0) + x
    r = tot["recolour"]
    return " | ".join(f"{k} {x/len(res):.4f} ({x/r:.3f}x)" for k, x in tot.items())

a, b = run(sys.argv[1]), run(sys.argv[2])
fa, fb = fit(a), fit(b)
print("factors fitted on", sys.argv[1], {k: round(v, 3) for k, v in fa.items()})
print("factors fitted on", sys.argv[2], {k: round(v, 3) for k, v in fb.items()})
print(sys.argv[2], "with", sys.argv[1], "factors:", score(b, fa))
print(sys.argv[2], "with own factors:", score(b, fb))
print(sys.argv[1], "with", sys.argv[2], "factors:", score(a, fb))
