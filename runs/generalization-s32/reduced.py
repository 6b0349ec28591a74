"""Session 32 (chain3.sh): the shipped default on reduced copies of held-out sets (session 15's perturb.py: base, a
copy; noaux, no albedo or normal; rgbaonly, R G B A Z ZBack only), each against flat OIDN and OIDN-then-recolour on
the same reduced files: deep-Z, held-out group, means over the 8 scenes; ranad's own flat FLIP in brackets.

Usage: python reduced.py SET... (run in the data folder; evaluations in s32/)"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s31"))
from cross import means  # noqa: E402

KINDS = ("base", "noaux", "rgbaonly")


def main() -> None:
    print("| set | spp | " + " | ".join(f"{k} flat" for k in KINDS) + " | " + " | ".join(f"{k} edit" for k in KINDS)
          + " |")
    print("|---|---|" + "---|" * 2 * len(KINDS))
    for s in sys.argv[1:]:
        for spp in (4, 16):
            flat, edit = [], []
            for k in KINDS:
                f = f"s32/ev_v8_red32_{k}_{spp}_{s}"
                if not os.path.exists(f + "/eval.csv"):
                    flat.append("")
                    edit.append("")
                    continue
                m = means(f)
                r = m[(spp, "ranad", "flip")]
                flat.append(f"{r / m[(spp, 'oidn', 'flip')]:.3f} ({r:.4f})")
                comp = m.get((spp, "ranad", "comp"))
                rc = m.get((spp, "recolour", "comp"))
                edit.append(f"{comp / rc:.3f}" if comp and rc else "n/a")
            print(f"| `{s}` | {spp} | " + " | ".join(flat) + " | " + " | ".join(edit) + " |")


if __name__ == "__main__":
    main()
