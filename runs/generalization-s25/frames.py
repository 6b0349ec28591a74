"""The frames fireflies.py and energy.py look at (session 25): per scene of a set (or the ones named) and per spp of
4, 16, 64 that it has, the deep-Z centre frame's flat luminance of the reference and of the noisy input, a model's
output and flat OIDN (in that order), with Rec. 709 weights (ranad's LUMA)."""
import os

from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep
from ranad_core.model.prior import LUMA
from ranad_core.model.store import load_model


def luminances(root: str, spec: str, scenes=()):
    """Yields (scene, spp, reference luminance [H, W], [noisy, model, OIDN luminance])."""
    model = load_model(spec).model
    for sc in sorted(os.listdir(root)):
        if scenes and sc not in scenes or not os.path.isdir(os.path.join(root, sc, "deepz")):
            continue
        for spp in (4, 16, 64):
            p = os.path.join(root, sc, "deepz", f"noisy_spp{spp}.0000.exr")
            if not os.path.exists(p):
                continue
            noisy = read_deep(p)
            ref = read_deep(os.path.join(root, sc, "deepz", f"reference_spp{spp}.0000.exr"))
            out = denoise_window(model, [noisy], 0).image
            flats = (metrics.flat_rgb(noisy), metrics.flat_rgb(out), oidn_flat(noisy))
            yield sc, spp, metrics.flat_rgb(ref) @ LUMA, [f @ LUMA for f in flats]
