"""Thin bins of one surface merged before the model and shared back after it.

Renderers differ in how much they merge a pixel's samples into deep bins: ranad's training data (synth.binning)
starts a new deep-Z bin only where the depths jump by more than 3%, while a renderer that merges less splits one
surface into several thin bins at nearly the same depth, each holding a share of the pixel's samples and so each
noisier, and the model (trained on whole-surface bins) denoises such a frame worse than the same frame binned
like its training data (`runs/bin-merge-s15`). So before the model, consecutive point bins of a pixel whose
depths lie within `gap` of the previous one (relative) and that share every object id the file has are
composited front to back into one bin; after it, the denoised bin is shared back among its members.

Merging (per group of the sorted bins, T_i the transmittance in front of member i within the group from the
noisy alphas): premultiplied layers sum T_i v_i (the group's composite: the flattened pixel is unchanged), alpha
composites to 1 - prod(1 - a_i), coverage sums, Z is the front's and ZBack the back's, and guides (albedo,
normal, the flat prior) average with the members' shares rho_i = T_i a_i / A of the composite.

Sharing back (`split_factors`): member i gets the share rho_i of the denoised group's contribution, as disjoint
sample sets would: its alpha rho_i A' / T'_i and every premultiplied layer v'_i = v' rho_i / T'_i, T'_i the
denoised transmittance in front of it (a member hidden behind opaque ones gets the group as it is). The factor
f_i = rho_i / T'_i is one number per bin, the same for every channel, so the output stays linear in the noisy
values (light groups through the cached kernels get the same factors and still sum to the beauty) and the members
composite exactly to the denoised group; they share one unpremultiplied colour, the group's. Members keep
their own depths, moved with the group's. Volume bins (ZBack beyond Z by more than the gap) are never merged.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .channels import ALPHA, COVERAGE, DEPTH, DEPTH_BACK, DIFFUSE, EMISSION, SPECULAR
from .deep import DeepImage, segment_exclusive_cumsum, transmittance

MERGE_GAP = 0.025  # below the 3% jump between ranad's training bins: its own data never merges

# canonical channels that hold premultiplied radiance (composited), and those summed as they are
PREMULTIPLIED = (*DIFFUSE, *SPECULAR, *EMISSION)
SUMMED = (COVERAGE,)


@dataclass
class Groups:
    """How the sorted bins of one image merge: `index` [N] the merged bin of each bin (non-decreasing),
    `offsets` [P+1] of the merged image, `trans` [N] T_i and `share` [N] rho_i (module docstring), `z` [N] the
    bins' own depths and `thick` [N] their ZBack - Z."""
    index: np.ndarray
    offsets: np.ndarray
    trans: np.ndarray
    share: np.ndarray
    z: np.ndarray
    thick: np.ndarray

    @property
    def merged(self) -> int:
        return int(self.offsets[-1])

    @property
    def members(self) -> np.ndarray:
        """[M + 1] the groups as runs of the sorted bins: group g holds bins members[g] .. members[g + 1] - 1."""
        return np.flatnonzero(np.r_[True, self.index[1:] != self.index[:-1], True])


def groups_of(srt: DeepImage, img: DeepImage, perm: np.ndarray, gap: float | None = None) -> "Groups | None":
    """find_groups of `srt`, the sorted canonical image of `img` (`perm`: the sort), with `img`'s object ids kept
    apart; `gap` None: MERGE_GAP."""
    from .exr.inspect import id_columns   # uint ids and a float object id channel alike

    return find_groups(srt, {k: np.asarray(v)[perm] for k, v in id_columns(img).items()},
                       MERGE_GAP if gap is None else gap)


def find_groups(srt: DeepImage, ids: dict | None = None, gap: float = MERGE_GAP) -> Groups | None:
    """The groups of `srt` (canonical, bins sorted front to back per pixel); None when nothing merges (or gap
    <= 0). `ids`: the bins' object-id channels in the same order (bins with different ids never merge)."""
    n = srt.num_bins
    if gap <= 0 or n < 2:
        return None
    z = srt.channel(DEPTH).astype(np.float64)
    zb = srt.channel(DEPTH_BACK).astype(np.float64) if DEPTH_BACK in srt.channels else z
    thick = np.maximum(zb - z, 0)
    point = (thick <= gap * z) & (z > 0)   # bins without a usable depth (0, negative, NaN) never merge
    pix = srt.pixel_index()
    join = np.zeros(n, bool)   # bin i joins the group of bin i - 1
    join[1:] = (pix[1:] == pix[:-1]) & point[1:] & point[:-1] & (z[1:] <= z[:-1] + gap * np.abs(z[:-1]))
    for v in (ids or {}).values():
        v = np.asarray(v).reshape(n, -1)
        join[1:] &= (v[1:] == v[:-1]).all(1)
    if not join.any():
        return None
    index = np.cumsum(~join) - 1
    m = int(index[-1]) + 1
    starts = np.flatnonzero(~join)
    counts = np.bincount(pix[starts], minlength=srt.num_pixels)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    a = np.clip(srt.channel(ALPHA).astype(np.float64), 0, 1)
    trans = transmittance(a, np.append(starts, n))   # T_i over the members in front of i, within its group
    contrib = trans * a
    total = np.bincount(index, contrib, minlength=m)
    size = np.bincount(index, minlength=m).astype(np.float64)
    share = np.where(total[index] > 1e-12, contrib / np.maximum(total[index], 1e-300), 1.0 / size[index])
    return Groups(index, offsets, trans, share, z, thick)


def _merged_column(v: np.ndarray, groups: Groups, how: str) -> np.ndarray:
    """[M] float64 of one per-bin column v [N] (float64): "composite" (sum of T_i v_i), "sum", or "mean" (weighted
    by the shares)."""
    w = {"composite": groups.trans, "sum": None, "mean": groups.share}[how]
    return np.bincount(groups.index, v if w is None else v * w, minlength=groups.merged)


def merge_values(values: np.ndarray, groups: Groups, how: str) -> np.ndarray:
    """[M, C] of per-bin [N, C]: "composite" (sum of T_i v_i), "sum" or "mean" (weighted by the shares)."""
    v = np.asarray(values, np.float64).reshape(len(groups.index), -1)
    return np.stack([_merged_column(v[:, j], groups, how) for j in range(v.shape[1])], 1)


def merge(srt: DeepImage, groups: Groups) -> DeepImage:
    """The canonical image with each group composited into one bin (module docstring), channel by channel on the
    transposed values (made and undone by torch's threaded copies): a strided column read and a strided column
    write (np.stack) per channel made merging a 0.9 M-bin, 25-channel frame take 0.7 s against 0.3 s."""
    import torch   # here, not at the top: `ranad info` counts thin bins (find_groups) without loading torch

    first, last = groups.members[:-1], groups.members[1:] - 1
    by_channel = torch.from_numpy(np.ascontiguousarray(srt.values)).t().contiguous().numpy()   # torch: threaded
    merged = np.empty((len(srt.channels), groups.merged), np.float32)
    for i, c in enumerate(srt.channels):
        v = by_channel[i]
        if c == ALPHA:
            merged[i] = _merged_column(np.clip(v.astype(np.float64), 0, 1), groups, "composite")
        elif c == DEPTH:
            merged[i] = v[first]
        elif c == DEPTH_BACK:
            merged[i] = v[last]
        else:
            how = "composite" if c in PREMULTIPLIED else "sum" if c in SUMMED else "mean"
            merged[i] = _merged_column(v.astype(np.float64), groups, how)
    return DeepImage(values=torch.from_numpy(merged).t().contiguous().numpy(), offsets=groups.offsets,
                     channels=list(srt.channels),
                     data_window=srt.data_window, display_window=srt.display_window)


def split_factors(groups: Groups, alpha: np.ndarray) -> np.ndarray:
    """[N] f_i = rho_i / T'_i for the denoised groups' alphas `alpha` [M] (module docstring)."""
    a = np.clip(np.asarray(alpha, np.float64).reshape(-1), 0, 1)[groups.index]
    in_front = segment_exclusive_cumsum(groups.share, groups.members)   # shares of the members in front
    t = np.maximum(1 - a * in_front, 0)
    # a member hidden behind opaque ones (T'_i = 0) is invisible whatever it holds: it gets the group as is
    return np.where(t > 1e-6, groups.share / np.maximum(t, 1e-6), 1.0)


def split(values: np.ndarray, groups: Groups, factors: np.ndarray) -> np.ndarray:
    """Per-bin [N, C] premultiplied values of the groups' [M, C]."""
    v = np.asarray(values)
    return (v[groups.index] * factors.reshape(-1, *([1] * (v.ndim - 1)))).astype(v.dtype)


def split_alpha(alpha: np.ndarray, groups: Groups, factors: np.ndarray) -> np.ndarray:
    """[N] members' alphas of the groups' denoised alphas [M]: f_i A'."""
    return split(np.clip(np.asarray(alpha).reshape(-1), 0, 1), groups, factors)


def split_depth(z_new: np.ndarray, groups: Groups) -> np.ndarray:
    """[N] members' depths: each its own, moved by its group's denoised front depth over the noisy one."""
    z_new = np.asarray(z_new, np.float64).reshape(-1)
    front = groups.z[groups.members[:-1]]
    ratio = np.where(np.abs(front) > 0, z_new / np.where(np.abs(front) > 0, front, 1), 1.0)
    return (groups.z * ratio[groups.index]).astype(np.float32)
