"""Query/key layouts for every use of RaNA, built from ragged offsets (int64 [H*W+1], row-major pixels).

All layouts of one image share its pixel grid; what changes is which bins are queries and which are keys:

* self-attention: queries and keys are the same bins (:func:`self_attention_layout`);
* down-sampling by bin dropout (paper Sec. 4.1.2): a subset of the bins queries all bins
  (:func:`downsample_layout` gives the subset's own offsets for the next, sparser, scale);
* up-sampling: the finer layout's bins query the coarser layout's bins (queries from :func:`bin_pixels`
  of the fine offsets, keys = the coarse offsets);
* temporal mixing: each pixel's bins of T frames concatenated (:func:`concat_frames`), radius 0 or small.
"""

from __future__ import annotations

import torch


def _as_offsets(offsets) -> torch.Tensor:
    return torch.as_tensor(offsets, dtype=torch.int64)


def bin_pixels(offsets, width: int) -> torch.Tensor:
    """int64 [N, 2]: (y, x) of every bin's pixel."""
    offsets = _as_offsets(offsets)
    counts = offsets[1:] - offsets[:-1]
    pix = torch.repeat_interleave(torch.arange(counts.numel(), device=offsets.device), counts,
                                  output_size=int(offsets[-1]))
    return torch.stack([pix // width, pix % width], dim=1)


def pixel_offsets_of(pixel_ids: torch.Tensor, num_pixels: int) -> torch.Tensor:
    """Offsets [num_pixels+1] of bins whose (non-decreasing) pixel ids are ``pixel_ids``."""
    counts = torch.bincount(pixel_ids, minlength=num_pixels)
    return torch.cat([counts.new_zeros(1), torch.cumsum(counts, 0)])


def self_attention_layout(offsets, height: int, width: int):
    """(q_pixels, k_offsets, k_size) for bins attending to bins of the same layout."""
    offsets = _as_offsets(offsets)
    return bin_pixels(offsets, width), offsets, (height, width)


def downsample_layout(offsets, width: int, keep: torch.Tensor):
    """Bin dropout: the kept bins (bool ``keep`` [N]) become the queries of a down-sampling RaNA over all bins.

    Returns (kept_index int64 [M], q_pixels [M, 2], sparse_offsets [H*W+1]): ``kept_index`` selects the
    kept bins' rows (in order), ``q_pixels`` their pixels, and ``sparse_offsets`` the layout of the kept bins,
    which the next scale uses for its own self-attention and the up-sampling uses as keys.
    """
    offsets = _as_offsets(offsets)
    npix = offsets.numel() - 1
    kept_index = torch.nonzero(keep, as_tuple=False).flatten()
    pix = bin_pixels(offsets, width)[kept_index]
    sparse = pixel_offsets_of(pix[:, 0] * width + pix[:, 1], npix)
    return kept_index, pix, sparse


def concat_frames(offsets_list: list) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Temporal key layout: per pixel, frame 0's bins, then frame 1's, ... (all frames share one grid).

    Returns (offsets [H*W+1], gather [N_total], frame [N_total]): row ``r`` of the temporal layout is row
    ``gather[r]`` of the frames' bins concatenated frame after frame (``torch.cat(frame_values)``), and
    ``frame[r]`` the frame it came from.
    """
    offs = [_as_offsets(o) for o in offsets_list]
    npix = offs[0].numel() - 1
    if any(o.numel() - 1 != npix for o in offs):
        raise ValueError("all frames must have the same number of pixels")
    counts = torch.stack([o[1:] - o[:-1] for o in offs])  # [T, P]
    total = counts.sum(0)
    out = torch.cat([total.new_zeros(1), torch.cumsum(total, 0)])
    dev = offs[0].device
    base = torch.cumsum(torch.tensor([0] + [int(o[-1]) for o in offs[:-1]], device=dev), 0)
    # destination of frame t's bins of pixel p starts at out[p] + sum_{s<t} counts[s, p]
    before = torch.cumsum(counts, 0) - counts  # [T, P]
    n = int(out[-1])
    gather = torch.empty(n, dtype=torch.int64, device=dev)
    frame = torch.empty(n, dtype=torch.int64, device=dev)
    for t, o in enumerate(offs):
        c = counts[t]
        m = int(o[-1])
        if m == 0:
            continue
        pix = torch.repeat_interleave(torch.arange(npix, device=dev), c, output_size=m)
        within = torch.arange(m, device=dev) - o[:-1][pix]
        dest = out[:-1][pix] + before[t][pix] + within
        gather[dest] = base[t] + torch.arange(m, device=dev)
        frame[dest] = t
    return out, gather, frame
