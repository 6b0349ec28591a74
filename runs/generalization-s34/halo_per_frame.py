"""Session 34: the tile-halo mismatch (ranad_core/halo.py's measure) of a model on each of v6's halo frames
(runs/generalization-s23/export.sh) at 16 px, frame by frame: which frame decides the measured halo.

Usage: python halo_per_frame.py MODEL...   (run in the data folder)"""
import sys

from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.halo import mismatch
from ranad_core.model.store import load_model

FRAMES = ([f"heldout_g1sg8/scene_000{s}/{k}/noisy_spp16.0000.exr" for s in range(4) for k in ("deepz", "deepoid")]
          + [f"heldout_g1sg8/scene_000{s}/deepz/noisy_spp4.0000.exr" for s in range(2)]
          + [f"train_g33_win/scene_000{s}/deepz/noisy_spp16.0000.exr" for s in range(2)]
          + ["heldout_g1fog/scene_0000/deepz/noisy_spp16.0000.exr",
             "heldout_g1fog_boxsob/scene_0000/deepz/noisy_spp16.0000.exr"])

for spec in sys.argv[1:]:
    model = load_model(spec).model.eval()
    print(f"{spec}")
    for f in FRAMES:
        img = read_deep(f)
        whole = denoise_frame(model, img).image.values
        mean, worst = mismatch(denoise_frame(model, img, tile=32, halo=16).image.values, whole)
        print(f"  {f}: halo 16 px, mean {mean:.1e}, worst bin {worst:.1e}")
