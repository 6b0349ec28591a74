"""Path samples -> deep pixels (deep-Z or deep-OID), and reference samples into the noisy image's bins.

Rules (documented in README, "Synthetic data"):

* deep-OID: one bin per (pixel, object id) of the samples' first stops; the id goes to the uint32 `id` channel.
* deep-Z: a pixel's samples are sorted by view depth and a new bin starts wherever consecutive depths differ by
  more than 3% plus 1 cm (Z_GAP_REL, Z_GAP_ABS; `gap_rel` overrides the 3%: a small one splits a surface into
  many thin bins, as renderers that merge less do); no id channel.
* Per bin: the mean of every attribute (albedo, normal, position, motion), `coverage` = samples in the bin / spp,
  Z = ZBack = the mean depth (surfaces are points), and radiance-like channels as sums / spp.
* Volume samples (first stop inside a participating medium, trace.py): one bin per (pixel, medium) in both kinds,
  whatever their depths, with Z and ZBack where the pixel's noisy samples entered and left the medium (the
  nearest entry, the farthest exit): a volume bin spans its medium, Z < ZBack. References are binned into it by
  medium, like deep-OID.
  With a pixel filter (pixel_filter.py) a sample counts in every pixel its filter reaches, with its weight, and
  spp becomes the pixel's total weight: means are weighted, coverage the bin's share of the pixel's weight.
* EXR alpha: bins are ordered front to back and bin i gets A_i = c_i / (1 - sum_{j<i} c_j) with its colours
  divided by the same (1 - sum_{j<i} c_j), so that compositing the bins "over" each other gives exactly the
  pixel's mean radiance (the coverages are disjoint sample sets, not layers).
* The reference is binned INTO the noisy bins: a reference sample goes to the noisy bin of its pixel with the
  same object id (deep-OID) or whose depth range, widened by the gap rule, holds its depth (deep-Z, nearest
  bin first). Samples that find no bin are dropped and counted: `unbinned_energy` is their share of the
  reference radiance. Noisy and reference images therefore have identical bin layouts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

Z_GAP_REL, Z_GAP_ABS = 0.03, 0.01

# radiance-like sample attributes (summed, premultiplied in the file) and mean attributes
SUMMED = ("diffuse", "specular", "emission")
MEANS = ("albedo", "normal", "position", "motion_prev", "motion_next")


@dataclass
class BinLayout:
    """Bins of one image: pixel of each bin (row-major), bin key (object id or depth cluster), depth range."""
    width: int
    height: int
    pixel: np.ndarray      # int64 [B]
    obj: np.ndarray        # uint32 [B]: object id (deep-OID) or majority id (deep-Z)
    zmin: np.ndarray
    zmax: np.ndarray
    kind: str              # "oid" or "z"
    volume: np.ndarray | None = None   # bool [B]: a volume bin (None: the image has none)
    zfront: np.ndarray | None = None   # [B] a volume bin's Z and ZBack (entry and exit depths; surfaces: unused)
    zback: np.ndarray | None = None

    @property
    def offsets(self) -> np.ndarray:
        counts = np.bincount(self.pixel, minlength=self.width * self.height)
        return np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)


def layout_from_samples(s: dict, width: int, height: int, kind: str,
                        gap_rel: float = Z_GAP_REL) -> tuple[BinLayout, np.ndarray]:
    """The bins of the noisy samples and each sample's bin (-1 for samples that hit nothing). `gap_rel`: the
    deep-Z split rule's relative depth gap (the absolute 1 cm applies only with the default gap)."""
    hit = np.flatnonzero(s["hit"])
    pix, z, obj = s["pixel"][hit], s["z"][hit], s["obj"][hit]
    vol = s["volume"][hit] if "volume" in s and s["volume"].any() else None
    if kind == "oid":
        order = np.lexsort((z, obj, pix))
        key_change = np.ones(len(order), bool)
        key_change[1:] = (pix[order][1:] != pix[order][:-1]) | (obj[order][1:] != obj[order][:-1])
    elif kind == "z":
        # volume samples: one group per medium; surface samples (group 0) split where depth jumps
        group = np.zeros(len(hit), np.int64) if vol is None else np.where(vol, obj.astype(np.int64) + 1, 0)
        order = np.lexsort((z, group, pix))
        zs = z[order]
        key_change = np.ones(len(order), bool)
        gap_abs = Z_GAP_ABS if gap_rel == Z_GAP_REL else 0.0
        gs = group[order]
        key_change[1:] = (pix[order][1:] != pix[order][:-1]) | (gs[1:] != gs[:-1]) | \
            ((gs[1:] == 0) & (zs[1:] > zs[:-1] * (1 + gap_rel) + gap_abs))
    else:
        raise ValueError(f"unknown deep kind {kind!r}")
    bin_sorted = np.cumsum(key_change) - 1
    nb = int(bin_sorted[-1]) + 1 if len(order) else 0
    sample_bin = np.full(len(s["hit"]), -1, np.int64)
    sample_bin[hit[order]] = bin_sorted
    b_pix = pix[order][key_change]
    zsorted = z[order]
    # both orders sort a bin's samples by depth last: its first and last sample hold its range
    zmin = zsorted[key_change].astype(np.float64)
    zmax = zsorted[np.append(np.flatnonzero(key_change)[1:], len(order))[:nb] - 1].astype(np.float64)
    if kind == "oid":
        b_obj = obj[order][key_change]
    else:  # majority object of each depth cluster (kept for motion checks, not written)
        pairs = bin_sorted.astype(np.int64) * (int(obj.max(initial=0)) + 1) + obj[order]
        uniq, cnt = np.unique(pairs, return_counts=True)
        best = np.zeros(nb, np.int64)
        best_cnt = np.zeros(nb, np.int64)
        b_of = uniq // (int(obj.max(initial=0)) + 1)
        for b, o, c in zip(b_of, uniq % (int(obj.max(initial=0)) + 1), cnt):
            if c > best_cnt[b]:
                best[b], best_cnt[b] = o, c
        b_obj = best.astype(np.uint32)
    b_vol = zfront = zback = None
    front = zmin
    if vol is not None:   # a volume bin spans its medium: the nearest entry, the farthest exit of its samples
        starts = np.flatnonzero(key_change)
        b_vol = vol[order][key_change]
        zfront = np.minimum.reduceat(s["zin"][hit][order].astype(np.float64), starts) if nb else np.zeros(0)
        zback = np.maximum.reduceat(s["zout"][hit][order].astype(np.float64), starts) if nb else np.zeros(0)
        front = np.where(b_vol, zfront, zmin)
    # bins ordered by pixel, then front to back
    ord2 = np.lexsort((front, b_pix))
    remap = np.empty(nb, np.int64)
    remap[ord2] = np.arange(nb)
    if nb:   # (without bins every sample_bin is already -1)
        sample_bin = np.where(sample_bin >= 0, remap[np.maximum(sample_bin, 0)], -1)
    pick = (lambda a: None if a is None else a[ord2])  # noqa: E731
    lay = BinLayout(width, height, b_pix[ord2].astype(np.int64), np.asarray(b_obj)[ord2].astype(np.uint32),
                    zmin[ord2], zmax[ord2], kind, pick(b_vol), pick(zfront), pick(zback))
    return lay, sample_bin


def _subset(lay: BinLayout, keep: np.ndarray, kind: str) -> BinLayout:
    """The bins `keep` (bool [B]) of a layout, in their order (a pixel's bins stay front to back), matched by
    `kind`'s rule."""
    return BinLayout(lay.width, lay.height, lay.pixel[keep], lay.obj[keep], lay.zmin[keep], lay.zmax[keep], kind)


def assign_to_layout(s: dict, lay: BinLayout) -> np.ndarray:
    """Each (reference) sample's bin in an existing layout, -1 when none matches."""
    out = np.full(len(s["hit"]), -1, np.int64)
    hit = np.flatnonzero(s["hit"])
    if len(lay.pixel) == 0 or len(hit) == 0:
        return out
    if lay.kind == "z" and lay.volume is not None and lay.volume.any():
        # volume samples go to their pixel's bin of their medium, surface samples to the surface bins by depth
        vol = s["volume"] if "volume" in s else np.zeros(len(s["hit"]), bool)
        for is_vol in (False, True):
            keep = lay.volume == is_vol
            sub = _subset(lay, keep, "oid" if is_vol else "z")
            part = assign_to_layout({**s, "hit": s["hit"] & (vol == is_vol)}, sub)
            ok = part >= 0
            out[ok] = np.flatnonzero(keep)[part[ok]]
        return out
    pix, z, obj = s["pixel"][hit], s["z"][hit], s["obj"][hit]
    if lay.kind == "oid":
        big = np.uint64(1 << 32)
        keys = lay.pixel.astype(np.uint64) * big + lay.obj.astype(np.uint64)
        order = np.argsort(keys, kind="stable")
        q = pix.astype(np.uint64) * big + obj.astype(np.uint64)
        pos = np.searchsorted(keys[order], q)
        pos_c = np.minimum(pos, len(keys) - 1)
        ok = keys[order][pos_c] == q
        out[hit[ok]] = order[pos_c[ok]]
        return out
    lo = lay.zmin / (1 + Z_GAP_REL) - Z_GAP_ABS
    hi = lay.zmax * (1 + Z_GAP_REL) + Z_GAP_ABS
    offs = lay.offsets
    # candidate: the last bin of the pixel whose lower bound <= z (bins are front to back within a pixel)
    scale = 1e6
    keys = lay.pixel.astype(np.float64) * scale + np.clip(lo, -1e3, 1e5 - 1) / 1e5 * (scale * 0.5)
    q = pix.astype(np.float64) * scale + np.clip(z, -1e3, 1e5 - 1) / 1e5 * (scale * 0.5)
    pos = np.searchsorted(keys, q, side="right") - 1
    first_of_pixel = offs[pix]
    ok = (pos >= first_of_pixel) & (pos < offs[pix + 1])
    pos_c = np.clip(pos, 0, len(keys) - 1)
    ok &= z <= hi[pos_c]
    out[hit[ok]] = pos_c[ok]
    return out


def _sample_matrix(s: dict):
    """[n, 2 + channels] float32 tensor of (1, z, every summed and mean channel), built once per sample set.

    A pixel filter's copies (pixel_filter.splat: `_parent`, `_src`, `weight`) gather their rows from the parent's
    matrix and weight them, column 0 becoming the weight."""
    import torch

    if "_matrix" not in s and "_parent" in s:
        base, names, widths = _sample_matrix(s["_parent"])
        src = torch.from_numpy(s["_src"])
        w = torch.from_numpy(s["weight"])
        s["_matrix"] = (base.index_select(0, src).mul_(w[:, None]), names, widths)
        s["_total"] = s["_parent"]["_total"][s["_src"]] * s["weight"]
    if "_matrix" not in s:
        names = [n for n in SUMMED + MEANS if n in s] + ["groups"]
        widths = [int(np.prod(s[n].shape[1:])) for n in names]
        n = len(s["hit"])
        mat = np.empty((n, 2 + sum(widths)), np.float32)
        mat[:, 0] = 1.0
        mat[:, 1] = s["z"]
        c = 2
        for k, w in zip(names, widths):
            mat[:, c:c + w] = s[k].reshape(n, w)
            c += w
        s["_matrix"] = (torch.from_numpy(mat), names, widths)
        s["_total"] = sum(s[k] for k in SUMMED).sum(axis=1).astype(np.float64)
    return s["_matrix"]


def accumulate(s: dict, sample_bin: np.ndarray, nbins: int, acc: dict | None = None, npixels: int = 0) -> dict:
    """Adds per-bin sums (count, summed channels, sums of mean channels, depth sum) of samples into acc.

    Filtered samples (a `weight` per sample, pixel_filter.splat) add weighted sums, and each pixel's total weight
    (misses included; `npixels` pixels) goes to acc["pixel_weight"], what bin_values divides by.

    One index_add over a matrix of every channel, built once per sample set and shared by every layout the
    samples are binned into (per-channel bincounts took 40% of a scene's time at 1024 spp). Samples without a
    bin go to a discarded extra row.
    """
    import torch

    mat, names, widths = _sample_matrix(s)
    if acc is None:
        acc = {"count": np.zeros(nbins), "z": np.zeros(nbins), "unbinned": 0.0, "total": 0.0}
        for n, w in zip(names, widths):
            acc[n] = np.zeros((nbins, w))
    ok = sample_bin >= 0
    idx = torch.from_numpy(np.where(ok, sample_bin, nbins))
    sums = torch.zeros(nbins + 1, mat.shape[1], dtype=mat.dtype).index_add_(0, idx, mat)[:nbins]
    sums = sums.numpy().astype(np.float64)
    if "weight" in s:
        if "_pixel_weight" not in s:   # the same for every layout the samples are binned into
            s["_pixel_weight"] = np.bincount(s["pixel"], weights=s["weight"], minlength=npixels)
        acc["pixel_weight"] = acc.get("pixel_weight", 0.0) + s["_pixel_weight"]
    acc["count"] += sums[:, 0]
    acc["z"] += sums[:, 1]
    c = 2
    for n, w in zip(names, widths):
        acc[n] += sums[:, c:c + w]
        c += w
    total = s["_total"]
    acc["unbinned"] += float(total[~ok].sum())
    acc["total"] += float(total.sum())
    return acc


def bin_values(acc: dict, lay: BinLayout, spp: int) -> dict:
    """Per-bin channel values from accumulated sums: coverage, EXR alpha, premultiplied radiance, means.

    Sums are divided by `spp`, or for filtered samples by the bin's pixel's total weight (a film's normalisation).
    """
    count = acc["count"]
    if "pixel_weight" in acc:
        spp = np.maximum(acc["pixel_weight"][lay.pixel], 1e-12)
    cov = count / spp
    offs = lay.offsets
    # coverage of the bins in front of each bin, within its pixel
    before = np.cumsum(cov) - cov
    before -= np.repeat(np.append(before, 0.0)[offs[:-1]], np.diff(offs))
    # what the bins in front leave; never less than the bin's own share: filtered counts are summed in float32 and
    # the pixel's weight in float64, so behind a nearly opaque front a bin of a few 1e-7 could find less room than
    # its own coverage, and dividing by the clamp made its colour overflow the file's half floats (inf)
    room = np.maximum(np.maximum(1.0 - before, cov), 1e-12)
    safe = np.where(count > 0, count, 1.0)[:, None]   # weighted counts of filtered samples can be below 1
    out = {"coverage": cov, "A": np.clip(cov / room, 0.0, 1.0)}
    for name in SUMMED + ("groups",):
        out[name] = acc[name] / (spp[:, None] if np.ndim(spp) else spp) / room[:, None]
    for name in MEANS:
        if name in acc:
            out[name] = acc[name] / safe
    mean_z = acc["z"] / safe[:, 0]
    out["Z"] = np.where(count > 0, mean_z, 0.5 * (lay.zmin + lay.zmax))
    out["ZBack"] = out["Z"]
    if lay.volume is not None:
        out["Z"] = np.where(lay.volume, lay.zfront, out["Z"])
        out["ZBack"] = np.where(lay.volume, lay.zback, out["ZBack"])
    out["unbinned_energy"] = acc["unbinned"] / acc["total"] if acc["total"] > 0 else 0.0
    return out
