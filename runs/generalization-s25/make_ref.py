"""A held-out set's scenes again with references of more samples (session 25): the noisy files copied as they are,
each scene's references traced again at REF_SPP (the set's recipe otherwise: the same scene, film and reference
seed) and binned into the same noisy layouts, both deep kinds. Usage: python make_ref.py SET OUT REF_SPP [SCENES...]"""
import json
import os
import shutil
import sys
import time

import numpy as np

from ranad_core.exr import read_deep, write_deep
from ranad_core.synth.binning import Z_GAP_REL
from ranad_core.synth.dataset import KINDS, _worker_init
from ranad_core.synth.render import bin_noisy, noisy_samples, render_reference
from ranad_core.synth.scene import make_scene
from ranad_core.synth.trace import load_frame

_worker_init(2)
root, out, ref_spp = sys.argv[1], sys.argv[2], int(sys.argv[3])
want = set(sys.argv[4:])
for sc in sorted(os.listdir(root)):
    mpath = os.path.join(root, sc, "manifest.json")
    if not os.path.exists(mpath) or (want and sc not in want) or os.path.exists(os.path.join(out, sc, "manifest.json")):
        continue
    t0 = time.perf_counter()
    m = json.load(open(mpath))
    spec = make_scene(m["seed"], m["preset"], m["size"], m["frames"], m["motion"])
    film = tuple(m.get("pixel_filter", ("box", 1.0)))
    frame = m["centre_frame"]
    fs = load_frame(spec, frame)
    kinds = sorted({f.split("/")[0] for f in m["files"]})
    lays, names = [], []
    for spp in m["spp"]:
        s = noisy_samples(spec, frame, spp, m["seed"] + 7919 * frame + spp, fs, m.get("sampler") == "stratified",
                          m.get("guides") == "through-specular", film)
        for kind in kinds:
            img, lay = bin_noisy(spec, s, spp, KINDS[kind], m.get("bin_gap", Z_GAP_REL))
            old = read_deep(os.path.join(root, sc, kind, f"noisy_spp{spp}.{frame:04d}.exr"))
            assert np.array_equal(old.offsets, img.offsets), f"{sc} {kind} {spp}: layout not reproduced"
            lays.append(lay)
            names.append((kind, spp))
    refs = render_reference(spec, frame, ref_spp, lays, m["seed"] + 104729, fs, film)
    tmp = os.path.join(out, sc + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    for kind in kinds:
        os.makedirs(os.path.join(tmp, kind))
        for f in os.listdir(os.path.join(root, sc, kind)):
            if f.startswith("noisy_"):
                shutil.copy(os.path.join(root, sc, kind, f), os.path.join(tmp, kind, f))
    for (kind, spp), (img, lost) in zip(names, refs):
        write_deep(os.path.join(tmp, kind, f"reference_spp{spp}.{frame:04d}.exr"), img)
        m["stats"][kind]["reference_unbinned_energy"][str(spp)] = lost
    m["ref_spp"] = ref_spp
    m["seconds"] = round(time.perf_counter() - t0, 2)
    json.dump(m, open(os.path.join(tmp, "manifest.json"), "w"), indent=1)
    os.rename(tmp, os.path.join(out, sc))
    print(sc, m["preset"], m["seconds"], "s", flush=True)
