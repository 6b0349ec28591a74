"""Which layer costs the flat FLIP: the denoised diffuse, specular or alpha put into the noisy frame one at a time
(the beauty rebuilt from the layers), scored against the reference, over one family's deep-Z scenes of a set.
usage: layer_swap.py SET SPP FAMILY [MODEL]   (rows: mean, then per scene)"""
import sys, json
import numpy as np
from pathlib import Path
from ranad_core.exr import read_deep
from ranad_core import metrics
from ranad_core.denoise import denoise_window
from ranad_core.model.store import load_model
root, spp, fam = Path(sys.argv[1]), sys.argv[2], sys.argv[3]
m = load_model(sys.argv[4] if len(sys.argv) > 4 else None).model
acc = {}
for sc in sorted(root.glob("scene_*")):
    if json.loads((sc / "manifest.json").read_text())["preset"] != fam:
        continue
    noisy = read_deep(sc / f"deepz/noisy_spp{spp}.0000.exr"); ref = read_deep(sc / f"deepz/reference_spp{spp}.0000.exr")
    out = denoise_window(m, [noisy], 0).image
    ch = out.channels
    fr = metrics.flat_rgb(ref)
    def mix(take):  # take: set of layers from ranad; others noisy; beauty rebuilt
        v = noisy.values.astype(np.float64).copy()
        for lay in take:
            cols = [c for c in ch if c.startswith(lay + ".")] if lay != "A" else ["A"]
            for c in cols:
                v[:, ch.index(c)] = out.channel(c)
        parts = ("diffuse", "specular", "emission")
        for c in "RGB":
            rest = noisy.channel(c) - sum(noisy.channel(f"{p}.{c}") for p in parts)   # what the split leaves out
            v[:, ch.index(c)] = sum(v[:, ch.index(f"{p}.{c}")] for p in parts) + rest
        return noisy.with_values(v.astype(np.float32))
    for name, take in (("noisy", ()), ("diff", ("diffuse",)), ("spec", ("specular",)), ("alpha", ("A",)),
                       ("diff+spec", ("diffuse", "specular")), ("all", ("diffuse", "specular", "A"))):
        acc.setdefault(name, []).append(metrics.flip(fr, metrics.flat_rgb(mix(take))))
    acc.setdefault("ranad", []).append(metrics.flip(fr, metrics.flat_rgb(out)))
for k, v in acc.items():
    print(f"{k:10s} {np.mean(v):.4f}  " + " ".join(f"{x:.3f}" for x in v))
