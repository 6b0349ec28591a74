"""Session 32 (chain3.sh): the shipped default on reduced copies of held-out sets (session 15's perturb.py: base, a
copy; noaux, no albedo or normal; rgbaonly, R G B A Z ZBack only), each against flat OIDN and OIDN-then-recolour on
the same reduced files: deep-Z, held-out group, means over the 8 scenes; ranad's own flat FLIP in brackets.

Usage: python reduced.py SET... (run in the data folder; evaluations in s32/)"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s31"))
from cross import means  # noqa: E402

KINDS = ("base", "noaux", "rgbaonly")


def ratio_cells(folder: str, spp: int, own: bool = False) -> tuple[str, str]:
    """(flat FLIP / OIDN's, edit FLIP / recolour's) of the evaluation in `folder` at `spp` as table cells, with
    ranad's own flat FLIP in brackets when `own`; empty cells where the evaluation is missing. Shared by noaux.py."""
    if not os.path.exists(folder + "/eval.csv"):
        return "", ""
    m = means(folder)
    r = m[(spp, "ranad", "flip")]
    flat = f"{r / m[(spp, 'oidn', 'flip')]:.3f}" + (f" ({r:.4f})" if own else "")
    comp, rc = m.get((spp, "ranad", "comp")), m.get((spp, "recolour", "comp"))
    return flat, f"{comp / rc:.3f}" if comp and rc else "n/a"


def main() -> None:
    print("| set | spp | " + " | ".join(f"{k} flat" for k in KINDS) + " | " + " | ".join(f"{k} edit" for k in KINDS)
          + " |")
    print("|---|---|" + "---|" * 2 * len(KINDS))
    for s in sys.argv[1:]:
        for spp in (4, 16):
            flat, edit = zip(*(ratio_cells(f"s32/ev_v8_red32_{k}_{spp}_{s}", spp, own=True) for k in KINDS))
            print(f"| `{s}` | {spp} | " + " | ".join(flat) + " | " + " | ".join(edit) + " |")


if __name__ == "__main__":
    main()
