"""Per-bin alpha error of a model against the reference, by the bin's place in its pixel (single-bin pixel; front,
middle or back bin of a multi-bin pixel) and by whether the noisy and the reference alpha are 1 (opaque): the
signed mean (bias) and the mean absolute error, the model's beside the noisy input's.

Usage (from the folder that holds the sets): python runs/cpu-small-pdl-fb-t1/alpha_classes.py SET MODEL SPP [KIND]"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "edit-oracles-s12"))
from common import scenes  # noqa: E402
from ranad_core.channels import ALPHA  # noqa: E402
from ranad_core.model.store import load_model  # noqa: E402


def place(img):
    """Per bin: 'single', 'front', 'middle' or 'back'."""
    n, idx = img.counts[img.pixel_index()], img.bin_index()
    return np.where(n == 1, "single", np.where(idx == 0, "front", np.where(idx == n - 1, "back", "middle")))


def main(dataset, model_name, spp, kind="deepz"):
    model = load_model(model_name).model
    acc = {}
    for _, noisy, ref, out, _, _ in scenes(dataset, model, spp, kind):
        an, ao, ar = noisy.channel(ALPHA), out.channel(ALPHA), ref.channel(ALPHA)
        where = place(noisy)
        for cls in ("single", "front", "middle", "back"):
            for opaque in (False, True):
                sel = (where == cls) & ((an >= 1 - 1e-6) & (ar >= 1 - 1e-3) if opaque else
                                        ~((an >= 1 - 1e-6) & (ar >= 1 - 1e-3)))
                d = acc.setdefault((cls, opaque), np.zeros(5))
                d += [sel.sum(), (ao - ar)[sel].sum(), np.abs(ao - ar)[sel].sum(), (an - ar)[sel].sum(),
                      np.abs(an - ar)[sel].sum()]
    print(f"{dataset} {model_name} {spp} spp {kind}: place, opaque (noisy and reference alpha 1), bins, "
          "model bias / MAE, noisy bias / MAE")
    for (cls, opaque), (n, b, a, bn, an_) in acc.items():
        if n:
            print(f"  {cls:6s} {'opaque' if opaque else 'other':6s} {int(n):7d}  {b / n:+.4f} / {a / n:.4f}  "
                  f"{bn / n:+.4f} / {an_ / n:.4f}")


if __name__ == "__main__":
    main(*sys.argv[1:])
