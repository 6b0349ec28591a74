"""Writes the two files of this folder from a `ranad synth` render (see README.md): a 32x32 crop of a layers-family
scene, the noisy frame with the channels the model reads and the reference with its beauty and depths.

Usage: python tests/data/ranad-synth/make_layer_stack.py HELDOUT_SET_FOLDER"""
import sys
from pathlib import Path

from ranad_core.exr import read_deep, write_deep

HERE = Path(__file__).resolve().parent
SCENE, Y, X, SIZE = "scene_0003", 48, 32, 32
NOISY = ("R", "G", "B", "A", "Z", "ZBack", "diffuse", "specular", "albedo", "N")
REFERENCE = ("R", "G", "B", "A", "Z", "ZBack")


def main(folder):
    for kind, chans, out in (("noisy", NOISY, "layer_stack_noisy_spp16.exr"),
                             ("reference", REFERENCE, "layer_stack_reference_spp16.exr")):
        img = read_deep(Path(folder) / SCENE / "deepz" / f"{kind}_spp16.0000.exr")
        x0, y0 = img.data_window[0] + X, img.data_window[1] + Y
        crop = img.crop((x0, y0, x0 + SIZE - 1, y0 + SIZE - 1))
        write_deep(HERE / out, crop.select([c for c in crop.channels if c in chans or c.split(".")[0] in chans]))


if __name__ == "__main__":
    main(sys.argv[1])
