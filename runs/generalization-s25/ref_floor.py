"""How far a set's references are from the truth (session 25): each scene's deep-Z reference traced again with
another seed at the same sample count, binned into the same noisy layouts, and flat FLIP between the two
references (the reference-noise floor: what even a perfect denoiser scores against the set's reference is at
least about this / sqrt(2)), next to the noisy input's and ranad's FLIP from an eval folder.
Usage: python ref_floor.py SET EVAL_FOLDER [SCENES...]"""
import csv
import json
import os
import sys

import numpy as np

from ranad_core import metrics
from ranad_core.exr import read_deep
from ranad_core.synth.binning import Z_GAP_REL
from ranad_core.synth.dataset import KINDS, _worker_init
from ranad_core.synth.render import bin_noisy, noisy_samples, render_reference
from ranad_core.synth.scene import make_scene
from ranad_core.synth.trace import load_frame

_worker_init(2)
root, evf = sys.argv[1], sys.argv[2]
want = set(sys.argv[3:])
rows = list(csv.DictReader(open(os.path.join(evf, "eval.csv"))))
print("| scene | family | spp | FLIP ref_b vs ref | noisy vs ref | ranad vs ref |")
print("|---|---|---|---|---|---|")
for sc in sorted(os.listdir(root)):
    mpath = os.path.join(root, sc, "manifest.json")
    if not os.path.exists(mpath) or (want and sc not in want):
        continue
    m = json.load(open(mpath))
    spec = make_scene(m["seed"], m["preset"], m["size"], m["frames"], m["motion"])
    film = tuple(m.get("pixel_filter", ("box", 1.0)))
    frame = m["centre_frame"]
    fs = load_frame(spec, frame)
    lays = []
    for spp in m["spp"]:
        s = noisy_samples(spec, frame, spp, m["seed"] + 7919 * frame + spp, fs, m.get("sampler") == "stratified",
                          m.get("guides") == "through-specular", film)
        lays.append(bin_noisy(spec, s, spp, KINDS["deepz"], m.get("bin_gap", Z_GAP_REL))[1])
    refs_b = render_reference(spec, frame, m["ref_spp"], lays, m["seed"] + 104729 + 777, fs, film)
    for spp, (ref_b, _) in zip(m["spp"], refs_b):
        ref = read_deep(os.path.join(root, sc, "deepz", f"reference_spp{spp}.{frame:04d}.exr"))
        assert np.array_equal(ref.offsets, ref_b.offsets), "layouts differ"
        fa, fb = metrics.flat_rgb(ref), metrics.flat_rgb(ref_b)
        r = {x["method"]: float(x["flip"]) for x in rows if x["scene"] == sc and x["kind"] == "deepz"
             and int(x["spp"]) == spp and float(x["exposure"]) == 0}
        print(f"| {sc} | {m['preset']} | {spp} | {metrics.flip(fa, fb):.4f} | {r.get('noisy', float('nan')):.4f} | "
              f"{r.get('ranad', float('nan')):.4f} |", flush=True)
