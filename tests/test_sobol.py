"""The Sobol sampler's draws (`ranad synth --sampler sobol`, ranad_core/synth/sobol.py), on numpy: no Mitsuba
needed. The oracle is the definition of a (0, m, 2)-net: 2^m points of which every elementary interval of area
2^-m (2^a by 2^(m-a) cells of the unit square) holds exactly one."""

from __future__ import annotations

import numpy as np
import pytest

from ranad_core.synth import sobol


def _cells(points: np.ndarray, a: int, m: int) -> np.ndarray:
    """The 2^a x 2^(m-a) cell of each point."""
    return np.floor(points[:, 0] * 2 ** a) * 2 ** (m - a) + np.floor(points[:, 1] * 2 ** (m - a))


@pytest.mark.parametrize("spp", [4, 16, 128])
def test_each_pair_of_each_pixel_is_a_net(spp):
    m = spp.bit_length() - 1
    for pixel, pair in ((0, 0), (7, 1), (1234, 2), (99999, 37)):
        p = sobol.net_points(pixel, 11, pair, spp)
        assert ((p >= 0) & (p < 1)).all()
        for a in range(m + 1):
            assert len(np.unique(_cells(p, a, m))) == spp, (pixel, pair, a)


def test_a_count_between_powers_of_two_takes_distinct_net_points():
    """12 samples: 12 of the 16-point net's points, so no two share an elementary interval of area 1/16."""
    p = sobol.net_points(5, 3, 4, 12)
    for a in range(5):
        assert len(np.unique(_cells(p, a, 4))) == 12


def test_the_index_shuffle_is_a_permutation():
    """Owen scrambling of a sample index, kept to its low m bits, permutes 0 .. 2^m - 1 for any seed: every
    sample of a pixel lands on a distinct net point."""
    with np.errstate(over="ignore"):
        j = np.arange(64, dtype=np.uint32)
        for seed in (0, 1, 0xDEADBEEF, 0x12345678):
            i = sobol._owen(j, np.uint32(seed)) & np.uint32(63)
            assert sorted(i.tolist()) == list(range(64))


def test_pixels_and_pairs_are_decorrelated():
    """Sample 0 of 4096 pixels: uniform in each pair, and two pairs' values unrelated (a shared index order
    would correlate a path's light choice with its BSDF choice)."""
    n = 4096
    first = np.array([[sobol.net_points(px, 21, pair, 16)[0, 0] for pair in (2, 3)] for px in range(n)])
    assert abs(first.mean(0) - 0.5).max() < 0.03
    assert np.histogram(first[:, 0], 8, (0, 1))[0].min() > n / 8 * 0.8
    assert abs(np.corrcoef(first[:, 0], first[:, 1])[0, 1]) < 0.05
    assert not np.array_equal(sobol.net_points(0, 21, 2, 16), sobol.net_points(1, 21, 2, 16))
    assert not np.array_equal(sobol.net_points(0, 21, 2, 16), sobol.net_points(0, 22, 2, 16))


def test_samples_past_the_largest_net_do_not_repeat_it():
    """A pixel with more samples than one net holds (2^SOBOL_BITS) gets a differently scrambled net for the rest,
    not the first samples' points again (which would trace the same paths twice)."""
    spp = (1 << sobol.SOBOL_BITS) + 64
    p = sobol.net_points(3, 5, 2, spp)
    assert len(np.unique(p, axis=0)) == spp
    np.testing.assert_array_equal(p[:64], sobol.net_points(3, 5, 2, 1 << sobol.SOBOL_BITS)[:64])
    assert not np.isin(p[-64:, 0], p[:64, 0]).any()
