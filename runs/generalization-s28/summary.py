"""Session 28: one line per model over the held-out sets, from `ranad eval` folders PREFIX + SET: the geometric mean
of the deep-Z flat-FLIP ratios to flat OIDN and of the edit ratios to OIDN-then-recolour over the sets and the 4 /
16 / 64 spp rows, separately for box-filtered sets and Gaussian-filtered ones (the two disagree: flat OIDN leaves
most of a Gaussian's correlated noise), and the worst single ratio of each.

Usage: python runs/generalization-s28/summary.py PREFIX... (run in the folder of the links; sets below)"""
import math
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "generalization-s21"))
from compare import ratios_by_kind  # noqa: E402

BOX = ("heldout_g1int8_box", "heldout_g1int8_boxsob", "heldout_g1fog_boxsob", "heldout_g1sg8_boxsob", "heldout_g1ac8")
GAUSS = ("heldout_g1int8", "heldout_g1sg8", "heldout_g1w4", "heldout_g1fog")


def line(prefix: str, sets) -> str:
    flat, edit = [], []
    for s in sets:
        f, e, _ = ratios_by_kind(prefix + s)["deepz"]
        flat += f
        edit += e
    g = lambda xs: math.exp(sum(map(math.log, xs)) / len(xs))  # noqa: E731
    return f"flat {g(flat):.3f} (worst {max(flat):.3f}), edit {g(edit):.3f} (worst {max(edit):.3f})"


for prefix in sys.argv[1:]:
    print(f"{prefix:8s} box: {line(prefix, BOX)} | Gaussian: {line(prefix, GAUSS)}")
