"""Per-bin alpha error by bin class (single-bin pixels; front, middle and last bin of multi-bin pixels): bias
and MAE of the model's and of the noisy alpha against the reference's.

Usage: python runs/edit-oracles-s12/alpha_stats.py DATASET SCENE [SCENE ...]   (deep-Z, 16 spp, cpu-small-pd-v4)"""
import sys, numpy as np
from ranad_core.channels import ALPHA
from ranad_core.denoise import denoise_frame
from ranad_core.exr import read_deep
from ranad_core.model.store import load_model
model = load_model("cpu-small-pd-v4").model
for sc in sys.argv[2:]:
    noisy = read_deep(f"{sys.argv[1]}/{sc}/deepz/noisy_spp16.0000.exr")
    ref = read_deep(f"{sys.argv[1]}/{sc}/deepz/reference_spp16.0000.exr")
    out = denoise_frame(model, noisy).image
    an, ao, ar = noisy.channel(ALPHA), out.channel(ALPHA), ref.channel(ALPHA)
    cnt = np.repeat(np.diff(ref.offsets), np.diff(ref.offsets)); bi = ref.bin_index()
    print(sc, "bins", ref.num_bins, "same layout", np.array_equal(noisy.offsets, ref.offsets))
    for name, m in [("all", cnt > 0), ("single", cnt == 1), ("multi front", (cnt > 1) & (bi == 0)),
                    ("multi mid", (cnt > 1) & (bi > 0) & (bi < cnt - 1)), ("multi last", (cnt > 1) & (bi == cnt - 1))]:
        if m.sum() == 0: continue
        e = ao[m] - ar[m]; en = an[m] - ar[m]
        print(f"  {name:12s} n {m.sum():6d} ref mean {ar[m].mean():.3f} | model bias {e.mean():+.4f} "
              f"mae {np.abs(e).mean():.4f} | noisy bias {en.mean():+.4f} mae {np.abs(en).mean():.4f}")
    # ref alpha distribution
    print("  ref alpha quantiles", np.round(np.quantile(ar, [0.1, 0.25, 0.5, 0.75, 0.9]), 3))
