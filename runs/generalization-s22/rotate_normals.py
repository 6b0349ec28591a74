"""A copy of a `ranad synth` set whose noisy frames' normals are in another space: every normal (N.X, N.Y, N.Z) of a
scene turned by one random rotation, as a renderer that writes camera-space normals, or world-space ones for a
camera facing another way, gives them. Radiance, albedo, depth and the references are unchanged, so `ranad eval`
on the copy against the original measures how much the model's output depends on the normals' space.

Usage: python runs/generalization-s22/rotate_normals.py SRC DST [--seed 0] [--yaw]   (--yaw: about the y axis only,
       a camera turned about the vertical)
"""
import argparse
import glob
import os
import shutil
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core.exr import read_deep, write_deep  # noqa: E402
from ranad_core.train.data import random_rotation, rotated_normals  # noqa: E402


def rotation(rng, yaw_only):
    """A yaw of 0.5 rad or more either way (yaw_only), else a uniform rotation, as `ranad train --rotate-normals`
    draws them."""
    if yaw_only:
        a = rng.uniform(0.5, 2 * np.pi - 0.5)
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return random_rotation(rng)


ap = argparse.ArgumentParser()
ap.add_argument("src")
ap.add_argument("dst")
ap.add_argument("--seed", type=int, default=0)
ap.add_argument("--yaw", action="store_true")
a = ap.parse_args()
rng = np.random.default_rng(a.seed)
for scene in sorted(glob.glob(os.path.join(a.src, "scene_*"))):
    out = os.path.join(a.dst, os.path.basename(scene))
    shutil.copytree(scene, out, dirs_exist_ok=True)
    rot = rotation(rng, a.yaw)
    for f in glob.glob(os.path.join(out, "*", "noisy_*.exr")):
        write_deep(f, rotated_normals(read_deep(f), rot))
    print(out, np.round(rot, 3).tolist())
