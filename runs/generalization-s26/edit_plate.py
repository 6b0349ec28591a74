"""The compositing edit with its inserted layer as bright as the plate (session 26): metrics.composite_edit inserts a
layer of fixed colour INSERT_COLOUR (luminance 0.24 at alpha 0.5) whatever the scene's exposure; in a dark frame
(the Gaussian-4 glass scenes' mean luminance is 0.01-0.05) the layer is most of the edited image, and HDR-FLIP,
which picks its exposures from the reference, barely sees the scene behind it. Here the layer's colour is scaled so
that its luminance is the reference's mean flat luminance (so the edit scales with the render's exposure).
Per scene and spp of a set's deep-Z frames: the scene's mean luminance, then edit FLIP of noisy, OIDN-then-recolour
and ranad with the fixed layer (as `ranad eval`) and with the plate-bright one; means per family and spp.
Usage: python edit_plate.py SET [MODEL]"""
import sys
from collections import defaultdict

import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat, recolour
from ranad_core.denoise import denoise_window
from ranad_core.evaluate import scene_family
from ranad_core.model.prior import LUMA
from edit_frames import deepz_frames, model_from_argv


def edit_with(img, z, colour):
    """metrics.composite_edit with the inserted layer's premultiplied colour `colour`."""
    old = metrics.INSERT_COLOUR
    metrics.INSERT_COLOUR = tuple(float(c) for c in colour)
    try:
        return metrics.composite_edit(img, z)
    finally:
        metrics.INSERT_COLOUR = old


root = sys.argv[1]
model = model_from_argv()
fixed = np.asarray(metrics.INSERT_COLOUR)
acc = defaultdict(list)
for pair, noisy, ref, z in deepz_frames(root):
    lum = float((metrics.flat_rgb(ref) @ LUMA).mean())
    plate = fixed * metrics.INSERT_ALPHA * lum / float(fixed @ LUMA)   # premultiplied, unpremultiplied luminance lum
    outs = [noisy, recolour(noisy, oidn_flat(noisy)), denoise_window(model, [noisy], 0).image]
    row = [lum]
    for colour in (fixed, plate):
        ce_ref = edit_with(ref, z, colour)
        row += [metrics.flip(ce_ref, edit_with(metrics.with_depths_of(o, ref), z, colour)) for o in outs]
    acc[scene_family(pair), pair.spp].append(row)
    print(pair.scene, scene_family(pair), pair.spp, " ".join(f"{v:.4f}" for v in row), flush=True)
print("| family | spp | scene luminance | fixed layer: noisy | recolour | ranad | ranad / recolour "
      "| plate-bright layer: noisy | recolour | ranad | ranad / recolour |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for (fam, spp), rows in sorted(acc.items()):
    m = np.mean(rows, 0)
    print(f"| {fam} | {spp} | {m[0]:.3f} | " + " | ".join(f"{v:.4f}" for v in m[1:4]) + f" | {m[3] / m[2]:.3f} | "
          + " | ".join(f"{v:.4f}" for v in m[4:7]) + f" | {m[6] / m[5]:.3f} |")
