"""Session 30 study: light matching with a clamp from the noisy render's own uncertainty. `ranad eval` with
`lightmatch.pixel_gain` replaced: the gain box_R(target) / box_R(current) is held within 1 +- max(CLAMP - 1,
K * SE / box_R(current)), SE the standard error of the noisy box mean (the box's sample standard deviation over
sqrt of its pixel count, pixels taken as independent, as in a box-filtered render), instead of within the fixed 2%:
where the noisy render's local light is well determined ranad's may move further toward it (glass_light.py: a glass
scene 2.9% short of the reference's light over its box means comes within 0.1%). Not the product's code.
Usage: python se_clamp_eval.py K SET OUT [CAP]   (from the data folder; CAP: the most the gain may move,
e.g. 0.05; without it a fall is held at 50% and a rise is not bounded)"""
import sys

import numpy as np
import torch

from ranad_core import lightmatch
from ranad_core.lightmatch import box_mean

K = float(sys.argv[1])
CAP = float(sys.argv[4]) if len(sys.argv) > 4 else None   # None: falls held at 50%, rises unbounded


def pixel_gain(target, current, radius=lightmatch.RADIUS, clamp=lightmatch.CLAMP):
    t = np.maximum(np.nan_to_num(target), 0)
    c = np.maximum(np.nan_to_num(current), 0)
    bt, bc = box_mean(t, radius), box_mean(c, radius)
    h, w = t.shape   # pixels in each box, cut at the frame's edges as box_mean cuts it
    ny = np.clip(np.arange(h) + radius + 1, 0, h) - np.clip(np.arange(h) - radius, 0, h)
    nx = np.clip(np.arange(w) + radius + 1, 0, w) - np.clip(np.arange(w) - radius, 0, w)
    n = ny[:, None] * nx[None, :]
    se = np.sqrt(np.maximum(box_mean(t * t, radius) - bt * bt, 0) / n)
    g = np.divide(bt, bc, out=np.ones_like(bt), where=(bc > 0) & (bt > 0))
    lim = np.maximum(clamp - 1, K * np.divide(se, bc, out=np.zeros_like(se), where=bc > 0))
    if CAP is None:   # as chain5.sh ran
        return np.clip(g, 1 - np.minimum(lim, 0.5), 1 + lim).astype(np.float32)
    lim = np.minimum(lim, CAP)
    return np.clip(g, 1 - lim, 1 + lim).astype(np.float32)


lightmatch.pixel_gain = pixel_gain
torch.set_num_threads(2)
from ranad_cli.main import cli  # noqa: E402

sys.argv = ["ranad", "eval", sys.argv[2], "-o", sys.argv[3], "--held-out", "glass,layers,interior,fog", "--grid", "0"]
cli(prog_name="ranad")
