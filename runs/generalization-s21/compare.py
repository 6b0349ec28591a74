"""Card rows from `ranad eval` folders of two models on the same sets: per set, deep-Z flat FLIP over flat OIDN's and
edit FLIP over OIDN-then-recolour's at each spp (ratios of means over the scenes, exposure +0), first model then
second, and the largest deep-OID/deep-Z difference of the second (last column).

Usage: python runs/generalization-s21/compare.py OLD_PREFIX NEW_PREFIX SET...   (folders OLD_PREFIX + SET, ...)
"""
import collections
import csv
import os
import sys


def ratios(folder):
    acc = collections.defaultdict(list)
    for r in csv.DictReader(open(os.path.join(folder, "eval.csv"))):
        if r.get("exposure", "0") in ("0", "+0"):
            acc[(r["kind"], int(r["spp"]), r["method"])].append(r)

    def mean(rows, key):
        return sum(float(r[key]) for r in rows) / len(rows)

    out = {}
    for kind in ("deepz", "deepoid"):
        spps = sorted({s for (k, s, m) in acc if k == kind})
        out[kind] = ([mean(acc[(kind, s, "ranad")], "flip") / mean(acc[(kind, s, "oidn")], "flip") for s in spps],
                     [mean(acc[(kind, s, "ranad")], "comp_flip") / mean(acc[(kind, s, "recolour")], "comp_flip")
                      for s in spps], spps)
    return out


def cells(values):
    return " / ".join(f"{v:.3f}" for v in values)


old, new = sys.argv[1], sys.argv[2]
for name in sys.argv[3:]:
    a, b = ratios(old + name), ratios(new + name)
    kind_gap = max(abs(x - y) for i in (0, 1) for x, y in zip(b["deepz"][i], b["deepoid"][i]))
    print(f"| `{name}` ({'/'.join(map(str, b['deepz'][2]))} spp) | {cells(a['deepz'][0])} | {cells(a['deepz'][1])} | "
          f"{cells(b['deepz'][0])} | {cells(b['deepz'][1])} | {kind_gap:.3f} |")
