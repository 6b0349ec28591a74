"""Session 33: v8 and two fine-tunes on v8's whole pool, at crop 64 (c64f, session 32's pna2-t1 again) and on whole
128x128 frames (c128f, chain1.sh), the first for four times the steps (c64f4, chain3.sh: as many pixels as c128f)
and the second for three times (c128f3, chain2.sh), each where run, per held-out set and spp (deep-Z, held-out
group, means over the scenes): flat FLIP / plain OIDN's and edit FLIP / OIDN-then-recolour's, each against the
baselines of its own evaluation.

Usage: python crop_full.py SET... (run in the data folder; evaluations in s31/ and s33/)"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s31"))
from cross import means  # noqa: E402

TAGS = {"v8": "s31/ev_v8_", "c64f": "s33/ev_c64f_", "c128f": "s33/ev_c128f_", "c64f4": "s33/ev_c64f4_",
        "c128f3": "s33/ev_c128f3_"}


def main() -> None:
    tags = [t for t in TAGS if any(os.path.exists(TAGS[t] + s + "/eval.csv") for s in sys.argv[1:])]
    print("| set | spp | " + " | ".join(tags) + " | " + " | ".join(f"edit {t}" for t in tags) + " |")
    print("|---|---|" + "---|" * 2 * len(tags))
    for s in sys.argv[1:]:
        runs = {t: means(TAGS[t] + s) for t in tags if os.path.exists(TAGS[t] + s + "/eval.csv")}
        if "v8" not in runs:
            continue
        for spp in sorted({k[0] for k in runs["v8"]}):
            cell = lambda t, m, base: (f"{runs[t][(spp, 'ranad', m)] / runs[t][(spp, base, m)]:.3f}"  # noqa: E731
                                       if t in runs else "")
            print(f"| `{s}` | {spp} | " + " | ".join(cell(t, "flip", "oidn") for t in tags) + " | " +
                  " | ".join(cell(t, "comp", "recolour") for t in tags) + " |")


if __name__ == "__main__":
    main()
