"""Which part of ranad's output limits the compositing edit: its colours or its alpha?

Usage: python runs/cpu-small-p-t2/alpha_edit.py HELDOUT_DATASET [MODEL]. On the deep-Z glass and layers scenes at
16 and 64 spp, scores the edit (metrics.deep_scores, which uses the reference's depths) of ranad's output, of
ranad's colours with the noisy or the reference alpha, and of the noisy colours with ranad's alpha."""
import sys

import numpy as np
import torch

from ranad_core import metrics
from ranad_core.channels import ALPHA
from ranad_core.denoise import denoise_frame
from ranad_core.evaluate import scene_family
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model
from ranad_core.train.data import find_pairs


def with_alpha_of(colour_from, alpha_from):
    """`colour_from` with the alpha of `alpha_from` (same bin layout)."""
    vals = colour_from.values.copy()
    col = colour_from.channels.index(ALPHA)
    vals[:, col] = alpha_from.values[:, alpha_from.channels.index(ALPHA)]
    return colour_from.with_values(vals)


torch.set_num_threads(1)
model = load_model(sys.argv[2] if len(sys.argv) > 2 else "cpu-small-p-v1").model
rows = {}
for p in find_pairs(sys.argv[1]):
    family = scene_family(p)
    if p.kind != "deepz" or p.spp not in (16, 64) or family not in ("glass", "layers"):
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    z = metrics.split_depth(ref)
    out = denoise_frame(model, noisy).image
    variants = {"noisy": noisy, "ranad": out, "ranad_col+noisy_a": with_alpha_of(out, noisy),
                "noisy_col+ranad_a": with_alpha_of(noisy, out), "ranad_col+ref_a": with_alpha_of(out, ref)}
    for k, v in variants.items():
        s = metrics.deep_scores(ref, v, z)
        f = metrics.flat_scores(metrics.flat_rgb(ref), metrics.flat_rgb(v))
        rows.setdefault((p.spp, k), []).append((f["flip"], s["comp_flip"], s["bin_smape"]))
    a_out, a_noisy, a_ref = (img.channel(ALPHA) for img in (out, noisy, ref))
    print(p.scene, family, p.spp, "alpha MAE ranad %.4f noisy %.4f"
          % (np.abs(a_out - a_ref).mean(), np.abs(a_noisy - a_ref).mean()), flush=True)
for (spp, k), v in sorted(rows.items()):
    m = np.mean(v, 0)
    print(f"{spp:3d} {k:20s} flip {m[0]:.4f} comp_flip {m[1]:.4f} bin_smape {m[2]:.4f}")
