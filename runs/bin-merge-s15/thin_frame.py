"""Write a deep frame with every bin split into K thin members 0.2% apart in depth that composite exactly to it
(tests/test_binmerge.py's `thin`: each an equal share of the coverage, alpha 1 - (1 - a)^(1/K), the bin's colours
at that alpha; float channels). usage: thin_frame.py IN.exr OUT.exr [K (2)]"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from test_binmerge import thin  # noqa: E402

from ranad_core.exr import read_deep, write_deep  # noqa: E402

src, dst = sys.argv[1], sys.argv[2]
k = int(sys.argv[3]) if len(sys.argv) > 3 else 2
img = read_deep(src)
write_deep(dst, thin(img, k))
print(f"{dst}: {img.num_bins} bins -> {img.num_bins * k}")
