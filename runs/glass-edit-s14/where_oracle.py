"""Which pixels carry the glass edit's alpha error: the HDR-FLIP error map of the edit (`metrics.composite_edit`)
with the model's alpha and with the noisy alpha, averaged over pixel classes of the noisy input (empty; one bin,
opaque or not; several bins), and each class's share of the image's mean.

Usage (from the folder that holds the sets): python runs/glass-edit-s14/where_oracle.py SET MODEL SPP [FAMILY]"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "edit-oracles-s12"))
from common import scenes, set_alpha  # noqa: E402
from ranad_core.channels import ALPHA  # noqa: E402
from ranad_core.metrics import composite_edit, split_depth  # noqa: E402
from ranad_core.model.store import load_model  # noqa: E402


def flip_map(ref, test):
    import flip_evaluator
    ref = np.ascontiguousarray(np.maximum(np.nan_to_num(ref), 0), np.float32)
    test = np.ascontiguousarray(np.maximum(np.nan_to_num(test), 0), np.float32)
    return flip_evaluator.evaluate(ref, test, "HDR", applyMagma=False)[0][..., 0]


def main(dataset, model_name, spp, family="glass"):
    model = load_model(model_name).model
    acc = {}
    for name, noisy, ref, out, base, _ in scenes(dataset, model, spp, "deepz"):
        if json.load(open(os.path.join(dataset, name, "manifest.json")))["preset"] != family:
            continue
        z = split_depth(ref)
        target = composite_edit(ref, z)
        n = noisy.counts.reshape(target.shape[:2])
        opaque = np.zeros(noisy.num_pixels, bool)
        an = noisy.channel(ALPHA)
        single = noisy.counts == 1
        opaque[single] = an[noisy.offsets[:-1][single]] >= 1 - 1e-6
        opaque = opaque.reshape(n.shape)
        cls = np.where(n == 0, "empty", np.where(n > 1, "several bins", np.where(opaque, "one, opaque", "one, not")))
        maps = {"model alpha": flip_map(target, composite_edit(out, z)),
                "noisy alpha": flip_map(target, composite_edit(set_alpha(out, an), z)),
                "recolour": flip_map(target, composite_edit(base, z))}
        for c in ("empty", "one, opaque", "one, not", "several bins"):
            m = cls == c
            a = acc.setdefault(c, {"pixels": 0, **{k: 0.0 for k in maps}})
            a["pixels"] += int(m.sum())
            for k, v in maps.items():
                a[k] += float(v[m].sum())
    total = {k: sum(a[k] for a in acc.values()) for k in ("model alpha", "noisy alpha", "recolour")}
    print(f"{dataset} {model_name} {spp} spp {family}, deep-Z: class, pixels, FLIP sum share (model alpha / noisy "
          f"alpha / recolour), mean per pixel")
    for c, a in acc.items():
        p = max(a["pixels"], 1)
        print(f"  {c:13s} {a['pixels']:7d}  " + " / ".join(f"{a[k] / total[k]:.3f}" for k in total) + "   " +
              " / ".join(f"{a[k] / p:.4f}" for k in total))


if __name__ == "__main__":
    main(*sys.argv[1:])
