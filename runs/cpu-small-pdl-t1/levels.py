"""Bins per down-sampling level of a frame under the first bin dropout and the lattice one (layers.bin_dropout),
patterns alternating as in the U-Nets.

Usage: python runs/cpu-small-pdl-t1/levels.py FRAME.exr   (e.g. heldout_g1u/scene_0000/deepz/noisy_spp16.0000.exr)
"""
import sys

from ranad_core.exr import read_deep
from ranad_core.model import bin_dropout, prepare


def main(path: str) -> None:
    layout = prepare(read_deep(path)).layout
    print(f"{layout.bins} bins, {layout.height * layout.width} pixels")
    for lattice in (False, True):
        lay, counts = layout, []
        for level in range(1, 5):
            lay = bin_dropout(lay, (level - 1) % 2, level, lattice)[1]
            counts.append(lay.bins)
        print("lattice" if lattice else "first  ", "bins at levels 1-4:", counts)


if __name__ == "__main__":
    main(sys.argv[1])
