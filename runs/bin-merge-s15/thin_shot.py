"""The bundled shot (examples/synth_shot, 3 frames at 16 spp) denoised by the sequence default as it is and with
every bin split in two (as tests/test_binmerge.py's `thin`), merged and unmerged: SMAPE of the centre frame's
flattened beauty against its reference. usage: thin_shot.py"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))
from test_binmerge import thin  # noqa: E402

from ranad_core import metrics  # noqa: E402
from ranad_core.denoise import denoise_window  # noqa: E402
from ranad_core.exr import read_deep  # noqa: E402
from ranad_core.model.store import default_model, load_model  # noqa: E402

shot = Path(__file__).resolve().parents[2] / "examples" / "synth_shot"
model = load_model(default_model(True)).model
frames = [read_deep(shot / f"noisy_spp16.{i:04d}.exr") for i in range(3)]
frames = [f.with_values(f.values.astype(np.float32)) for f in frames]
ref = metrics.flat_rgb(read_deep(shot / "reference_spp16.0001.exr"))
thins = [thin(f, 2) for f in frames]


def score(imgs, gap=None):
    return metrics.smape(ref, metrics.flat_rgb(denoise_window(model, imgs, 1, merge_gap=gap).image))


print(f"noisy {metrics.smape(ref, metrics.flat_rgb(frames[1])):.4f}; as rendered {score(frames):.4f}; "
      f"thin, merged {score(thins):.4f}; thin, unmerged {score(thins, 0.0):.4f}")
