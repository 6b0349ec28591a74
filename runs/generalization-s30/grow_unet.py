"""Session 30: an init for a config with one backbone U-Net more than INIT's (cpu-small-pdl-gza-u3 from v7): the
new last U-Net is a copy of the U-Net two before it (the same bin-dropout pattern) whose residual branches all
start at zero (every block's attention output and second MLP layer, every up-merge), so the grown model computes
exactly what INIT computes and the new U-Net's weights get gradient from the first step.
Usage: python grow_unet.py INIT CONFIG OUT.safetensors"""
import json
import sys

import torch
from safetensors.torch import save_file

from ranad_core.model.config import get_config
from ranad_core.model.inputs import feature_dim
from ranad_core.model.ranad import RaNAD
from ranad_core.model.store import load_model, read_weights, resolve

init_name, cfg_name, out = sys.argv[1:4]
old = load_model(init_name).model
_, meta = read_weights(resolve(init_name))
config = get_config(cfg_name)
new = RaNAD(config, feature_dim(config.features))
state, own = old.state_dict(), new.state_dict()
n_old = old.config.unets
assert config.unets == n_old + 1, (config.unets, n_old)
grown = {}
for k in own:
    parts = k.split(".")
    if parts[:2] == ["backbone", "unets"] and int(parts[2]) == n_old:
        src = ".".join(parts[:2] + [str(n_old - 2)] + parts[3:])
        v = state[src].clone()
        zero = (parts[-2] == "out" and "attn" in parts) or (parts[-3:-1] == ["mlp", "2"]) or "merge" in parts
        grown[k] = torch.zeros_like(v) if zero else v
    else:
        grown[k] = state[k].clone()
new.load_state_dict(grown)
meta = dict(meta)
meta["model_config"] = json.dumps(config.to_dict())
meta.pop("halo", None)
save_file({k: v.contiguous() for k, v in grown.items()}, out, metadata=meta)
zeroed = sorted(k for k in grown if k.startswith(f"backbone.unets.{n_old}.") and not grown[k].any())
print("wrote", out, "from", init_name, f"U-Net {n_old} a copy of U-Net {n_old - 2}; zeroed:", len(zeroed))
for k in zeroed:
    print("  ", k)
