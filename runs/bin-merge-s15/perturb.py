"""Copy a held-out set with its noisy files (and, for bin splits, the references) changed the way another
renderer's conventions would change them, one spp only. usage: perturb.py SRC DST KIND[,KIND] [SPP (16)]

KIND: rotnormal (normals in another frame: one fixed rotation), flipnormal, noaux (no albedo/normal), rgbaonly
(R G B A Z ZBack only), nocov (no coverage channel, as renderers write), albedo1 (albedo 1 where covered),
depth1000 (depths in other units, references too), split2 (every bin as two coincident-ish bins 0.1% apart that
composite to it, references too), base (a copy)."""
import json, sys
from pathlib import Path
import numpy as np
from ranad_core.exr import read_deep, write_deep
from ranad_core.deep import DeepImage

src, dst, kinds = Path(sys.argv[1]), Path(sys.argv[2]), sys.argv[3].split(",")
spp = sys.argv[4] if len(sys.argv) > 4 else "16"
rng = np.random.default_rng(5)
q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
ROT = q * np.sign(np.linalg.det(q))


def split_bins(img: DeepImage) -> DeepImage:
    """Every bin as two coincident-ish bins (the second 0.1% deeper) each with alpha 1-sqrt(1-a): same composite."""
    ch = img.channels
    n = img.num_bins
    rows = np.repeat(np.arange(n), 2)
    vals = img.values[rows].astype(np.float64)
    a = img.channel("A").astype(np.float64)
    a2 = 1 - np.sqrt(np.clip(1 - a, 0, 1))
    f = np.where(a > 0, a2 / np.maximum(a, 1e-12), 0.5)
    f2 = np.repeat(f, 2)
    lin = [i for i, c in enumerate(ch) if c.split(".")[0] in ("R", "G", "B", "A", "diffuse", "specular", "emission",
                                                                  "lg_key", "lg_fill")]
    # second copy of a split bin sits behind the first: a composite of two a2 layers = a
    vals[:, lin] *= f2[:, None]
    if "coverage" in ch:   # disjoint sample sets: half each
        vals[:, ch.index("coverage")] = np.repeat(img.channel("coverage").astype(np.float64) / 2, 2)
    zi = ch.index("Z")
    second = np.arange(2 * n) % 2 == 1
    vals[second, zi] *= 1.001
    if "ZBack" in ch:
        zb = ch.index("ZBack")
        vals[second, zb] = np.maximum(vals[second, zb] * 1.001, vals[second, zi])
    offsets = img.offsets * 2
    return DeepImage(values=vals.astype(img.values.dtype), offsets=offsets, channels=list(ch),
                     ids={k: v[rows] for k, v in img.ids.items()}, data_window=img.data_window,
                     display_window=img.display_window, channel_types=dict(img.channel_types))


def perturb(img, kind, noisy):
    ch = img.channels
    if kind == "rotnormal" and noisy and "N.X" in ch:
        v = img.values.copy()
        idx = [ch.index(c) for c in ("N.X", "N.Y", "N.Z")]
        v[:, idx] = v[:, idx] @ ROT.T
        return img.with_values(v)
    if kind == "flipnormal" and noisy and "N.X" in ch:
        v = img.values.copy()
        idx = [ch.index(c) for c in ("N.X", "N.Y", "N.Z")]
        v[:, idx] = -v[:, idx]
        return img.with_values(v)
    if kind == "noaux" and noisy:
        return img.select([c for c in ch if not c.startswith(("albedo.", "N."))])
    if kind == "nocov" and noisy:
        return img.select([c for c in ch if c != "coverage"])
    if kind == "rgbaonly" and noisy:
        return img.select([c for c in ch if c in ("R", "G", "B", "A", "Z", "ZBack")])
    if kind == "albedo1" and noisy and "albedo.R" in ch:
        v = img.values.copy()
        for c in ("albedo.R", "albedo.G", "albedo.B"):
            v[:, ch.index(c)] = np.where(img.channel("A") > 0, 1.0, 0.0)
        return img.with_values(v)
    if kind == "depth1000":
        v = img.values.copy()
        for c in ("Z", "ZBack"):
            if c in ch:
                v[:, ch.index(c)] *= 1000
        return img.with_values(v)
    if kind == "split2":
        return split_bins(img)
    return img


for scene in sorted(src.glob("scene_*")):
    out = dst / scene.name
    for k in ("deepz", "deepoid"):
        (out / k).mkdir(parents=True, exist_ok=True)
    m = json.loads((scene / "manifest.json").read_text())
    m["spp"] = [int(spp)]
    m["files"] = [f for f in m["files"] if f"spp{spp}." in f]
    (out / "manifest.json").write_text(json.dumps(m, indent=1))
    for f in m["files"]:
        img = read_deep(scene / f)
        noisy = "noisy" in f
        for kind in kinds:
            img = perturb(img, kind, noisy)
        write_deep(out / f, img)
print("done", dst)
