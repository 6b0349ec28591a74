"""The card's figures from `ranad eval` folders: per deep kind and spp, ranad's flat FLIP over flat OIDN's and its
edit FLIP over OIDN-then-recolour's (ratios of means over the scenes, exposure +0), and deep-Z's absolute flat FLIP.

Usage: python runs/generalization-s20/summarise.py EVAL_FOLDER...
"""
import collections
import csv
import os
import sys

def load(d):
    rows = list(csv.DictReader(open(os.path.join(d, "eval.csv"))))
    acc = collections.defaultdict(list)
    for r in rows:
        if r.get("exposure", "0") not in ("0", "+0"):
            continue
        acc[(r["kind"], int(r["spp"]), r["method"])].append(r)
    return acc
def mean(v, k):
    x = [float(r[k]) for r in v]
    return sum(x) / len(x)
for d in sys.argv[1:]:
    acc = load(d)
    out = []
    for kind in ("deepz", "deepoid"):
        spps = sorted({s for (k, s, m) in acc if k == kind})
        fl = [mean(acc[(kind, s, "ranad")], "flip") / mean(acc[(kind, s, "oidn")], "flip") for s in spps]
        ed = [mean(acc[(kind, s, "ranad")], "comp_flip") / mean(acc[(kind, s, "recolour")], "comp_flip") for s in spps]
        out.append(f"{kind}: flat {' / '.join(f'{x:.3f}' for x in fl)}  edit {' / '.join(f'{x:.3f}' for x in ed)}")
        if kind == "deepz":
            ab = {m: [mean(acc[(kind, s, m)], "flip") for s in spps] for m in ("noisy", "oidn", "ranad")}
            out.append("   abs flat " + "; ".join(f"{m} {' / '.join(f'{x:.4f}' for x in v)}" for m, v in ab.items()))
    n = len(acc[("deepz", spps[0], "ranad")])
    print(f"{d} (n={n}, spp {spps})"); [print("  " + o) for o in out]
