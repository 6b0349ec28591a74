"""Where the glass family's compositing-edit error is: the flat colour, the split of it among a pixel's bins, or
alpha. Per scene of one family, edit FLIP (`metrics.composite_edit` against the reference's, as `ranad eval`
scores it) of: ranad; OIDN then recolour; ranad's flattened result handed out by the noisy bins' shares
(`baselines.recolour` with ranad's flat image instead of OIDN's: ranad's flat colour, recolour's split and alpha);
ranad with the noisy alpha; ranad with the reference's alpha; ranad with the reference's split of its own flat
colour (recolour of the reference by ranad's flat). Ratios of sums against recolour's (< 1: better).

Usage (from the folder that holds the sets): python runs/glass-edit-s14/split_oracle.py SET MODEL SPP [KIND] [FAMILY]"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "edit-oracles-s12"))
from common import scenes, set_alpha  # noqa: E402
from ranad_core.baselines import recolour  # noqa: E402
from ranad_core.channels import ALPHA  # noqa: E402
from ranad_core.metrics import composite_edit, flat_rgb, flip, split_depth  # noqa: E402
from ranad_core.model.store import load_model  # noqa: E402


def main(dataset, model_name, spp, kind="deepz", family="glass"):
    model = load_model(model_name).model
    tot = {}
    for name, noisy, ref, out, base, flat in scenes(dataset, model, spp, kind):
        fam = json.load(open(os.path.join(dataset, name, "manifest.json"))).get("preset", "")
        if family not in (fam, "all"):
            continue
        z = split_depth(ref)
        target = composite_edit(ref, z)
        out_flat = flat_rgb(out)
        row = {"recolour": flip(target, composite_edit(base, z)),
               "ranad": flip(target, composite_edit(out, z)),
               "ranad flat, noisy split": flip(target, composite_edit(recolour(noisy.with_values(
                   _depths(noisy, ref)), out_flat), z)),
               "ranad, noisy alpha": flip(target, composite_edit(set_alpha(out, noisy.channel(ALPHA)), z)),
               "ranad, reference alpha": flip(target, composite_edit(set_alpha(out, ref.channel(ALPHA)), z)),
               "ranad flat, reference split": flip(target, composite_edit(recolour(ref, out_flat), z)),
               "OIDN flat, reference split": flip(target, composite_edit(recolour(ref, flat), z))}
        for k, v in row.items():
            tot[k] = tot.get(k, 0) + v
    print(f"{dataset} {model_name} {spp} spp {kind} {family}: " + " | ".join(
        f"{k} {v / tot['recolour']:.3f}" for k, v in tot.items() if k != "recolour"))


def _depths(noisy, ref):
    """noisy's values with the reference's depths (as scenes() gives the outputs)."""
    v = noisy.values.copy()
    for c in ("Z", "ZBack"):
        if c in noisy.channels:
            v[:, noisy.channels.index(c)] = ref.channel(c)
    return v


if __name__ == "__main__":
    main(*sys.argv[1:])
