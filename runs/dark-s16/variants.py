"""Which black neighbourhoods to keep black: the default model's flat HDR-FLIP per family and spp, with no rule and
with rule variants applied to its output (pixel masks on the flattened image, which is what ranad_core.darkness
does per bin: every bin of a kept pixel keeps its noisy colour, 0).

Variants: `off`; `rR`: the pixel's (2R+1)^2 window exactly black; `KkSs`: r1 and no speck within s pixels, a speck
being a lit pixel with at least k of its 8 neighbours black; `KkSswW`: the same with a (2W+1)^2 window (w0: the
pixel alone); `KkSsgG`: KkSs grown G times by one pixel into black pixels with no speck within s (gf: until it
stops growing). The shipped rule is K7S3g1: every pixel of a black 3x3 window whose centre, and itself, have no
speck within 3 px.
usage: python runs/dark-s16/variants.py SET KIND [VARIANT,...]   (SET: a `ranad synth` folder; KIND: deepz, deepoid)
"""
import json
import sys
from pathlib import Path

import flip_evaluator
import numpy as np

from ranad_core import metrics
from ranad_core.darkness import _box_sum   # the rule's own window counts (clipped to the image)
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

root, kind = Path(sys.argv[1]), sys.argv[2]
names = sys.argv[3].split(",") if len(sys.argv) > 3 else ["off", "r1", "r2", "K7S2", "K7S3", "K7S4", "K8S3", "K7S3w0",
                                                           "K7S3g1", "K7S3g2", "K7S3gf"]
model = load_model(None).model


def flip(ref, test):
    ref32, test32 = (np.ascontiguousarray(np.maximum(x, 0), np.float32) for x in (ref, test))
    return float(flip_evaluator.evaluate(ref32, test32, "HDR", applyMagma=False)[1])


def mask(name, lit):
    if name == "off":
        return np.zeros_like(lit)
    if name.startswith("r"):
        return _box_sum(lit, int(name[1:])) == 0
    grow = None
    if "g" in name:
        name, grow = name.split("g")
    w = int(name.split("w")[1]) if "w" in name else 1
    k, s = (int(x) for x in name.split("w")[0][1:].split("S"))
    speck = lit & (_box_sum(~lit, 1) - ~lit >= k)
    calm = _box_sum(speck, s) == 0
    m = (_box_sum(lit, w) == 0) & calm
    for _ in range(10 ** 6 if grow == "f" else int(grow or 0)):
        grown = ~lit & calm & (_box_sum(m, 1) > 0)
        if (grown == m).all():
            break
        m = grown
    return m


res = {}
for scene in sorted(root.glob("scene_*")):
    fam = json.loads((scene / "manifest.json").read_text())["preset"]
    for spp in (4, 16, 64):
        noisy = read_deep(scene / f"{kind}/noisy_spp{spp}.0000.exr")
        ref = metrics.flat_rgb(read_deep(scene / f"{kind}/reference_spp{spp}.0000.exr"))
        nf = metrics.flat_rgb(noisy)
        out = metrics.flat_rgb(denoise_window(model, [noisy], 0, dark_radius=0).image)
        lit = (nf != 0).any(-1)
        r = {"noisy": flip(ref, nf)}
        r.update({n: flip(ref, np.where(mask(n, lit)[..., None], 0, out)) for n in names})
        res.setdefault((fam, spp), []).append(r)
print("| family | spp | scenes | " + " | ".join(res[next(iter(res))][0]) + " |")
print("|---|---|---|" + "---|" * len(res[next(iter(res))][0]))
for (fam, spp), rows in sorted(res.items()):
    print(f"| {fam} | {spp} | {len(rows)} | " + " | ".join(f"{np.mean([x[m] for x in rows]):.4f}" for m in rows[0])
          + " |")
