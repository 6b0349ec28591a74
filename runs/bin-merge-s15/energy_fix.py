"""Experiment: the denoised layers rescaled per pixel by blur(noisy flat layer) / blur(denoised flat layer), a
Gaussian of sigma S px (the noisy input is unbiased at large scales), scored by flat FLIP per family.
usage: energy_fix.py SPPS SIGMAS LAYERS SET...   e.g. energy_fix.py 16,64 4,8,16 specular heldout_g1ac"""
import sys, json, numpy as np
from pathlib import Path


def gaussian_filter(x, s, mode="nearest"):
    r = int(3 * s)
    k = np.exp(-0.5 * (np.arange(-r, r + 1) / s) ** 2); k /= k.sum()
    p = np.pad(x, r, mode="edge")
    p = np.apply_along_axis(lambda a: np.convolve(a, k, "valid"), 0, p)
    return np.apply_along_axis(lambda a: np.convolve(a, k, "valid"), 1, p)
from ranad_core.exr import read_deep
from ranad_core import metrics
from ranad_core.deep import flatten
from ranad_core.denoise import denoise_window
from ranad_core.model.store import load_model
m = load_model(None).model
sigmas = [float(s) for s in sys.argv[2].split(",")]
layers = sys.argv[3].split(",")   # e.g. specular or specular,diffuse
for root in sys.argv[4:]:
    acc = {}
    for sc in sorted(Path(root).glob("scene_*")):
        fam = json.loads((sc / "manifest.json").read_text())["preset"]
        for spp in sys.argv[1].split(","):
            noisy = read_deep(sc / f"deepz/noisy_spp{spp}.0000.exr")
            ref = read_deep(sc / f"deepz/reference_spp{spp}.0000.exr")
            den = denoise_window(m, [noisy], 0).image
            ch = den.channels
            R = metrics.flat_rgb(ref)
            fn, fd = flatten(noisy), flatten(den)
            pix = den.pixel_index()
            row = [metrics.flip(R, metrics.flat_rgb(noisy)), metrics.flip(R, metrics.flat_rgb(den))]
            for s in sigmas:
                v = den.values.astype(np.float64).copy()
                for lay in layers:
                    for c in "RGB":
                        i = ch.index(f"{lay}.{c}")
                        num = gaussian_filter(fn[..., i].astype(np.float64), s, mode="nearest")
                        den_ = gaussian_filter(fd[..., i].astype(np.float64), s, mode="nearest")
                        F = np.clip(np.where(den_ > 1e-8, num / np.maximum(den_, 1e-12), 1.0), 0.5, 2.0).ravel()[pix]
                        extra = (F - 1) * v[:, i]
                        v[:, i] += extra
                        v[:, ch.index(c)] += extra
                row.append(metrics.flip(R, metrics.flat_rgb(den.with_values(v.astype(np.float32)))))
            acc.setdefault((fam, spp), []).append(row)
    for (fam, spp), rows in sorted(acc.items()):
        r = np.mean(rows, 0)
        print(f"{root.split('/')[-1]} {fam:10s} {spp:>3s} noisy {r[0]:.4f} ranad {r[1]:.4f} "
              + " ".join(f"s{s:g} {x:.4f}" for s, x in zip(sigmas, r[2:])))
