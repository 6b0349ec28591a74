"""Diagnostic (session 29): ranad's flat image times a clamped low-frequency luminance gain toward flat OIDN's,
g = clip(box_R(L_oidn) / box_R(L_ranad), 1/G, G), over a grid of (R, G). Flat FLIP per spp as a ratio to flat
OIDN's, mean over a set's deep-Z pairs, of ranad without its own light matching. Writes one JSON line per set and
spp. With --rgb first: a gain per RGB channel on top of ranad's light matching (the default since this session);
with --noisy first: the noisy input's flat luminance as the target instead of OIDN's (no light matching).
Usage: python lf_grid.py [--rgb] OUT.jsonl SET... """
import sys
import json
import collections
import numpy as np
from ranad_core.exr import read_deep
from ranad_core import metrics
from ranad_core.baselines import oidn_flat
from ranad_core.denoise import denoise_window
from ranad_core.train.data import find_pairs
from ranad_core.model.store import load_model
from ranad_core.model.prior import LUMA

from ranad_core.lightmatch import box_mean as box  # the product's summed-area box mean

RGB, NOISY = sys.argv[1] == "--rgb", sys.argv[1] == "--noisy"
args = sys.argv[2:] if RGB or NOISY else sys.argv[1:]
model = load_model(None).model
luma = np.asarray(LUMA, np.float64)
GRID = [(r, g) for r in (4, 8, 16, 32) for g in (1.02, 1.03, 1.05)]
with open(args[0], "a") as out:
    for s in args[1:]:
        acc = collections.defaultdict(list)
        for p in find_pairs([s]):
            if p.kind != "deepz":
                continue
            noisy, ref = read_deep(p.noisy), read_deep(p.reference)
            fr, oidn = metrics.flat_rgb(ref), oidn_flat(noisy)
            fo = metrics.flat_rgb(noisy) if NOISY else oidn   # the target (OIDN's FLIP stays the divisor)
            fn = metrics.flat_rgb(denoise_window(model, [noisy], 0, light_match=RGB).image)
            lo, ln = (np.maximum(f.astype(np.float64) @ luma, 0) for f in (fo, fn))
            row = [metrics.flip(fr, oidn), metrics.flip(fr, fn)]
            for r, G in GRID:
                if RGB:
                    g = np.stack([np.clip(box(np.maximum(fo[..., c], 0).astype(np.float64), r) / np.maximum(
                        box(np.maximum(fn[..., c], 0).astype(np.float64), r), 1e-8), 1 / G, G) for c in range(3)], -1)
                else:
                    g = np.clip(box(lo, r) / np.maximum(box(ln, r), 1e-8), 1 / G, G)[..., None]
                row.append(metrics.flip(fr, fn * g.astype(np.float32)))
            acc[p.spp].append(row)
        for spp in sorted(acc):
            m = np.mean(acc[spp], axis=0)
            rec = {"set": s, "spp": spp, "rgb": RGB, "noisy": NOISY, "ranad": m[1] / m[0],
                   **{f"R{r}G{g}": x / m[0] for (r, g), x in zip(GRID, m[2:])}}
            out.write(json.dumps(rec) + "\n")
            out.flush()
            print(s, spp, f"{rec['ranad']:.3f}", " ".join(f"{x / m[0]:.3f}" for x in m[2:]), flush=True)
