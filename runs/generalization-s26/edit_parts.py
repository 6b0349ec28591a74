"""What the compositing edit's error is made of (session 26): per scene and spp of a set's deep-Z frames, edit FLIP
(metrics.composite_edit at the scores' split depth) of the noisy input and of ranad's output, each as it is, with
the reference's alpha put in (its error from colour alone) and with the reference's colour put in (from alpha
alone; premultiplied R, G, B taken from the reference bin). Means per family and spp.
Usage: python edit_parts.py SET [MODEL]"""
import sys
from collections import defaultdict

import numpy as np

from ranad_core import metrics
from ranad_core.channels import ALPHA, RGB
from ranad_core.denoise import denoise_window
from ranad_core.evaluate import scene_family
from edit_frames import deepz_frames, model_from_argv


def with_from(img, ref, names):
    """`img` with channels `names` taken from `ref` (same bin layout)."""
    vals = img.values.copy()
    for c in names:
        vals[:, img.channels.index(c)] = ref.channel(c)
    return img.with_values(vals)


root = sys.argv[1]
model = model_from_argv()
acc = defaultdict(list)
for pair, noisy, ref, z in deepz_frames(root):
    ce_ref = metrics.composite_edit(ref, z)
    row = []
    for out in (noisy, denoise_window(model, [noisy], 0).image):
        out = metrics.with_depths_of(out, ref)
        for x in (out, with_from(out, ref, [ALPHA]), with_from(out, ref, RGB)):
            row.append(metrics.flip(ce_ref, metrics.composite_edit(x, z)))
    acc[scene_family(pair), pair.spp].append(row)
    print(pair.scene, scene_family(pair), pair.spp, " ".join(f"{v:.4f}" for v in row), flush=True)
print("| family | spp | noisy | noisy, ref alpha | noisy, ref colour | ranad | ranad, ref alpha | ranad, ref colour |")
print("|---|---|---|---|---|---|---|---|")
for (fam, spp), rows in sorted(acc.items()):
    print(f"| {fam} | {spp} | " + " | ".join(f"{v:.4f}" for v in np.mean(rows, 0)) + " |")
