"""On clean real renders a denoiser should change little: the flattened output's mean relative change against the
input (and alpha's mean absolute change), with and without thin-bin merging. usage: clean_change.py FILE.exr ..."""
import sys

import numpy as np

from ranad_core.deep import flatten
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model

model = load_model(None).model
for path in sys.argv[1:]:
    img = read_deep(path)
    ch = img.channels
    flat = flatten(img)
    rgb, a = [ch.index(c) for c in "RGB"], ch.index("A")
    row = []
    for gap in (None, 0.0):
        out = flatten(denoise_window(model, [img], 0, merge_gap=gap).image)
        rel = np.abs(out[..., rgb] - flat[..., rgb]).sum() / max(np.abs(flat[..., rgb]).sum(), 1e-12)
        row.append(f"{'merged' if gap is None else 'unmerged'}: colour {rel:.4f}, alpha "
                   f"{np.abs(out[..., a] - flat[..., a]).mean():.5f}")
    print(f"{path}: " + "; ".join(row))
