"""Every EXR of a synth set reads and holds finite values (exit 1 naming the first that does not)."""
import sys
from pathlib import Path

import numpy as np

from ranad_core.exr import read_deep

n = 0
for path in sorted(Path(sys.argv[1]).rglob("*.exr")):
    img = read_deep(str(path))
    bad = ~np.isfinite(img.values).all(0)
    if bad.any():
        sys.exit(f"{path}: non-finite values in {[c for c, b in zip(img.channels, bad) if b]}")
    n += 1
print(f"{n} files, all finite")
