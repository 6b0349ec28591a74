"""Per-family rows of two models' `ranad eval` folders on the same set: flat FLIP over flat OIDN's and edit FLIP over
OIDN-then-recolour's (by `ranad eval`'s own `evaluate.family_ratios`: means over the family's scenes and both kinds,
exposure +0), and ranad's flat FLIP over the noisy input's, at each spp, first model then second.

Usage: python runs/generalization-s22/families.py OLD_FOLDER NEW_FOLDER
"""
import csv
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core.evaluate import DEEP, FLAT, family_ratios, summary  # noqa: E402


def rows_of(folder):
    """eval.csv at exposure +0, numeric fields as numbers."""
    rows = [{**r, "exposure": float(r["exposure"]), "spp": int(r["spp"]),
             **{k: float(r[k]) for k in (*FLAT, *DEEP, "seconds", "light") if k in r}}
            for r in csv.DictReader(open(os.path.join(folder, "eval.csv")))]
    return [r for r in rows if r["exposure"] == 0]


def table(folder):
    """(family, spp) -> (flat vs OIDN, edit vs recolour, ranad's flat FLIP / the noisy input's)."""
    rows = rows_of(folder)
    out = {}
    for r in family_ratios(rows):
        sel = [x for x in rows if x.get("family") == r["family"] and x["spp"] == r["spp"]]
        flip = {s["method"]: s["flip"] for s in summary(sel)}
        out[(r["family"], r["spp"])] = (r["flip_vs_oidn"], r["edit_vs_recolour"], flip["ranad"] / flip["noisy"])
    return out


if __name__ == "__main__":
    a, b = table(sys.argv[1]), table(sys.argv[2])
    print("| family | spp | flat vs OIDN | edit vs recolour | flat vs noisy |")
    print("|---|---|---|---|---|")
    for key in sorted(set(a) & set(b)):
        print(f"| {key[0]} | {key[1]} | " + " | ".join(f"{x:.3f} -> {y:.3f}" for x, y in zip(a[key], b[key])) + " |")
