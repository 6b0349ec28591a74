"""Where the glass scenes' compositing-edit error comes from (session 26): the flat image, or how it is split among
a pixel's bins. Per scene and spp of a set's deep-Z frames, the edit FLIP (metrics.composite_edit, the scores' split
depth) against the reference's of: ranad's output; OIDN-then-recolour (OIDN's flat split by the noisy bins'
shares); ranad's flat split by the noisy shares (`recolour(noisy, ranad flat)`); OIDN's flat split by ranad's
shares (`recolour(ranad, OIDN flat)`). Means per family (scene manifest) and spp.
Usage: python shares.py SET [MODEL]"""
import sys
from collections import defaultdict

import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat, recolour
from ranad_core.denoise import denoise_window
from ranad_core.evaluate import scene_family
from edit_frames import deepz_frames, model_from_argv

root = sys.argv[1]
model = model_from_argv()
METHODS = ("ranad", "oidn+noisy shares", "ranad flat+noisy shares", "oidn flat+ranad shares")
acc = defaultdict(list)
for pair, noisy, ref, z in deepz_frames(root):
    out = denoise_window(model, [noisy], 0).image
    oidn = oidn_flat(noisy)
    outs = (out, recolour(noisy, oidn), recolour(noisy, metrics.flat_rgb(out)), recolour(out, oidn))
    ce_ref = metrics.composite_edit(ref, z)
    fam = scene_family(pair)
    row = [metrics.flip(ce_ref, metrics.composite_edit(metrics.with_depths_of(o, ref), z)) for o in outs]
    acc[fam, pair.spp].append(row)
    print(pair.scene, fam, pair.spp, " ".join(f"{v:.4f}" for v in row), flush=True)
print("| family | spp | " + " | ".join(METHODS) + " |")
print("|---|---|" + "---|" * len(METHODS))
for (fam, spp), rows in sorted(acc.items()):
    m = np.mean(rows, 0)
    print(f"| {fam} | {spp} | " + " | ".join(f"{v:.4f}" for v in m) + " |")
