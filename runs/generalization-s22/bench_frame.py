"""The held-out 1080p bench frame's source without its whole set: scene 5 of `heldout_g1` (cpu-small-p-v1's card:
seed 1002, presets glass and layers, 128x128, 1 frame) rendered at 16 spp, deep-Z only. The noisy frame's samples
depend only on the scene's seed, the frame and the spp (dataset.make_one), so it is the same file as the full set's
`heldout_g1/scene_0005/deepz/noisy_spp16.0000.exr`; the reference is rendered at 16 spp only to skip its cost (the
bench reads the noisy frame alone).

Usage: python runs/generalization-s22/bench_frame.py OUT_FOLDER   (then bench/denoise.py --real "" --frame
       OUT_FOLDER/scene_0005/deepz/noisy_spp16.0000.exr)
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
from ranad_core.synth import dataset  # noqa: E402

cfg = dataset.SynthConfig(out=sys.argv[1], scenes=6, size=128, frames=1, spp=(16,), ref_spp=16, seed=1002,
                          presets=("glass", "layers"), kinds=("deepz",))
print(dataset.make_one(cfg, 5)["files"])
