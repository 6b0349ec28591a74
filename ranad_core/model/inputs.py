"""Input processing (paper Sec. 4.1.1): per-bin features from a deep image in ranad's channel convention.

Transforms suited to each kind of data: radiance-like layers through log1p (HDR range), alpha and coverage as they
are, depth as log depth standardised per image (scale-free), albedo and normals as they are; then a positional
encoding of the pixel position (periodic, so tiles are treated alike) and of the bin index within its pixel
(bins in front-to-back order). The noisy layers the reconstruction denoises are returned alongside.

Feature sets (a model's config names the one it was trained with, `ModelConfig.features`):
- "log1p": radiance as log1p of its absolute value (the v1 models; their output moves with exposure);
- "prior": radiance divided by the frame's exposure scale first (exposure-invariant), plus the flat prior and the
  pixel's flattened noisy beauty, both divided by the same scale (prior.py; channels added by `with_prior`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from ..channels import ALBEDO, ALPHA, COVERAGE, DEPTH, DIFFUSE, FLAT_NOISY, NORMAL, PRIOR, SPECULAR
from ..deep import DeepImage, transmittance
from .layers import Layout

RADIANCE_LAYERS = {"diffuse": DIFFUSE, "specular": SPECULAR}   # denoised by their own reconstruction modules
AUX = {"albedo": ALBEDO, "normal": NORMAL}
PERIODS = (2.0, 4.0, 8.0, 16.0)              # pixel-position encoding
BIN_FREQS = 3                                # bin-index encoding


# Albedo demodulation (models whose config has `demodulate`): the diffuse layer is divided per bin by its albedo
# plus this floor before the kernels and multiplied back by the query bin's after, so kernels average irradiance
# and a texture the albedo guide shows survives the smoothing (as in KPCN). The floor keeps dark albedos from
# amplifying noise.
DEMOD_FLOOR = 0.02


@dataclass
class ModelInputs:
    layout: Layout
    features: torch.Tensor      # [N, F]
    layers: dict                # name -> [N, C] noisy values (premultiplied radiance, alpha [N,1], depth [N,1])
    # [N, 3] albedo + DEMOD_FLOOR where the image has albedo and the diffuse/specular split, else None: what a
    # demodulating model divides the diffuse layer by (modulation())
    modulation: torch.Tensor | None = None
    # [N, 1] the bins' depths, what a layer-gated reconstruction reads (reconstruction.layer_gate); kept apart from
    # `layers` so that callers that do not denoise the depth layer (--keep-depth, the AOV pass) still give them
    depth: torch.Tensor | None = None

    @property
    def feature_dim(self) -> int:
        return self.features.shape[1]

    def to(self, device) -> "ModelInputs":
        """These inputs on `device` (tiles are prepared on the CPU and moved to the model's device)."""
        return ModelInputs(self.layout.to(device), None if self.features is None else self.features.to(device),
                           {k: v.to(device) for k, v in self.layers.items()},
                           None if self.modulation is None else self.modulation.to(device),
                           None if self.depth is None else self.depth.to(device))


FEATURE_SETS = ("log1p", "prior")
# first column of the "prior" set's six (PRIOR, FLAT_NOISY), after radiance (2 x 3), alpha, coverage, depth and
# the guides (2 x 3)
PRIOR_AT = 2 * 3 + 2 + 1 + 3 + 3
PRIOR_GUIDES_WIDTH = 6   # those six columns: what prior_guides returns, two RGB triplets


# columns of prepare()'s features that describe what a bin shows rather than its noise: standardised log depth,
# albedo, normal and, with "prior" features, the flat prior of its pixel (the matching temporal step compares them);
# and the bin's noisy radiance, of which the guides keep only whether it is exactly black
GUIDE_COLUMNS = {"depth": slice(8, 9), "albedo": slice(9, 12), "normal": slice(12, 15), "prior": slice(15, 18),
                 "radiance": slice(0, 6)}


# the columns of guides()' rows
GUIDE_LAYOUT = {"depth": slice(0, 1), "albedo": slice(1, 4), "normal": slice(4, 7), "prior": slice(7, 10),
                "black": slice(10, 11)}
GUIDE_WIDTH = 11


def guides(features: torch.Tensor, feature_set: str) -> torch.Tensor:
    """[N, GUIDE_WIDTH] the guides of `features` (GUIDE_LAYOUT): depth, albedo, normal, prior (log1p of the
    exposure-normalised flat prior; zero without "prior" features) and 1 where the bin's noisy radiance is exactly
    black."""
    cols = [features[:, GUIDE_COLUMNS[k]] for k in ("depth", "albedo", "normal")]
    prior = features[:, GUIDE_COLUMNS["prior"]] if feature_set == "prior" else features.new_zeros(len(features), 3)
    black = (features[:, GUIDE_COLUMNS["radiance"]] == 0).all(1, keepdim=True).to(features.dtype)
    return torch.cat([*cols, prior, black], 1)


def feature_dim(features: str = "log1p") -> int:
    base = 2 * 3 + 2 + 1 + 3 + 3 + 4 * len(PERIODS) + 2 * BIN_FREQS + 1
    return base + (6 if features == "prior" else 0)


def old_columns(old: str, new: str) -> list:
    """Where each feature column of set `old` sits in set `new` (the "prior" set inserts its 6 columns after the
    guides, before the position encodings): how a model of one set starts training with another's weights."""
    head = PRIOR_AT
    idx = list(range(feature_dim(old)))
    shift = feature_dim(new) - feature_dim(old)
    return [i if i < head else i + shift for i in idx]


def prior_guides(features: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """([N, 3] the flat prior, [N, 3] the pixel's flattened noisy beauty) of "prior" features, as `prepare` puts
    them (log1p of the exposure-normalised colour): what a prior-range reconstruction compares."""
    prior, flat = features[:, PRIOR_AT:PRIOR_AT + PRIOR_GUIDES_WIDTH].split(3, 1)
    return prior, flat


def _cols(img: DeepImage, names) -> np.ndarray:
    return img.columns(names).astype(np.float32, copy=False)


def _has(img: DeepImage, names) -> bool:
    return all(n in img.channels for n in names)


def modulation(img: DeepImage) -> np.ndarray | None:
    """[N, 3] the diffuse layer's modulation of a canonical image: its albedo guide (clipped to [0, 1]) plus
    DEMOD_FLOOR, or None without albedo or without the split (the "diffuse" layer then holds the whole beauty,
    specular light included, which the diffuse albedo does not modulate)."""
    if not (_has(img, ALBEDO) and _has(img, SPECULAR)):
        return None
    return _modulation_of(_cols(img, ALBEDO))


def _modulation_of(albedo: np.ndarray) -> np.ndarray:
    """[N, 3] the modulation of albedo columns: clipped to [0, 1], NaN as 0, plus DEMOD_FLOOR."""
    return (np.clip(np.nan_to_num(albedo), 0, 1) + np.float32(DEMOD_FLOOR)).astype(np.float32)


def depth_stats(img: DeepImage) -> tuple[float, float]:
    """(mean, std) of log depth over the image's bins: the standardisation `prepare` applies. Tiles of a frame
    pass the whole frame's statistics, so a bin's features do not depend on the tiling."""
    if img.num_bins == 0:
        return 0.0, 1.0
    logz = np.log(np.maximum(img.channel(DEPTH).astype(np.float64), 1e-4))
    return float(logz.mean()), float(logz.std())


def contribution(alpha: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """[N, 1] each bin's share of its pixel, a_i prod_{j<i} (1 - a_j) over the bins in front (front-to-back order):
    the model's coverage input where a file has no `coverage` channel (renderers write none). For surfaces it is
    exactly the sample coverage the training data carries (synth.binning gives bin i alpha c_i / (1 - the
    coverages in front)); the alpha itself, what files without coverage gave before, differs from it in every bin
    behind another (by 0.23 on average in a layered held-out scene)."""
    a = np.clip(np.asarray(alpha, np.float64).reshape(-1), 0, 1)
    return (a * transmittance(a, offsets))[:, None].astype(np.float32)


def exact_row_kernels(floats, indices=()):
    """The C++ kernels for the passes that give torch's values bit for bit (concat_columns, matching.pair_features,
    matching.pair_sum), where they are built and every tensor is on the CPU, the floats float32 without gradients
    (inference) and the indices int64; None otherwise (torch does the work)."""
    from ..rana.extension import cpu_extension_or_none

    plain = (all(t.dtype == torch.float32 and t.device.type == "cpu" and not t.requires_grad for t in floats)
             and all(t.dtype == torch.int64 and t.device.type == "cpu" for t in indices))
    return cpu_extension_or_none() if plain else None


def concat_columns(parts: list) -> torch.Tensor:
    """torch.cat of [N, c] and [N] parts along the columns: float32 CPU tensors without gradients by the C++
    kernels' one pass over the rows where they are built (torch's cat of 30 parts of 1-16 columns took 60-75 ms per
    0.5 M rows), the same values; others (GPU, autograd) by torch.cat."""
    parts = [p[:, None] if p.dim() == 1 else p for p in parts]
    ext = exact_row_kernels(parts)
    if ext is None:
        return torch.cat(parts, 1)
    return ext.rows_concat([p.contiguous() for p in parts])


def prepare(img: DeepImage, z_stats: tuple[float, float] | None = None, features: str = "log1p",
            scale: float = 1.0) -> ModelInputs:
    """Features and noisy layers of a deep image whose bins are in front-to-back order within each pixel.
    `z_stats`: the log-depth standardisation (default: this image's own, see `depth_stats`); `features`: the
    feature set (FEATURE_SETS); `scale`: the frame's exposure scale ("prior" features; prior.frame_scale of the
    whole frame, so that tiles and crops agree).

    The channels it reads are taken from the bins' rows in one gather (a take per channel group read every row
    of the image once per group) and the blocks are concatenated once, in one pass (`concat_columns`; the radiance
    and guide blocks were joined first, then joined again with the stacked encodings). Each value is computed as
    before (log1p and log on fresh contiguous arrays), so the features are bitwise the same (tests/test_inputs.py
    keeps the earlier version as the oracle)."""
    if features not in FEATURE_SETS:
        raise ValueError(f"unknown feature set {features!r} (known: {', '.join(FEATURE_SETS)})")
    inv = 1.0 / scale if features == "prior" else 1.0
    n = img.values.shape[0]
    groups = {**RADIANCE_LAYERS, "alpha": (ALPHA,), "depth": (DEPTH,), "coverage": (COVERAGE,), **AUX}
    if features == "prior":
        groups.update(prior=PRIOR, flat=FLAT_NOISY)
    # alpha and depth are required (channel_index names a missing one); the other groups are optional
    present = {k: v for k, v in groups.items() if k in ("alpha", "depth") or _has(img, v)}
    raw = np.take(img.values, [img.channel_index(c) for v in present.values() for c in v], axis=1)
    raw = raw.astype(np.float32, copy=False)
    col, at = {}, 0
    for k, v in present.items():
        col[k] = raw[:, at:at + len(v)]
        at += len(v)

    def group(name: str, width: int) -> np.ndarray:   # a group's columns, contiguous; zeros where it is absent
        return np.ascontiguousarray(col[name]) if name in col else np.zeros((n, width), np.float32)

    layers = {"diffuse": group("diffuse", 3), "specular": group("specular", 3), "alpha": group("alpha", 1),
              "depth": group("depth", 1)}
    cov = group("coverage", 1) if "coverage" in col else contribution(layers["alpha"], img.offsets)
    mean, std = depth_stats(img) if z_stats is None else z_stats
    zn = ((np.log(np.maximum(layers["depth"], 1e-4)) - mean) / (std + 1e-6)).astype(np.float32)
    rad = lambda x: np.log1p(np.maximum(np.asarray(x, np.float32) * np.float32(inv), 0))  # noqa: E731
    blocks = [rad(layers["diffuse"]), rad(layers["specular"]), layers["alpha"], cov, zn, group("albedo", 3),
              group("normal", 3)]
    if features == "prior":
        blocks += [rad(group("prior", 3)), rad(group("flat", 3))]
    layout = Layout.of(torch.from_numpy(img.offsets), img.height, img.width)
    y, x = layout.pixels[:, 0].float(), layout.pixels[:, 1].float()
    pos = [f(2 * math.pi * t / p) for p in PERIODS for t in (x, y) for f in (torch.sin, torch.cos)]
    offs = layout.offsets
    counts = (offs[1:] - offs[:-1])
    b = (torch.arange(layout.bins) - torch.repeat_interleave(offs[:-1], counts, output_size=layout.bins)).float()
    nb = torch.repeat_interleave(counts, counts, output_size=layout.bins).float()
    bins = [f(b * math.pi / 2 ** k) for k in range(BIN_FREQS) for f in (torch.sin, torch.cos)]
    feats = concat_columns([*(torch.from_numpy(blk) for blk in blocks), *pos, *bins, b / nb.clamp(min=1)])
    mod = _modulation_of(col["albedo"]) if "albedo" in col and "specular" in col else None   # modulation(img)
    tensors = {k: torch.from_numpy(v) for k, v in layers.items()}
    return ModelInputs(layout, feats, tensors, None if mod is None else torch.from_numpy(mod), tensors["depth"])
