"""Session 29: the light-matching gains the default model gives real deep files of other people (statistics per file:
least, largest and mean gain, share of pixels at the clamp). Usage: python real_gains.py FILE.exr..."""
import sys
import numpy as np
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep
from ranad_core.denoise import denoise_window
from ranad_core.lightmatch import CLAMP
from ranad_core.model.store import load_model

model = load_model(None).model
for f in sys.argv[1:]:
    try:
        img = read_deep(f)
    except RanadError as e:
        print(f, "skipped:", e.problem)
        continue
    g = denoise_window(model, [img], 0).gain
    at = np.mean(np.abs(np.abs(np.log(g)) - np.log(CLAMP)) < 1e-4)
    print(f"{f.split('/')[-1]}: {img.width}x{img.height}, gain {g.min():.4f} .. {g.max():.4f}, mean {g.mean():.4f}, "
          f"{100 * at:.0f}% of pixels at the clamp")
