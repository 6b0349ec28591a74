"""What every oracle script here starts from: a held-out set's scenes with the model's output and the baseline's."""
import glob
import os

from ranad_core.baselines import oidn_flat, recolour
from ranad_core.channels import ALPHA
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.metrics import with_depths_of


def scenes(dataset, model, spp, kind="deepz"):
    """Per scene of `dataset`, in order: (name, noisy, reference, the model's output, OIDN then recolour, OIDN's
    flat image [H, W, 3]); the two deep outputs carry the reference's depths, as `ranad eval` scores the edit."""
    for scene in sorted(glob.glob(os.path.join(dataset, "scene_*"))):
        noisy = read_deep(f"{scene}/{kind}/noisy_spp{spp}.0000.exr")
        ref = read_deep(f"{scene}/{kind}/reference_spp{spp}.0000.exr")
        out = with_depths_of(denoise_frame(model, noisy).image, ref)
        flat = oidn_flat(noisy)
        yield os.path.basename(scene), noisy, ref, out, with_depths_of(recolour(noisy, flat), ref), flat


def set_alpha(img, alpha):
    """`img` with its per-bin alpha replaced."""
    v = img.values.copy()
    v[:, img.channels.index(ALPHA)] = alpha
    return img.with_values(v)
