"""Write a deep frame with every bin split into K thin members 0.2% apart in depth that composite exactly to it
(each an equal share of the coverage, alpha 1 - (1 - a)^(1/K), the bin's colours at that alpha; float channels),
as tests/test_binmerge.py's `thin` does. usage: thin_frame.py IN.exr OUT.exr [K (2)]"""
import sys

import numpy as np

from ranad_core.deep import DeepImage
from ranad_core.exr import read_deep, write_deep

COLOURS = ("diffuse.", "specular.", "emission.", "lg_")
src, dst = sys.argv[1], sys.argv[2]
k = int(sys.argv[3]) if len(sys.argv) > 3 else 2
img = read_deep(src)
ch, n = img.channels, img.num_bins
rows, member = np.repeat(np.arange(n), k), np.tile(np.arange(k), n)
vals = img.values[rows].astype(np.float64)
a = np.clip(img.channel("A").astype(np.float64), 0, 1)
ak = 1 - (1 - a) ** (1.0 / k)
f = np.repeat(np.where(a > 0, ak / np.maximum(a, 1e-300), 1.0 / k), k)
for i, c in enumerate(ch):
    if c == "A":
        vals[:, i] = np.repeat(ak, k)
    elif c in ("Z", "ZBack"):
        vals[:, i] *= 1 + 0.002 * member
    elif c == "coverage":
        vals[:, i] /= k
    elif c in ("R", "G", "B") or c.startswith(COLOURS):
        vals[:, i] *= f
types = {c: ("uint" if c in img.ids else "float") for c in list(ch) + list(img.ids)}
write_deep(dst, DeepImage(values=vals.astype(np.float32), offsets=img.offsets * k, channels=list(ch),
                          ids={name: v[rows] for name, v in img.ids.items()}, data_window=img.data_window,
                          display_window=img.display_window, channel_types=types))
print(f"{dst}: {n} bins -> {n * k}")
