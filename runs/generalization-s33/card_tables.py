"""Session 33: the rows of cpu-small-pdl-gza-v9's card: per set, v8's and v9's flat FLIP / flat OIDN's and edit FLIP
/ OIDN-then-recolour's at each spp (deep-Z, means over the scenes; every scene of these sets is of one group), and
the largest difference of v9's deep-OID ratios from its deep-Z ones. v9 is run c128f3-t1 exported (the same
weights): its evaluations are s33/ev_c128f3_SET, or s33/ev_v9_SET where the set was scored after the export; v8's
s31/ev_v8_SET or s33/ev_v8_SET.

Usage: python card_tables.py SET...   (run in the data folder)"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s31"))
from cross import means  # noqa: E402


def found(*folders):
    return next((f for f in folders if os.path.exists(f + "/eval.csv")), None)


def ratios(folder, kind, metric, base):
    m = means(folder, kind, group=None)   # every scene of these sets is of one group
    return {spp: m[(spp, "ranad", metric)] / m[(spp, base, metric)]
            for spp in sorted({k[0] for k in m}) if (spp, "ranad", metric) in m and (spp, base, metric) in m}


def main() -> None:
    print("| set | v8 flat | v8 edit | **v9 flat** | **v9 edit** | deep-OID |")
    print("|---|---|---|---|---|---|")
    for s in sys.argv[1:]:
        v8 = found(f"s31/ev_v8_{s}", f"s33/ev_v8_{s}")
        v9 = found(f"s33/ev_c128f3_{s}", f"s33/ev_v9_{s}")
        if not (v8 and v9):
            continue
        cells = []
        for f in (v8, v9):
            for metric, base in (("flip", "oidn"), ("comp", "recolour")):
                cells.append(" / ".join(f"{x:.3f}" for x in ratios(f, "deepz", metric, base).values()))
        z, o = ratios(v9, "deepz", "flip", "oidn"), ratios(v9, "deepoid", "flip", "oidn")
        dz = max((abs(o[k] - z[k]) for k in z if k in o), default=float("nan"))
        print(f"| `{s}` | " + " | ".join(cells) + f" | {dz:.3f} |")


if __name__ == "__main__":
    main()
