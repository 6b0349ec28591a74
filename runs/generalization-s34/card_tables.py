"""Session 34: rows for the model cards: per set, each model's flat FLIP / flat OIDN's and edit FLIP /
OIDN-then-recolour's at each spp (deep-Z, means over the scenes; every scene of these sets is of one group), and
the largest difference of the last model's deep-OID flat ratios from its deep-Z ones. A model's evaluation of SET is
the first of FOLDER_PATTERNs (with {set} in them) that holds an eval.csv.

With --count (two models): below the table, over every figure of every set, how many of the second model's
ratios are lower, equal (to three decimals) and higher than the first's, and the geometric mean of their quotients.

Usage: python card_tables.py [--count] --model NAME=PATTERN[,PATTERN...] [--model ...] SET...   (in the data folder)
e.g.   --model v8=s31/ev_v8_{set},s34/ev_v8_{set} --model v9=s33/ev_c128f3_{set},s33/ev_v9_{set},s34/ev_v9_{set}"""
import argparse
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s33"))
from card_tables import ratios  # noqa: E402  (session 33's: ranad's mean over every scene / the baseline's, per spp)


def found(patterns, s):
    return next((f for f in (p.format(set=s) for p in patterns) if os.path.exists(f + "/eval.csv")), None)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", action="append", required=True, help="NAME=PATTERN[,PATTERN...]")
    ap.add_argument("--count", action="store_true")
    ap.add_argument("sets", nargs="+")
    a = ap.parse_args()
    models = [(n, p.split(",")) for n, p in (m.split("=", 1) for m in a.model)]
    head = [f"{n} {w}" for n, _ in models for w in ("flat", "edit")]
    print("| set | " + " | ".join(head) + " | deep-OID |")
    print("|---" * (len(head) + 2) + "|")
    pairs = {"flat": [], "edit": []}
    for s in a.sets:
        folders = [found(p, s) for _, p in models]
        if not all(folders):
            continue
        r = [[ratios(f, "deepz", metric, base) for metric, base in (("flip", "oidn"), ("comp", "recolour"))]
             for f in folders]
        cells = [" / ".join(f"{x:.3f}" for x in d.values()) for per in r for d in per]
        if a.count and len(folders) == 2:
            for name, i in (("flat", 0), ("edit", 1)):
                pairs[name] += [(round(r[0][i][k], 3), round(r[1][i][k], 3)) for k in r[0][i] if k in r[1][i]]
        z, o = ratios(folders[-1], "deepz", "flip", "oidn"), ratios(folders[-1], "deepoid", "flip", "oidn")
        dz = max((abs(o[k] - z[k]) for k in z if k in o), default=float("nan"))
        print(f"| `{s}` | " + " | ".join(cells) + f" | {dz:.3f} |")
    if a.count and len(models) == 2:
        print()
        for name, ps in pairs.items():
            lo, eq = sum(b < x for x, b in ps), sum(b == x for x, b in ps)
            gm = math.exp(sum(math.log(b / x) for x, b in ps) / len(ps)) if ps else float("nan")
            print(f"{models[1][0]} against {models[0][0]}, {name}: {lo} lower, {eq} equal, {len(ps) - lo - eq} higher "
                  f"of {len(ps)}; geometric mean quotient {gm:.4f}")


if __name__ == "__main__":
    main()
