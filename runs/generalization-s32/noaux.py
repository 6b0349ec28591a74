"""Session 32 (chain4.sh): v8 and its two fine-tunes on its whole pool (pna2: the default share of guide-less crops,
0.2; pna5: 0.5) on chain3.sh's reduced copies (base: with guides; noaux: without), deep-Z, held-out group, means
over the 8 scenes: flat FLIP / flat OIDN's and edit FLIP / OIDN-then-recolour's on the same files.

Usage: python noaux.py SET... (run in the data folder; evaluations in s32/)"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from reduced import ratio_cells  # noqa: E402

TAGS = ("v8", "pna2", "pna5")


def main() -> None:
    print("| set | files | spp | " + " | ".join(f"{t} flat" for t in TAGS) + " | " +
          " | ".join(f"{t} edit" for t in TAGS) + " |")
    print("|---|---|---|" + "---|" * 2 * len(TAGS))
    for s in sys.argv[1:]:
        for kind in ("base", "noaux"):
            for spp in (4, 16):
                flat, edit = zip(*(ratio_cells(f"s32/ev_{t}_red32_{kind}_{spp}_{s}", spp) for t in TAGS))
                print(f"| `{s}` | {kind} | {spp} | " + " | ".join(flat) + " | " + " | ".join(edit) + " |")


if __name__ == "__main__":
    main()
