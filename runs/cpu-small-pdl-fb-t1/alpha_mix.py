"""Edit FLIP (ratio of means against OIDN + recolour's) with the model's per-bin alpha moved toward the noisy
alpha, three ways: opaque bins kept opaque (alpha 1 where the noisy alpha is 1: every bin, or the back bins of
multi-bin pixels only); a mix, (1 - g) model + g noisy; and a soft threshold, the noisy alpha moved toward the
model's but stopped t short of it (nothing where they differ by less than t).

Usage (from the folder that holds the sets): python runs/cpu-small-pdl-fb-t1/alpha_mix.py SET MODEL SPP [KIND]"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "edit-oracles-s12"))
sys.path.insert(0, os.path.dirname(__file__))
from alpha_classes import place  # noqa: E402
from common import scenes, set_alpha  # noqa: E402
from ranad_core.channels import ALPHA  # noqa: E402
from ranad_core.metrics import composite_edit, flip, split_depth  # noqa: E402
from ranad_core.model.store import load_model  # noqa: E402

MIX = (0.15, 0.3, 0.5)
SOFT = (0.01, 0.02, 0.04)


def main(dataset, model_name, spp, kind="deepz"):
    model = load_model(model_name).model
    tot, n = {}, 0
    for _, noisy, ref, out, base, _ in scenes(dataset, model, spp, kind):
        an, ao = noisy.channel(ALPHA), out.channel(ALPHA)
        z = split_depth(ref)
        target = composite_edit(ref, z)
        row = {"recolour": flip(target, composite_edit(base, z)), "model": flip(target, composite_edit(out, z))}
        opaque = an >= 1 - 1e-6
        for name, sel in (("opaque all", opaque), ("opaque back", opaque & (place(noisy) == "back"))):
            row[name] = flip(target, composite_edit(set_alpha(out, np.where(sel, 1, ao).astype(np.float32)), z))
        for g in MIX:
            row[f"mix {g}"] = flip(target, composite_edit(set_alpha(out, ((1 - g) * ao + g * an)
                                                                   .astype(np.float32)), z))
        d = ao - an
        for t in SOFT:
            soft = an + np.sign(d) * np.maximum(np.abs(d) - t, 0)
            row[f"soft {t}"] = flip(target, composite_edit(set_alpha(out, soft.astype(np.float32)), z))
        for k, v in row.items():
            tot[k] = tot.get(k, 0) + v
        n += 1
    print(f"{dataset} {model_name} {spp} spp {kind}: " + " | ".join(f"{k} {v / tot['recolour']:.3f}"
                                                                    for k, v in tot.items() if k != "recolour"))


if __name__ == "__main__":
    main(*sys.argv[1:])
