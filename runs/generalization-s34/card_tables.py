"""Session 34: rows for the model cards: per set, each model's flat FLIP / flat OIDN's and edit FLIP /
OIDN-then-recolour's at each spp (deep-Z, means over the scenes; every scene of these sets is of one group), and
the largest difference of the last model's deep-OID flat ratios from its deep-Z ones. A model's evaluation of SET is
the first of FOLDER_PATTERNs (with {set} in them) that holds an eval.csv.

Usage: python card_tables.py --model NAME=PATTERN[,PATTERN...] [--model ...] SET...   (run in the data folder)
e.g.   --model v8=s31/ev_v8_{set},s34/ev_v8_{set} --model v9=s33/ev_c128f3_{set},s33/ev_v9_{set},s34/ev_v9_{set}"""
import argparse
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s31"))
from cross import means  # noqa: E402


def found(patterns, s):
    return next((f for f in (p.format(set=s) for p in patterns) if os.path.exists(f + "/eval.csv")), None)


def ratios(folder, kind, metric, base):
    m = means(folder, kind, group=None)   # every scene of these sets is of one group
    return {spp: m[(spp, "ranad", metric)] / m[(spp, base, metric)]
            for spp in sorted({k[0] for k in m}) if (spp, "ranad", metric) in m and (spp, base, metric) in m}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", action="append", required=True, help="NAME=PATTERN[,PATTERN...]")
    ap.add_argument("sets", nargs="+")
    a = ap.parse_args()
    models = [(n, p.split(",")) for n, p in (m.split("=", 1) for m in a.model)]
    head = [f"{n} {w}" for n, _ in models for w in ("flat", "edit")]
    print("| set | " + " | ".join(head) + " | deep-OID |")
    print("|---" * (len(head) + 2) + "|")
    for s in a.sets:
        folders = [found(p, s) for _, p in models]
        if not all(folders):
            continue
        cells = [" / ".join(f"{x:.3f}" for x in ratios(f, "deepz", metric, base).values())
                 for f in folders for metric, base in (("flip", "oidn"), ("comp", "recolour"))]
        z, o = ratios(folders[-1], "deepz", "flip", "oidn"), ratios(folders[-1], "deepoid", "flip", "oidn")
        dz = max((abs(o[k] - z[k]) for k in z if k in o), default=float("nan"))
        print(f"| `{s}` | " + " | ".join(cells) + f" | {dz:.3f} |")


if __name__ == "__main__":
    main()
