"""Absolute deep-Z flat FLIP of flat OIDN and of the model, and the model's edit FLIP, 4 / 16 / 64 spp (means over
scenes, exposure +0), per `ranad eval` folder (FAMILY: that family's scenes only): how much of a ratio's change is
the model's and how much the baseline's.

Usage: python runs/generalization-s22/absolute.py [--family FAMILY] FOLDER...
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from families import rows_of  # noqa: E402
from ranad_core.evaluate import summary  # noqa: E402

args = sys.argv[1:]
family = None
if args[:1] == ["--family"]:
    family, args = args[1], args[2:]
for folder in args:
    rows = [r for r in rows_of(folder) if r["kind"] == "deepz" and family in (None, r.get("family"))]
    by = {(s["method"], s["spp"]): s for s in summary(rows)}
    spps = sorted({k[1] for k in by})
    label = f"{folder} {family}" if family else folder
    print(f"{label}: OIDN " + " / ".join(f"{by[('oidn', s)]['flip']:.4f}" for s in spps)
          + "; ranad " + " / ".join(f"{by[('ranad', s)]['flip']:.4f}" for s in spps)
          + "; ranad edit " + " / ".join(f"{by[('ranad', s)]['comp_flip']:.4f}" for s in spps))
