"""Card rows from `ranad eval` folders of two models on the same sets: per set, deep-Z flat FLIP over flat OIDN's and
edit FLIP over OIDN-then-recolour's at each spp (ratios of means over the scenes at exposure +0, by `ranad eval`'s
own `evaluate.ratios`), first model then second, and the largest deep-OID/deep-Z difference of the second (last
column).

Usage: python runs/generalization-s21/compare.py OLD_PREFIX NEW_PREFIX SET...   (folders OLD_PREFIX + SET, ...)
"""
import csv
import os
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core.evaluate import DEEP, FLAT, ratios  # noqa: E402


def ratios_by_kind(folder):
    """kind -> (flat ratios, edit ratios, spps) of a set's eval.csv at exposure +0, by `ranad eval`'s own ratios."""
    rows = [{**r, "exposure": float(r["exposure"]), "spp": int(r["spp"]),
             **{k: float(r[k]) for k in (*FLAT, *DEEP, "seconds", "light") if k in r}}
            for r in csv.DictReader(open(os.path.join(folder, "eval.csv")))]
    out = {}
    for r in ratios(rows):
        if r["exposure"] == "+0":
            flat, edit, spps = out.setdefault(r["kind"], ([], [], []))
            assert r["spp"] not in spps, f"{folder}: more than one group per kind"
            flat.append(r["flip_vs_oidn"])
            edit.append(r["edit_vs_recolour"])
            spps.append(r["spp"])
    return out


def cells(values):
    return " / ".join(f"{v:.3f}" for v in values)


def main(old: str, new: str, names) -> None:
    for name in names:
        a, b = ratios_by_kind(old + name), ratios_by_kind(new + name)
        kind_gap = max(abs(x - y) for i in (0, 1) for x, y in zip(b["deepz"][i], b["deepoid"][i]))
        print(f"| `{name}` ({'/'.join(map(str, b['deepz'][2]))} spp) | {cells(a['deepz'][0])} | "
              f"{cells(a['deepz'][1])} | {cells(b['deepz'][0])} | {cells(b['deepz'][1])} | {kind_gap:.3f} |")


if __name__ == "__main__":   # importable (runs/generalization-s28/summary.py reads ratios_by_kind)
    main(sys.argv[1], sys.argv[2], sys.argv[3:])
