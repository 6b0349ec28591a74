"""Session 31: the clean-aux study's table from `ranad eval` folders (chain1.sh): per held-out set and spp (deep-Z,
held-out group), mean flat FLIP and edit FLIP of
  v8   the shipped default, its baselines plain OIDN (raw albedo and normal) and OIDN then recolour;
  cp   v8 with OIDN's prefiltered aux in its flat prior (the baselines as v8's);
  cb   the baselines with OIDN's prefiltered aux (ranad as v8's),
as ratios: v8 / OIDN, cp / OIDN, cleaned OIDN / OIDN (what prefiltering gives OIDN itself), v8 and cp / cleaned
OIDN, and
the edit ratios v8 and cp to OIDN then recolour, cp to cleaned OIDN then recolour.

Usage: python cross.py SET... (run in the data folder's s31)"""
from __future__ import annotations

import csv
import sys
from collections import defaultdict


def means(folder: str, kind: str = "deepz", group: str | None = "held-out") -> dict:
    """(spp, method, "flip" or "comp") -> mean over the scenes of `group` (None: every scene, for a set of one group
    such as the in-family ones)."""
    acc = defaultdict(list)
    with open(f"{folder}/eval.csv") as f:
        for r in csv.DictReader(f):
            if group in (None, r["group"]) and r["kind"] == kind and r["exposure"] == "0":
                acc[(int(r["spp"]), r["method"], "flip")].append(float(r["flip"]))
                if r["comp_flip"] not in ("", "n/a", "nan"):
                    acc[(int(r["spp"]), r["method"], "comp")].append(float(r["comp_flip"]))
    return {k: sum(v) / len(v) for k, v in acc.items()}


def main() -> None:
    print("| set | spp | v8 / OIDN | cp / OIDN | clean OIDN / OIDN | v8 / clean OIDN | cp / clean OIDN | edit v8 | "
          "edit cp | edit cp / clean |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for s in sys.argv[1:]:
        try:
            v8, cp, cb = (means(f"ev_{t}_{s}") for t in ("v8", "cp", "cb"))
        except FileNotFoundError:
            continue
        for spp in sorted({k[0] for k in v8}):
            o, oc = v8[(spp, "oidn", "flip")], cb[(spp, "oidn", "flip")]
            rc, rcc = v8[(spp, "recolour", "comp")], cb[(spp, "recolour", "comp")]
            print(f"| `{s}` | {spp} | {v8[(spp, 'ranad', 'flip')] / o:.3f} | {cp[(spp, 'ranad', 'flip')] / o:.3f} | "
                  f"{oc / o:.3f} | {v8[(spp, 'ranad', 'flip')] / oc:.3f} | {cp[(spp, 'ranad', 'flip')] / oc:.3f} | "
                  f"{v8[(spp, 'ranad', 'comp')] / rc:.3f} | "
                  f"{cp[(spp, 'ranad', 'comp')] / rc:.3f} | {cp[(spp, 'ranad', 'comp')] / rcc:.3f} |")


if __name__ == "__main__":
    main()
