"""Which part of ranad's output limits the compositing edit: its colours or its alpha?

Usage: python runs/cpu-small-p-t2/alpha_edit.py HELDOUT_DATASET [MODEL]. On the deep-Z glass and layers scenes at
16 and 64 spp, scores the edit (metrics.deep_scores, which uses the reference's depths) of ranad's output, of
ranad's colours with the noisy or the reference alpha, and of the noisy colours with ranad's alpha."""
import sys, numpy as np, torch
from ranad_core import metrics
from ranad_core.channels import ALPHA
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.train.data import find_pairs
from ranad_core.model.store import load_model
from ranad_core.evaluate import scene_family
torch.set_num_threads(1)
model = load_model(sys.argv[2] if len(sys.argv) > 2 else "cpu-small-p-v1").model
rows = {}
for p in find_pairs(sys.argv[1]):
    if p.kind != "deepz" or p.spp not in (16, 64):
        continue
    fam = scene_family(p)
    if fam not in ("glass", "layers"):
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    z = metrics.split_depth(ref)
    out = denoise_frame(model, noisy).image
    ai = out.channels.index(ALPHA)
    def mix(colour_from, alpha_from):
        v = colour_from.values.copy(); v[:, ai] = alpha_from.values[:, ai]; return colour_from.with_values(v)
    variants = {"noisy": noisy, "ranad": out, "ranad_col+noisy_a": mix(out, noisy), "noisy_col+ranad_a": mix(noisy, out),
                "ranad_col+ref_a": mix(out, ref)}
    for k, v in variants.items():
        s = metrics.deep_scores(ref, v, z)
        f = metrics.flat_scores(metrics.flat_rgb(ref), metrics.flat_rgb(v))
        rows.setdefault((p.spp, k), []).append((f["flip"], s["comp_flip"], s["bin_smape"]))
    a_err = np.abs(out.values[:, ai] - ref.values[:, ai]).mean(); a_n = np.abs(noisy.values[:, ai] - ref.values[:, ai]).mean()
    print(p.scene, fam, p.spp, "alpha MAE ranad %.4f noisy %.4f" % (a_err, a_n), flush=True)
for (spp, k), v in sorted(rows.items()):
    m = np.mean(v, 0); print(f"{spp:3d} {k:20s} flip {m[0]:.4f} comp_flip {m[1]:.4f} bin_smape {m[2]:.4f}")
