"""Diagnostic (session 28): where does ranad's flat HDR-FLIP exceed OIDN's? Per-pixel FLIP maps of both, summed
by buckets of the reference's luminance (quartiles per frame) and of its local contrast (the reference's 3x3
luminance range over its mean, quartiles). Prints each bucket's share of OIDN's total error and ranad/OIDN there.
Usage: python where_diag.py SET SPP [MODEL]"""
import sys
import collections
import numpy as np
import flip_evaluator
from ranad_core.exr import read_deep
from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.train.data import find_pairs
from ranad_core.model.store import load_model
from ranad_core.model.prior import LUMA


def fmap(ref, test):
    ref = np.ascontiguousarray(np.maximum(ref, 0), np.float32)
    test = np.ascontiguousarray(np.maximum(test, 0), np.float32)
    return np.asarray(flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)[0]).reshape(ref.shape[:2])


model = load_model(sys.argv[3] if len(sys.argv) > 3 else None).model
spp = int(sys.argv[2])
luma = np.asarray(LUMA, np.float64)
by = {name: collections.defaultdict(lambda: np.zeros(2)) for name in ("luminance", "contrast")}
for p in find_pairs([sys.argv[1]]):
    if p.kind != "deepz" or p.spp != spp:
        continue
    noisy, ref = read_deep(p.noisy), read_deep(p.reference)
    fr, fo = metrics.flat_rgb(ref), oidn_flat(noisy)
    fn = metrics.flat_rgb(denoise_window(model, [noisy], 0).image)
    eo, en = fmap(fr, fo), fmap(fr, fn)
    lr = np.maximum(fr.astype(np.float64) @ luma, 0)
    pad = np.pad(lr, 1, mode="edge")
    win = np.stack([pad[i:i + lr.shape[0], j:j + lr.shape[1]] for i in range(3) for j in range(3)])
    con = (win.max(0) - win.min(0)) / (win.mean(0) + 1e-3)
    for name, v in (("luminance", lr), ("contrast", con)):
        q = np.quantile(v, [0.25, 0.5, 0.75])
        b = np.searchsorted(q, v)
        for k in range(4):
            by[name][k] += [eo[b == k].sum(), en[b == k].sum()]
for name, d in by.items():
    tot = sum(v[0] for v in d.values())
    print(sys.argv[1], spp, name,
          " ".join(f"Q{k + 1}: share {d[k][0] / tot:.2f} ratio {d[k][1] / d[k][0]:.3f}" for k in range(4)))
