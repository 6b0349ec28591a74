"""Diagnostic (session 33): can ranad's flat output take flat OIDN's luminance where OIDN is better, by a per-pixel
gain (the light-matching mechanism: one gain per pixel keeps every output linear in the noisy values)?

For each deep-Z scene of a set at 4 and 16 spp: R = ranad's flat image (MODEL), O = flat OIDN's (albedo
and normal), and per-pixel variants of R times a gain toward O's luminance: R (L_O / L_R)^b with b = 1, 0.5; b from
a rule that needs no reference (1 where O's 3x3 luminance range over its mean is below that frame's median, fading
to 0 at twice it); the linear blend 0.5 R + 0.5 O (session 28); and, as a ceiling of any region-wise choice, an
oracle that takes R or O per quartile of the reference's local contrast, whichever scores lower there. Prints mean
flat HDR-FLIP over the scenes divided by O's.
Usage: python gain_blend.py [--model M] SET...   (run in the data folder; M: cpu-small-pdl-gza-v8, the default
       when the study ran it, unless given)"""
import collections
import sys

import flip_evaluator
import numpy as np

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.prior import LUMA
from ranad_core.model.store import load_model
from ranad_core.train.data import find_pairs

VARIANTS = ("R", "gain b=1", "gain b=0.5", "gain rule", "blend 0.5", "oracle quartile")


def fmap(ref, test):
    ref = np.ascontiguousarray(np.maximum(ref, 0), np.float32)
    test = np.ascontiguousarray(np.maximum(test, 0), np.float32)
    return np.asarray(flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)[0]).reshape(ref.shape[:2])


def lum(x):
    return np.maximum(x.astype(np.float64) @ LUMA, 0)


def contrast(l):
    pad = np.pad(l, 1, mode="edge")
    win = np.stack([pad[i:i + l.shape[0], j:j + l.shape[1]] for i in range(3) for j in range(3)])
    return (win.max(0) - win.min(0)) / (win.mean(0) + 1e-3)


def gained(r, o, b):
    lr, lo = lum(r), lum(o)
    g = np.where(lr > 1e-6, (lo + 1e-6) / (lr + 1e-6), 1.0) ** b
    return (r * g[..., None]).astype(np.float32)


def main() -> None:
    args = sys.argv[1:]
    name = "cpu-small-pdl-gza-v8"
    if args[:1] == ["--model"]:
        name, args = args[1], args[2:]
    model = load_model(name).model
    for folder in args:
        acc = collections.defaultdict(list)
        for p in find_pairs([folder]):
            if p.kind != "deepz" or p.spp not in (4, 16):
                continue
            noisy, ref = read_deep(p.noisy), read_deep(p.reference)
            fr, fo = metrics.flat_rgb(ref), oidn_flat(noisy)
            fn = metrics.flat_rgb(denoise_window(model, [noisy], 0).image)
            c = contrast(lum(fo))
            t = np.median(c)
            rule = np.clip(2 - c / max(t, 1e-6), 0, 1)
            outs = {"R": fn, "gain b=1": gained(fn, fo, 1.0), "gain b=0.5": gained(fn, fo, 0.5),
                    "gain rule": gained(fn, fo, rule), "blend 0.5": 0.5 * fn + 0.5 * fo}
            eo, en = fmap(fr, fo), fmap(fr, fn)
            cr = contrast(lum(fr))
            q = np.searchsorted(np.quantile(cr, [0.25, 0.5, 0.75]), cr)
            oracle = sum(min(eo[q == k].sum(), en[q == k].sum()) for k in range(4)) / eo.size
            row = [metrics.flip(fr, outs[v]) for v in VARIANTS[:-1]] + [oracle, float(eo.mean())]
            acc[p.spp].append(row)
        for spp in sorted(acc):
            m = np.mean(acc[spp], axis=0)
            print(f"| {folder} | {spp} | " + " | ".join(f"{x / m[-1]:.3f}" for x in m[:-1]) + f" | {m[-1]:.4f} |",
                  flush=True)


if __name__ == "__main__":
    print("| set | spp | " + " | ".join(VARIANTS) + " | OIDN's FLIP |")
    print("|---|---|" + "---|" * (len(VARIANTS) + 1))
    main()
