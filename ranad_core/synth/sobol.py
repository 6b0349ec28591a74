"""Low-discrepancy sample draws for `ranad synth --sampler sobol`: production renderers' samplers.

Production renderers draw every dimension of a path (pixel position, lens, light and BSDF choices at each bounce)
from low-discrepancy sequences (Cycles' Sobol-Burley, pbrt's Sobol samplers, the progressive multi-jittered sets
of Arnold and RenderMan), not from independent random numbers: at equal samples their noise is lower and more
evenly spread between pixels, so a denoiser that only saw independent samples sees another kind of noise in a
user's renders. This is Burley's hash-based construction ("Practical Hash-based Owen Scrambling", JCGT 2020):
each pair of dimensions of a pixel takes the 2-D Sobol (0,2)-sequence, its sample order shuffled and its values
Owen-scrambled by hashes of (pixel, dimension pair, seed), so each pair's first 2^m samples form a (0, m, 2)-net
and the pairs are decorrelated from each other. A 1-D draw takes the first coordinate of its own pair.

Everything is 32-bit integer arithmetic on Dr.Jit arrays (wrapping multiplies), so it runs inside the traced
path loop; `net_points` evaluates the same functions on numpy through a small shim for the tests.
"""

from __future__ import annotations

LK = (0x6C50B47C, 0xB82F1E52, 0xC7AFE638, 0x8D22F6E6)   # Laine-Karras permutation constants (Burley 2020)
SOBOL_BITS = 16      # a pixel's samples form nets of up to 2^16 points; beyond, each further 2^16 another net


def _hash(x):
    """A 32-bit integer hash (lowbias32): any change of the input changes about half the output bits."""
    x = x ^ (x >> 16)
    x = x * 0x7FEB352D
    x = x ^ (x >> 15)
    x = x * 0x846CA68B
    return x ^ (x >> 16)


def _reverse(x):
    """The 32 bits of x in reverse order."""
    x = ((x >> 1) & 0x55555555) | ((x & 0x55555555) << 1)
    x = ((x >> 2) & 0x33333333) | ((x & 0x33333333) << 2)
    x = ((x >> 4) & 0x0F0F0F0F) | ((x & 0x0F0F0F0F) << 4)
    x = ((x >> 8) & 0x00FF00FF) | ((x & 0x00FF00FF) << 8)
    return (x >> 16) | (x << 16)


def _owen(x, seed):
    """Nested uniform (Owen) scrambling of the binary fraction x / 2^32: each bit flipped by a hash of the bits
    above it (Laine-Karras on the reversed bits). Maps every elementary interval onto one of the same size."""
    x = _reverse(x) + seed
    for k in LK:
        x = x ^ (x * k)
    return _reverse(x)


def _sobol_pair(i, select, zero):
    """The 2-D Sobol point of index i (i < 2^SOBOL_BITS) as 32-bit fractions: the van der Corput radical inverse
    and Sobol's second dimension (direction numbers v_0 = 2^31, v_{k+1} = v_k ^ (v_k >> 1))."""
    x, y, v = zero, zero, 1 << 31
    for k in range(SOBOL_BITS):
        bit = ((i >> k) & 1) == 1
        x = select(bit, x ^ (1 << (31 - k)), x)
        y = select(bit, y ^ v, y)
        v ^= v >> 1
    return x, y


def pixel_seed(pixel, seed: int):
    """Per-pixel seed of the draws (a UInt32 array of pixels and a Python seed)."""
    return _hash(pixel ^ _hash_int(seed))


def _hash_int(seed: int) -> int:
    """_hash of a Python integer, in Python (a constant of the traced kernels)."""
    x = seed & 0xFFFFFFFF
    x ^= x >> 16
    x = (x * 0x7FEB352D) & 0xFFFFFFFF
    x ^= x >> 15
    x = (x * 0x846CA68B) & 0xFFFFFFFF
    return x ^ (x >> 16)


def draw_pair(j, pseed, pair, mask, select, zero):
    """The 32-bit fractions (x, y) of sample j (its index in the pixel) in dimension pair `pair` (an array or an
    int) of the pixel whose seed is pseed; mask = 2^m - 1 with 2^m >= the pixel's sample count."""
    # samples past the first 2^SOBOL_BITS (j's high bits) scramble another copy of the net, not repeat this one
    base = _hash(pseed ^ _hash(pair * 0x9E3779B9 + 0x632BE5AB + (j >> SOBOL_BITS) * 0x85EBCA6B))
    i = _owen(j, _hash(base ^ 0x5BD1E995)) & mask      # a shuffle of 0 .. 2^m - 1: the low bits of j, permuted
    x, y = _sobol_pair(i, select, zero)
    return _owen(x, _hash(base ^ 0x68E31DA4)), _owen(y, _hash(base ^ 0xB5297A4D))


def to_unit(x, to_float):
    """A 32-bit fraction as a float in [0, 1): its top 24 bits, exact in single precision."""
    return to_float(x >> 8) * (1.0 / (1 << 24))


def index_mask(spp: int) -> int:
    """2^m - 1 for the smallest 2^m >= spp (at most SOBOL_BITS bits)."""
    return (1 << min(max(spp - 1, 0).bit_length(), SOBOL_BITS)) - 1


def net_points(pixel: int, seed: int, pair: int, spp: int):
    """[spp, 2] float64 numpy draws of one pixel's samples in one dimension pair: the same arithmetic as the traced
    kernels on uint32 numpy arrays (the tests' view of it)."""
    import numpy as np

    with np.errstate(over="ignore"):
        j = np.arange(spp, dtype=np.uint32)
        pseed = pixel_seed(np.full(spp, pixel, np.uint32), seed)
        x, y = draw_pair(j, pseed, np.uint32(pair), np.uint32(index_mask(spp)),
                         lambda c, a, b: np.where(c, a, b).astype(np.uint32), np.zeros(spp, np.uint32))
        f = lambda v: v.astype(np.float64)  # noqa: E731
        return np.stack([to_unit(x, f), to_unit(y, f)], 1)


class Draws:
    """The random numbers of one path-loop iteration: `u1(slot)` and `u2(slot)` for the slot'th draw of the
    iteration. With `sobol` None they are the PCG32 stream's next numbers in call order (the independent and
    stratified samplers, unchanged); else `sobol` = (j, pixel seed, iteration, mask) and slot s of iteration t
    is dimension pair FIRST_PAIR + t * pairs + s."""

    FIRST_PAIR = 2          # pairs 0 and 1: the pixel position and the lens

    def __init__(self, mi, dr, rng, sobol=None, pairs: int = 0):
        self.mi, self.dr, self.rng, self.sobol, self.pairs = mi, dr, rng, sobol, pairs

    def _pair(self, slot):
        mi, dr = self.mi, self.dr
        j, pseed, it, mask = self.sobol
        pair = it * self.pairs + (self.FIRST_PAIR + slot)
        return draw_pair(j, pseed, pair, mask, dr.select, mi.UInt32(0))

    def u1(self, slot: int):
        if self.sobol is None:
            return self.rng.next_float32()
        return to_unit(self._pair(slot)[0], self.mi.Float)

    def u2(self, slot: int):
        mi = self.mi
        if self.sobol is None:
            a = self.rng.next_float32()
            return mi.Point2f(a, self.rng.next_float32())
        x, y = self._pair(slot)
        return mi.Point2f(to_unit(x, mi.Float), to_unit(y, mi.Float))
