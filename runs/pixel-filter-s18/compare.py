"""Ratios of means from `ranad eval` CSVs: ranad's flat FLIP over flat OIDN's and its compositing-edit FLIP over
OIDN-then-recolour's, per deep kind and spp (and per family with --family), one row per NAME=eval.csv.

    python runs/pixel-filter-s18/compare.py [--family] NAME=OUT/eval.csv ...
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict


def ratios(path: str, by_family: bool) -> dict:
    acc = defaultdict(list)
    for r in csv.DictReader(open(path)):
        if r["exposure"] not in ("0", "+0", "0.0"):
            continue
        key = (r["family"] if by_family else "all", r["kind"], int(r["spp"]))
        acc[key + (r["method"], "flip")].append(float(r["flip"]))
        if r["comp_flip"] not in ("", "n/a"):
            acc[key + (r["method"], "comp")].append(float(r["comp_flip"]))
    mean = {k: sum(v) / len(v) for k, v in acc.items()}
    out = {}
    for (fam, kind, spp, method, what), _ in mean.items():
        if method != "ranad" or what != "flip":
            continue
        k = (fam, kind, spp)
        out[k] = (mean[k + ("ranad", "flip")] / mean[k + ("oidn", "flip")],
                  mean[k + ("ranad", "comp")] / mean[k + ("recolour", "comp")],
                  mean[k + ("ranad", "flip")], mean[k + ("noisy", "flip")])
    return out


def main(argv: list) -> None:
    by_family = "--family" in argv
    runs = [a.split("=", 1) for a in argv if "=" in a]
    print("| run | family | kind | flat FLIP vs OIDN, 4 / 16 / 64 spp | edit FLIP vs recolour | ranad flat FLIP |")
    print("|---|---|---|---|---|---|")
    for name, path in runs:
        r = ratios(path, by_family)
        for fam, kind in sorted({(f, k) for f, k, _ in r}):
            spps = sorted(s for f, k, s in r if (f, k) == (fam, kind))
            cells = [" / ".join(f"{r[(fam, kind, s)][i]:.3f}" for s in spps) for i in (0, 1)]
            flat = " / ".join(f"{r[(fam, kind, s)][2]:.4f}" for s in spps)
            print(f"| {name} | {fam} | {kind} | {cells[0]} | {cells[1]} | {flat} |")


if __name__ == "__main__":
    main(sys.argv[1:])
