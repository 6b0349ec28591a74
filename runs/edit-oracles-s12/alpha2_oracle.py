"""Edit FLIP when the model's alpha reconstruction is applied k times (K(K(a)) for k = 2: a wider support with
the learned edge-aware weights), and the alpha MAE against the reference.

Usage: python runs/edit-oracles-s12/alpha2_oracle.py DATASET MODEL SPP [deepz|deepoid]"""
import sys
import numpy as np, torch
from ranad_core.channels import ALPHA, detect
from ranad_core.denoise import _model_frame, model_features
from ranad_core.model.inputs import prepare
from ranad_core.deep import unsort
from ranad_core.metrics import composite_edit, flip, split_depth
from ranad_core.model.store import load_model

from common import scenes, set_alpha

def main(dataset, model_name, spp, kind="deepz"):
    model = load_model(model_name).model
    tot, n = {}, 0
    for name, noisy, ref, out, base, _ in scenes(dataset, model, spp, kind):
        fr = _model_frame(noisy, detect(noisy), model_features(model), None)
        inp = prepare(fr.srt, fr.stats, fr.features, fr.scale)
        alphas = {}
        with torch.inference_mode():
            emb = model.embeddings(inp).half().float()
            a = inp.layers["alpha"]
            for k in range(1, 5):
                a = model.reconstruct_layer("alpha", emb, inp, a)
                alphas[k] = np.clip(unsort(a.numpy(), fr.perm)[:, 0], 0, 1)
        if n == 0:
            print("k=1 vs output alpha", float(np.abs(alphas[1] - out.channel(ALPHA)).max()))
        z = split_depth(ref); target = composite_edit(ref, z)
        cases = {"recolour": base, "model": out}
        for k in (2, 3, 4):
            cases[f"k{k}"] = set_alpha(out, alphas[k])
        row = {k: flip(target, composite_edit(c, z)) for k, c in cases.items()}
        ar = ref.channel(ALPHA)
        for k in (1, 2, 3):
            row[f"mae k{k}"] = float(np.abs(alphas[k] - ar).mean())
        print(name, " ".join(f"{k} {v:.4f}" for k, v in row.items()), flush=True)
        for k, v in row.items(): tot[k] = tot.get(k, 0) + v
        n += 1
    r = tot["recolour"]
    print("mean", " | ".join(f"{k} {v/n:.4f} ({v/r:.3f}x)" for k, v in tot.items()))

if __name__ == "__main__":
    main(*sys.argv[1:])
