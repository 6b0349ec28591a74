"""Session 32: v8, session 31's control fine-tune (ctl: 1000 steps on train_g35_boxsob at crop 64) and the same
fine-tune on whole 128x128 frames (c128, chain1.sh) and with as many pixels at crop 64 (c64l, chain2.sh, where run),
per held-out set and spp (deep-Z, held-out group, means over the scenes): flat FLIP / plain OIDN's and edit FLIP /
OIDN-then-recolour's, each against the baselines of its own evaluation (session 31's ran on another machine), and
the plain OIDN's own FLIP in each (the check that the baselines agree across machines).

Usage: python crop.py SET... (run in the data folder; evaluations in s31/ and s32/)"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s31"))
from cross import means  # noqa: E402

TAGS = {"v8": "s31/ev_v8_", "ctl": "s31/ev_ctl_", "c128": "s32/ev_c128_", "c64l": "s32/ev_c64l_"}


def main() -> None:
    print("| set | spp | OIDN flip (v8's eval / c128's) | " + " | ".join(TAGS) + " | " +
          " | ".join(f"edit {t}" for t in TAGS) + " |")
    print("|---|---|---|" + "---|" * 2 * len(TAGS))
    for s in sys.argv[1:]:
        runs = {t: means(p + s) for t, p in TAGS.items() if os.path.exists(p + s + "/eval.csv")}
        if "v8" not in runs:
            continue
        for spp in sorted({k[0] for k in runs["v8"]}):
            cell = lambda t, m, base: (f"{runs[t][(spp, 'ranad', m)] / runs[t][(spp, base, m)]:.3f}"  # noqa: E731
                                       if t in runs else "")
            o = " / ".join(f"{runs[t][(spp, 'oidn', 'flip')]:.4f}" for t in ("v8", "c128") if t in runs)
            print(f"| `{s}` | {spp} | {o} | " + " | ".join(cell(t, "flip", "oidn") for t in TAGS) + " | " +
                  " | ".join(cell(t, "comp", "recolour") for t in TAGS) + " |")


if __name__ == "__main__":
    main()
