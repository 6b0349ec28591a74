"""A copy of a model file with `layer_gate` set in its stored config, the weights untouched: how the layer gate
was measured on the shipped weights before any training with it. Not a shipped model (no training made it).

Usage: python runs/layer-gate-s14/gated_copy.py MODEL OUT.safetensors LAYER[,LAYER...]"""
import json
import sys

from safetensors import safe_open
from safetensors.torch import save_file

from ranad_core.model.store import resolve


def main(src, out, layers):
    with safe_open(str(resolve(src)), "pt") as f:
        meta = dict(f.metadata())
        state = {k: f.get_tensor(k) for k in f.keys()}
    cfg = json.loads(meta["model_config"])
    cfg["layer_gate"] = [x for x in layers.split(",") if x]
    meta["model_config"] = json.dumps(cfg)
    save_file(state, out, metadata=meta)


if __name__ == "__main__":
    main(*sys.argv[1:])
