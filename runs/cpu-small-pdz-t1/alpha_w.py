"""Edit FLIP of a depth-term model on held-out deep-Z 16-spp frames with the alpha reconstruction's depth weight forced
to W (argv[3:]; 'trained' keeps the learned ones)."""
import math, sys
import numpy as np, torch
sys.path.insert(0, "/work/main")
from ranad_core import metrics
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model
from ranad_core.model.reconstruction import DEPTH_GAIN, DEPTH_W0
from ranad_core.train.data import find_pairs
torch.set_num_threads(1)
model = load_model(sys.argv[2]).model
pairs = [p for p in find_pairs(sys.argv[1]) if p.kind == "deepz" and p.spp == 16]
saved = {n: p.detach().clone() for n, p in model.named_parameters() if n.endswith("depth_theta")}
for wv in sys.argv[3:]:
    for n, p in model.named_parameters():
        if n in saved:
            p.data.copy_(saved[n])
            if wv != "trained" and n.startswith(tuple(f"recon.{l}." for l in sys.argv[1:2] and ["alpha"])):
                p.data.fill_((math.log(float(wv)) - DEPTH_W0) / DEPTH_GAIN)
    ed, fl, am = [], [], []
    for p in pairs:
        noisy, ref = read_deep(p.noisy), read_deep(p.reference)
        out = denoise_frame(model, noisy).image
        s = metrics.deep_scores(ref, out)
        ed.append(s["comp_flip"]); fl.append(metrics.flat_scores(metrics.flat_rgb(ref), metrics.flat_rgb(out))["flip"])
        am.append(np.abs(out.channel("A") - ref.channel("A")).mean())
    print(f"alpha w {wv}: edit {np.mean(ed):.4f} flat {np.mean(fl):.4f} alpha MAE {np.mean(am):.4f}", flush=True)
