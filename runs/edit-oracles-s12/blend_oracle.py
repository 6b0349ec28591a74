"""The model's output blended toward itself recoloured to flat OIDN (each bin's colour (1 - g) out + g
recolour(out, OIDN)), per gain g: edit FLIP against recolour's and flat FLIP against OIDN's.

Usage: python runs/edit-oracles-s12/blend_oracle.py DATASET MODEL SPP [deepz|deepoid]"""
import sys
import numpy as np
from ranad_core.channels import RGB
from ranad_core.metrics import flat_rgb, composite_edit, flip, split_depth
from ranad_core.model.store import load_model

from common import scenes
from ranad_core.baselines import recolour

def blend(a, b, g):
    v = a.values.copy(); idx = [a.channels.index(c) for c in RGB]
    bi = [b.channels.index(c) for c in RGB]
    v[:, idx] = (1 - g) * a.values[:, idx] + g * b.values[:, bi]
    return a.with_values(v)

def main(dataset, model_name, spp, kind="deepz"):
    model = load_model(model_name).model
    tot, n = {}, 0
    for name, noisy, ref, out, base, fl in scenes(dataset, model, spp, kind):
        rc_out = recolour(out, fl)
        counts = np.diff(ref.offsets)
        z = split_depth(ref); target = composite_edit(ref, z)
        cases = {"recolour": base}
        for g in (0, 0.25, 0.5, 0.75, 1.0):
            cases[f"g{g}"] = blend(out, rc_out, g)
        single = np.repeat(counts == 1, counts).astype(np.float32)[:, None]
        v = out.values.copy(); idx = [out.channels.index(c) for c in RGB]
        v[:, idx] = (1 - single) * out.values[:, idx] + single * rc_out.values[:, idx]
        cases["g1 single-bin"] = out.with_values(v)
        row = {k: flip(target, composite_edit(c, z)) for k, c in cases.items()}
        fr = flat_rgb(ref)
        row["flat oidn"] = flip(fr, fl.reshape(fr.shape))
        for g in (0, 0.5, 1.0):
            row[f"flat g{g}"] = flip(fr, flat_rgb(cases[f"g{g}"]))
        print(name, f"multi {np.mean(counts > 1):.2f}",
              " ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)
        for k, v in row.items(): tot[k] = tot.get(k, 0) + v
        n += 1
    r = tot["recolour"]
    print("mean", " | ".join(f"{k} {v/n:.4f} ({v/r:.3f}x)" for k, v in tot.items() if not k.startswith("flat")))
    o = tot["flat oidn"]
    print("flat", " | ".join(f"{k} {v/n:.4f} ({v/o:.3f}x)" for k, v in tot.items() if k.startswith("flat")))

if __name__ == "__main__":
    main(*sys.argv[1:])
