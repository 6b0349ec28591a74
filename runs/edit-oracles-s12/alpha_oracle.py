"""Edit FLIP of the model's output with its per-bin alpha replaced by the noisy alpha, the mean of the two, or the
reference's; and recolour's with the model's alpha.

Usage: python runs/edit-oracles-s12/alpha_oracle.py DATASET MODEL SPP [deepz|deepoid]"""
import sys
import numpy as np
from ranad_core.channels import ALPHA
from ranad_core.metrics import composite_edit, flip, split_depth
from ranad_core.model.store import load_model

from common import scenes, set_alpha

def main(dataset, model_name, spp, kind="deepz"):
    model = load_model(model_name).model
    tot, n = {}, 0
    for name, noisy, ref, out, base, _ in scenes(dataset, model, spp, kind):
        an, ao, ar = noisy.channel(ALPHA), out.channel(ALPHA), ref.channel(ALPHA)
        z = split_depth(ref); target = composite_edit(ref, z)
        cases = {"recolour": base, "model": out, "noisy alpha": set_alpha(out, an),
                 "mean alpha": set_alpha(out, 0.5 * (an + ao)), "ref alpha": set_alpha(out, ar),
                 "recolour+model alpha": set_alpha(base, ao)}
        row = {k: flip(target, composite_edit(c, z)) for k, c in cases.items()}
        row["alpha mae model"] = float(np.abs(ao - ar).mean()); row["alpha mae noisy"] = float(np.abs(an - ar).mean())
        print(name, " ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)
        for k, v in row.items(): tot[k] = tot.get(k, 0) + v
        n += 1
    r = tot["recolour"]
    print("mean", " | ".join(f"{k} {v/n:.4f} ({v/r:.3f}x)" for k, v in tot.items()))

if __name__ == "__main__":
    main(*sys.argv[1:])
