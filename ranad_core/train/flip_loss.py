"""A differentiable HDR-FLIP (Andersson et al., "FLIP: A Difference Evaluator for Alternating Images", HPG 2020,
and "Visualizing Errors in Rendered High Dynamic Range Images", EG 2021) for the `flip` training term.

Why: `ranad eval` and the issue's targets score HDR-FLIP, and the per-pixel SMAPE terms weigh errors differently
from it. On box-filtered held-out interiors ranad beats flat OIDN in SMAPE and DSSIM but loses in HDR-FLIP, and
the pixels where it loses are smooth, mid-contrast ones: FLIP filters both images by the eye's contrast
sensitivity, which keeps low-frequency blotches a per-pixel term hardly charges (runs/generalization-s28).

The steps follow the papers: the reference's luminance sets the exposures (the brightest pixel and the median each
mapped to 0.85 by the ACES curve, one exposure per stop, at least two); at each exposure both images are
tone-mapped, taken to the YCxCz opponent space, filtered by the achromatic, red-green and blue-yellow contrast
sensitivity functions (sums of Gaussians in degrees of visual angle, 67 pixels per degree: a 4K monitor 0.7 m
wide seen from 0.7 m), clamped to the unit RGB cube, taken to Hunt-adjusted L*a*b*, and compared by the HyAB
distance raised to 0.7 and compressed to [0, 1]; edges and points (first and second derivatives of a Gaussian on
the luminance) raise the colour error to 1 - feature error. The per-pixel error is the largest over the
exposures, the score its mean. Small offsets keep the gradients finite where the papers' powers and norms have
none (at zero difference), cancelled so that identical images score exactly 0. A test
(`tests/test_train.py::test_flip_term_is_hdr_flip`) holds it to NVIDIA's evaluator."""

from __future__ import annotations

import functools
import math

import torch
import torch.nn.functional as F

from ..model.prior import LUMA   # the Rec. 709 luminance FLIP's exposures read

PPD = 0.7 * 3840 / 0.7 * math.pi / 180       # pixels per degree of the default observer (about 67)
QC, QF, PC, PT = 0.7, 0.5, 0.4, 0.95           # colour and feature exponents; error compression
# ACES (Narkowicz's fit) with its 0.6 pre-exposure folded in: (K0 x^2 + K1 x) / (K3 x^2 + K4 x + K5)
K0, K1, K3, K4, K5 = 0.6 * 0.6 * 2.51, 0.6 * 0.03, 0.6 * 0.6 * 2.43, 0.6 * 0.59, 0.14
T_EXPOSE = 0.85                                # tone-mapped value of the brightest pixel / the median
MAX_EXPOSURES = 12
# contrast sensitivity: (a1, b1, a2, b2) per opponent channel (achromatic, red-green, blue-yellow)
CSF = ((1.0, 0.0047, 0.0, 1e-5), (1.0, 0.0053, 0.0, 1e-5), (34.1, 0.04, 13.5, 0.025))
WHITE = (0.950428545, 1.0, 1.088900371)        # D65
RGB2XYZ = ((10135552 / 24577794, 8788810 / 24577794, 4435075 / 24577794),
           (2613072 / 12288897, 8788810 / 12288897, 887015 / 12288897),
           (1425312 / 73733382, 8788810 / 73733382, 70074185 / 73733382))
XYZ2RGB = ((3.241003275, -1.537398934, -0.498615861), (-0.969224334, 1.875930071, 0.041554224),
           (0.055639423, -0.204011202, 1.057148933))
EPS = 1e-6


def _aces_inverse(t: float) -> float:
    """The x >= 0 that the ACES curve maps to t."""
    c0, c1 = (K1 - K4 * t) / (K0 - K3 * t), (-K5 * t) / (K0 - K3 * t)
    return -0.5 * c0 + math.sqrt((0.5 * c0) ** 2 - c1)


def exposures(ref: torch.Tensor) -> list:
    """Exposures (stops) for a [3, H, W] linear reference: from the one that maps its brightest luminance to 0.85
    to the one that maps its median there, one per stop (at least two). Two guards the evaluator lacks, for training
    crops: at most MAX_EXPOSURES, and a median of 0 (a crop mostly black) taken as 2^-20 of the brightest."""
    y = torch.einsum("c,chw->hw", ref.new_tensor(LUMA), ref).detach().float()
    hi = float(y.max())
    if hi <= 0:
        return [0.0]
    lo = max(float(y.flatten().median()), hi * 2.0 ** -20)
    x = _aces_inverse(T_EXPOSE)
    start, stop = math.log2(x / hi), math.log2(x / lo)
    n = min(max(2, math.ceil(stop - start)), MAX_EXPOSURES)
    return [start + i * (stop - start) / (n - 1) for i in range(n)]


@functools.cache
def _filters(device, dtype) -> tuple[torch.Tensor, torch.Tensor]:
    """(csf [3, 1, k, k], features [4, 1, j, j]: edge x, edge y, point x, point y), cached per device and dtype."""
    r = math.ceil(3 * math.sqrt(max(b for c in CSF for b in (c[1], c[3])) / (2 * math.pi ** 2)) * PPD)
    t = torch.arange(-r, r + 1, dtype=torch.float64) / PPD
    z = t[:, None] ** 2 + t[None, :] ** 2
    csf = []
    for a1, b1, a2, b2 in CSF:
        s = a1 * math.sqrt(math.pi / b1) * torch.exp(-math.pi ** 2 * z / b1) \
            + a2 * math.sqrt(math.pi / b2) * torch.exp(-math.pi ** 2 * z / b2)
        csf.append(s / s.sum())
    sd = 0.5 * 0.082 * PPD
    rf = math.ceil(3 * sd)
    u = torch.arange(-rf, rf + 1, dtype=torch.float64)
    g = torch.exp(-(u[None, :] ** 2 + u[:, None] ** 2) / (2 * sd * sd))
    feats = []
    for h in (-u[None, :] * g, (u[None, :] ** 2 / (sd * sd) - 1) * g):
        k = torch.where(h < 0, h / -h[h < 0].sum(), h / h[h > 0].sum())
        feats += [k, k.T]
    return torch.stack(csf)[:, None].to(device, dtype), torch.stack(feats)[:, None].to(device, dtype)


def _conv(x: torch.Tensor, k: torch.Tensor) -> torch.Tensor:
    """Depthwise convolution of [B, C, H, W] by [C, 1, s, s] kernels, edges replicated (as the papers' filters)."""
    r = k.shape[-1] // 2
    return F.conv2d(F.pad(x, (r, r, r, r), mode="replicate"), k, groups=k.shape[0])


def _mat(x: torch.Tensor, m) -> torch.Tensor:
    """[B, 3, H, W] times a 3x3 matrix over the channels."""
    return torch.einsum("ij,bjhw->bihw", x.new_tensor(m), x)


def _lab(rgb: torch.Tensor) -> torch.Tensor:
    """Linear RGB in [0, 1] -> Hunt-adjusted L*a*b* ([B, 3, H, W])."""
    xyz = _mat(rgb, RGB2XYZ) / rgb.new_tensor(WHITE)[None, :, None, None]
    d = 6 / 29
    f = torch.where(xyz > d ** 3, xyz.clamp(min=d ** 3) ** (1 / 3), xyz / (3 * d * d) + 4 / 29)
    L = 116 * f[:, 1:2] - 16
    a, b = 500 * (f[:, 0:1] - f[:, 1:2]), 200 * (f[:, 1:2] - f[:, 2:3])
    return torch.cat([L, 0.01 * L * a, 0.01 * L * b], 1)


def _hyab(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """HyAB distance of two [B, 3, H, W] L*a*b* images: |dL| plus the Euclidean distance in (a, b) -> [B, H, W]."""
    d = a - b
    e2 = d.new_tensor(EPS * EPS)   # sqrt(0 + e2) - sqrt(e2) is exactly 0: a finite gradient, no offset
    return d[:, 0].abs() + torch.sqrt(d[:, 1] ** 2 + d[:, 2] ** 2 + e2) - torch.sqrt(e2)


@functools.cache
def _cmax() -> float:
    """The largest colour error, HyAB between Hunt-adjusted green and blue, raised to QC: the compression's scale."""
    green, blue = torch.tensor([0.0, 1.0, 0.0]), torch.tensor([0.0, 0.0, 1.0])
    lab = _lab(torch.stack([green, blue])[:, :, None, None].double())
    return float(_hyab(lab[:1], lab[1:]).squeeze()) ** QC


def ldr_flip_map(ref: torch.Tensor, test: torch.Tensor) -> torch.Tensor:
    """Per-pixel LDR-FLIP of [B, 3, H, W] linear images in [0, 1] -> [B, H, W]."""
    csf, feat = _filters(ref.device, ref.dtype)
    white = ref.new_tensor(WHITE)[None, :, None, None]

    def ycxcz(x):
        xyz = _mat(x, RGB2XYZ) / white
        y = xyz[:, 1:2]
        return torch.cat([116 * y - 16, 500 * (xyz[:, 0:1] - y), 200 * (y - xyz[:, 2:3])], 1)

    def filtered_lab(o):
        f = _conv(o, csf)
        y = (f[:, 0:1] + 16) / 116
        xyz = torch.cat([y + f[:, 1:2] / 500, y, y - f[:, 2:3] / 200], 1) * white
        return _lab(_mat(xyz, XYZ2RGB).clamp(0, 1))

    oref, otest = ycxcz(ref), ycxcz(test)
    cmax = _cmax()
    e = _power(_hyab(filtered_lab(oref), filtered_lab(otest)), QC)
    pcc = PC * cmax
    ec = torch.where(e < pcc, e * (PT / pcc), PT + (e - pcc) / (cmax - pcc) * (1 - PT))

    def features(o):
        f = _conv(((o[:, 0:1] + 16) / 116).expand(-1, 4, -1, -1), feat)
        return torch.sqrt(f[:, 0] ** 2 + f[:, 1] ** 2 + EPS * EPS), torch.sqrt(f[:, 2] ** 2 + f[:, 3] ** 2 + EPS * EPS)

    (er, pr), (et, pt) = features(oref), features(otest)
    ef = torch.maximum((er - et).abs(), (pr - pt).abs())
    ef = _power(ef / math.sqrt(2), QF)
    return _power(ec, 1 - ef)


def _power(x: torch.Tensor, p) -> torch.Tensor:
    """x^p for x >= 0, as (x + EPS)^p - EPS^p: 0 at 0 (identical images score exactly 0) with a finite gradient."""
    e = torch.full_like(x, EPS)   # same shape as x + e: the same pow kernel for both, so 0 maps to exactly 0
    return (x + e) ** p - e ** p


def _tone_map(x: torch.Tensor) -> torch.Tensor:
    return ((K0 * x * x + K1 * x) / (K3 * x * x + K4 * x + K5)).clamp(0, 1)


def hdr_flip(ref: torch.Tensor, test: torch.Tensor) -> torch.Tensor:
    """Mean HDR-FLIP of two [3, H, W] linear HDR images (negatives clamped to 0), differentiable in `test`."""
    ref, test = ref.clamp(min=0), test.clamp(min=0)
    scales = ref.new_tensor([2.0 ** c for c in exposures(ref)])[:, None, None, None]
    maps = ldr_flip_map(_tone_map(ref[None] * scales), _tone_map(test[None] * scales))
    return maps.max(0).values.mean()
