"""Session 28: an init for a config whose diffuse reconstruction has one scale more than v7's: the new scale's
modules start as copies of the coarsest old scale's (q, k, head mix; its relative-position bias centred in the
larger table), its mixer row as the coarsest's with the bias lowered by SHIFT, so the new scale carries a share of
the mix from the start and gets gradient. Usage: python grow_init.py INIT CONFIG OUT.safetensors SHIFT"""
import json
import sys

import torch
from safetensors.torch import save_file

from ranad_core.model.config import get_config
from ranad_core.model.inputs import feature_dim
from ranad_core.model.ranad import RaNAD
from ranad_core.model.store import load_model, read_weights, resolve

init_name, cfg_name, out, shift = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
old = load_model(init_name).model
_, meta = read_weights(resolve(init_name))
config = get_config(cfg_name)
new = RaNAD(config, feature_dim(config.features))
state, own = old.state_dict(), new.state_dict()
grown = {}
for k, v in own.items():
    if k in state and state[k].shape == v.shape:
        grown[k] = state[k].clone()
for layer, rc in config.recon.items():
    S_old = old.config.recon[layer].scales
    for S in range(S_old, rc.scales):
        for mod, src_i, dst_i in (("down", S - 2, S - 1), ("per_scale", S - 1, S)):
            src, dst = f"recon.{layer}.{mod}.{src_i}.", f"recon.{layer}.{mod}.{dst_i}."
            for k, v in own.items():
                if not k.startswith(dst):
                    continue
                sv = grown[src + k[len(dst):]]
                if k.endswith(".bias") and v.dim() == 3:   # relative-position bias table, centred
                    t = torch.zeros_like(v)
                    o = (v.shape[1] - sv.shape[1]) // 2
                    t[:, o:o + sv.shape[1], o:o + sv.shape[2]] = sv
                    grown[k] = t
                else:
                    grown[k] = sv.clone()
        mw, mb = f"recon.{layer}.mixer.weight", f"recon.{layer}.mixer.bias"
        w, b = state[mw] if S == S_old else grown[mw], state[mb] if S == S_old else grown[mb]
        grown[mw] = torch.cat([w, w[-1:]], 0)
        grown[mb] = torch.cat([b, b[-1:] + shift], 0)
missing = sorted(set(own) - set(grown))
assert not missing, missing
new.load_state_dict(grown)
meta = dict(meta)
meta["model_config"] = json.dumps(config.to_dict())
meta.pop("halo", None)
save_file({k: v.contiguous() for k, v in grown.items()}, out, metadata=meta)
print("wrote", out, "from", init_name, "new scales:",
      {l: (old.config.recon[l].scales, rc.scales) for l, rc in config.recon.items()})
