"""The frames shares.py, edit_plate.py and edit_parts.py look at (session 26): per deep-Z pair of 4, 16 or 64 spp of a
set, (pair, noisy image, reference, the scores' split depth), and the model named on the command line."""
import sys

from ranad_core import metrics
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model
from ranad_core.train.data import find_pairs


def model_from_argv():
    """The model of argv[2] (default: the shipped single-frame one)."""
    return load_model(sys.argv[2] if len(sys.argv) > 2 else "cpu-small-pdl-gza-v7").model


def deepz_frames(root: str):
    """Yields (pair, noisy, reference, split depth)."""
    for pair in find_pairs(root):
        if pair.kind != "deepz" or pair.spp not in (4, 16, 64):
            continue
        noisy, ref = read_deep(pair.noisy), read_deep(pair.reference)
        yield pair, noisy, ref, metrics.split_depth(ref)
