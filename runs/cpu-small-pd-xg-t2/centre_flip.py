"""Centre-frame HDR-FLIP of the single-frame default against cross-frame models, per 3-frame scene.

The quick comparison this run was steered by (one frame per shot, one kind, one spp; `ranad eval --temporal` is
the full one). Usage, from the repository root:

    python runs/cpu-small-pd-xg-t2/centre_flip.py SPP KIND CROSS[,CROSS...] DATASET [DATASET...]

e.g. `16 deepz cpu-small-pd-xk-v1,cpu-small-pd-xg-v1 heldout_g3s heldout_g3b heldout_g3`. Prints, per scene,
FLIP of the noisy frame, the single-frame model and each cross-frame model, then per dataset the means and each
cross-frame model's ratio to the single-frame one. With 16 deepz the bundled shot is scored too ("example").
"""
import sys
from pathlib import Path

import numpy as np
import torch

from ranad_core import metrics
from ranad_core.denoise import denoise_window
from ranad_core.evaluate import read_deep
from ranad_core.model.store import DEFAULT_MODEL, load_model

torch.set_num_threads(2)
spp, kind, crosses = int(sys.argv[1]), sys.argv[2], sys.argv[3].split(",")
single = load_model(DEFAULT_MODEL).model
models = [load_model(c).model for c in crosses]
cases = []
for ds in sys.argv[4:]:
    for sc in sorted(Path(ds).glob("scene_*")):
        d = sc / kind
        if (d / f"reference_spp{spp}.0001.exr").exists() and (d / f"noisy_spp{spp}.0002.exr").exists():
            cases.append((f"{Path(ds).name}/{sc.name}", [d / f"noisy_spp{spp}.{f:04d}.exr" for f in range(3)],
                          d / f"reference_spp{spp}.0001.exr"))
if spp == 16 and kind == "deepz":
    ex = Path("examples/synth_shot")
    cases.append(("example/shot", [ex / f"noisy_spp16.{f:04d}.exr" for f in range(3)], ex / "reference_spp16.0001.exr"))
print("case noisy single", " ".join(crosses), flush=True)
res = {}
for name, paths, refp in cases:
    imgs = [read_deep(str(p)) for p in paths]
    ref = metrics.flat_rgb(read_deep(str(refp)))
    row = [metrics.flip(ref, metrics.flat_rgb(imgs[1])),
           metrics.flip(ref, metrics.flat_rgb(denoise_window(single, [imgs[1]], 0).image))]
    row += [metrics.flip(ref, metrics.flat_rgb(denoise_window(m, imgs, 1).image)) for m in models]
    res.setdefault(name.split("/")[0], []).append(row)
    print(name, " ".join(f"{v:.4f}" for v in row), flush=True)
for k, rows in res.items():
    m = np.mean(rows, 0)
    print("MEAN", k, " ".join(f"{v:.4f}" for v in m), "ratio cross/single", " ".join(f"{v / m[1]:.3f}" for v in m[2:]))
