"""Session 33 (chain4.sh): v8 (session 32's evaluations) and v9 on session 32's reduced copies of three held-out
sets, with guides (base) and without albedo and normal (noaux), each against flat OIDN and OIDN-then-recolour on
the same files: deep-Z, held-out group, means over the 8 scenes; ranad's own flat FLIP in brackets.

Usage: python guideless.py SET... (run in the data folder; evaluations in s32/ and s33/)"""
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "generalization-s32"))
from reduced import ratio_cells  # noqa: E402

COLUMNS = (("v8", "base", "s32/ev_v8"), ("v9", "base", "s33/ev_v9"), ("v8", "noaux", "s32/ev_v8"),
           ("v9", "noaux", "s33/ev_v9"))


def main() -> None:
    print("| set | spp | " + " | ".join(f"{m} {k} flat" for m, k, _ in COLUMNS) + " | " +
          " | ".join(f"{m} {k} edit" for m, k, _ in COLUMNS) + " |")
    print("|---|---|" + "---|" * 2 * len(COLUMNS))
    for s in sys.argv[1:]:
        for spp in (4, 16):
            flat, edit = zip(*(ratio_cells(f"{p}_red32_{k}_{spp}_{s}", spp, own=True) for _, k, p in COLUMNS))
            print(f"| `{s}` | {spp} | " + " | ".join(flat) + " | " + " | ".join(edit) + " |")


if __name__ == "__main__":
    main()
