"""Ratios of means from `ranad eval` CSVs, as `ranad eval` computes them (ranad_core.evaluate.ratios): ranad's flat
FLIP over flat OIDN's and its compositing-edit FLIP over OIDN-then-recolour's, per deep kind and spp (per family with
--family), exposure 0, one row per NAME=eval.csv, with ranad's own mean flat FLIP.

    python runs/pixel-filter-s18/compare.py [--family] NAME=OUT/eval.csv ...
"""

from __future__ import annotations

import csv
import sys

from ranad_core.evaluate import COLUMNS, ratios, summary

TEXT = ("scene", "family", "group", "kind", "method")


def rows(path: str, by_family: bool) -> list:
    """The CSV's exposure-0 rows typed as `ranad eval` made them; with by_family, the family as the group."""
    out = []
    for r in csv.DictReader(open(path)):
        row = {k: (r[k] if k in TEXT else int(r[k]) if k == "spp" else float(r[k])) for k in COLUMNS}
        if row["exposure"] == 0:
            out.append({**row, "group": row["family"] if by_family else "all"})
    return out


def main(argv: list) -> None:
    by_family = "--family" in argv
    print("| run | family | kind | flat FLIP vs OIDN, 4 / 16 / 64 spp | edit FLIP vs recolour | ranad flat FLIP |")
    print("|---|---|---|---|---|---|")
    for name, path in (a.split("=", 1) for a in argv if "=" in a):
        table = rows(path, by_family)
        cells = {}
        for r in ratios(table):
            cells.setdefault((r["group"], r["kind"]), []).append(r)
        for (group, kind), rs in sorted(cells.items()):
            sel = [t for t in table if (t["group"], t["kind"]) == (group, kind)]
            flat = {s["spp"]: s["flip"] for s in summary(sel) if s["method"] == "ranad"}
            cols = [" / ".join(fmt.format(v) for v in vals) for fmt, vals in (
                ("{:.3f}", [r["flip_vs_oidn"] for r in rs]), ("{:.3f}", [r["edit_vs_recolour"] for r in rs]),
                ("{:.4f}", [flat[r["spp"]] for r in rs]))]
            print(f"| {name} | {group} | {kind} | " + " | ".join(cols) + " |")

if __name__ == "__main__":
    main(sys.argv[1:])
