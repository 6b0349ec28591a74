"""DeepImage operations against plain per-pixel references, the OpenEXR spec's own formulas and OpenImageIO.

The references below loop over pixels and samples in pure Python and follow "Interpreting OpenEXR Deep
Pixels" literally (split one sample at a time until nothing partially overlaps, then merge), so they are
slow but easy to check by eye; the vectorised code in ranad_core.deep must agree with them.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from ranad_core.deep import (
    DEPTH,
    NO_ALPHA,
    DeepImage,
    all_finite,
    associated_alpha,
    copy_values,
    nonfinite_bins,
    flatten,
    flatten_torch,
    gather_bins,
    merge,
    unsort,
)

FLT_MIN = float(np.finfo(np.float32).tiny)

#: colour + layer with its own alpha + layer without (-> A) + auxiliary channel
CH_LAYERS = ["R", "G", "B", "A", "Z", "ZBack", "diffuse.R", "diffuse.G", "diffuse.B", "diffuse.A", "spec.R", "N.x"]
#: per-colour alphas, no A: R->AR, ...; L1.Y and extra have no alpha at all
CH_RGB_ALPHA = ["AR", "AG", "AB", "R", "G", "B", "Z", "ZBack", "L1.Y", "extra"]
#: points only
CH_NO_ZBACK = ["R", "G", "B", "A", "Z"]


# ---------------------------------------------------------------------------------------------------------
# synthetic messy images
# ---------------------------------------------------------------------------------------------------------
def make_messy(seed: int, channels, width=9, height=7, origin=(3, -2), id_names=("id", "obj")) -> DeepImage:
    """Unsorted bins, overlapping volumes, coincident samples, alpha exactly 0/1/denormal, empty pixels,
    pixels with 10+ bins, points stored with ZBack < Z, -0.0 depths."""
    rng = np.random.default_rng(seed)
    p = width * height
    counts = rng.choice([0, 1, 2, 3, 4, 6, 12, 15], size=p, p=[0.12, 0.18, 0.2, 0.18, 0.12, 0.08, 0.07, 0.05])
    counts[0], counts[1] = 0, 14
    n = int(counts.sum())
    c = len(channels)
    vals = rng.uniform(0.0, 2.0, size=(n, c))
    on_grid = rng.random(n) < 0.6
    z = np.where(on_grid, rng.integers(0, 8, size=n) * 0.5, rng.uniform(0.0, 4.0, size=n))
    z[rng.random(n) < 0.03] = -0.0
    kind = rng.random(n)
    length = np.where(rng.random(n) < 0.5, rng.integers(1, 5, size=n) * 0.5, rng.uniform(0.1, 3.0, size=n))
    zb = np.where(kind < 0.3, z, np.where(kind < 0.4, z - 0.25, z + length))
    for j, name in enumerate(channels):
        base = name.rpartition(".")[2]
        if base in ("A", "AR", "AG", "AB"):
            r = rng.random(n)
            a = rng.uniform(0.0, 1.0, size=n)
            a = np.where(r < 0.15, 0.0, np.where(r < 0.3, 1.0, np.where(r < 0.34, 1e-39, a)))
            vals[:, j] = a
    if "Z" in channels:
        vals[:, channels.index("Z")] = z
    if "ZBack" in channels:
        vals[:, channels.index("ZBack")] = zb
    vals = vals.astype(np.float32)
    # exact duplicates of some samples within their pixel (coincident samples, equal alphas)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    colour = [j for j, r in enumerate(ref_roles(channels)) if r not in (None, channels[j])][0]
    for pi in np.flatnonzero(counts >= 3)[::3]:
        s = offsets[pi]
        vals[s + 1, :] = vals[s, :]
        vals[s + 1, colour] += 0.5  # same depth and alpha, different colour
    ids = {k: rng.integers(0, 2**32, size=n, dtype=np.uint64).astype(np.uint32) for k in id_names}
    x0, y0 = origin
    return DeepImage(vals, offsets, channels, ids=ids, data_window=(x0, y0, x0 + width - 1, y0 + height - 1),
                     header={"deepImageState": "MESSY", "comments": "kept"})


def make_tidy(seed: int, channels, width=8, height=6) -> DeepImage:
    """Sorted, non-overlapping bins (what OpenImageIO's flatten assumes), alpha 0 and 1 included."""
    rng = np.random.default_rng(seed)
    counts = rng.choice([0, 1, 2, 3, 5, 11], size=width * height)
    counts[0], counts[1] = 0, 11
    n = int(counts.sum())
    c = len(channels)
    vals = rng.uniform(0.0, 1.0, size=(n, c))
    gaps = rng.uniform(0.1, 1.0, size=n)
    lengths = np.where(rng.random(n) < 0.5, 0.0, rng.uniform(0.05, 0.5, size=n))
    offsets = np.concatenate([[0], np.cumsum(counts)])
    pix = np.repeat(np.arange(width * height), counts)
    step = gaps + lengths
    cs = np.cumsum(step)
    base = np.repeat(cs[offsets[:-1][counts > 0]] - step[offsets[:-1][counts > 0]], counts[counts > 0])
    zfront = cs - step - base + gaps
    for j, name in enumerate(channels):
        if name.rpartition(".")[2] in ("A", "AR", "AG", "AB"):
            r = rng.random(n)
            vals[:, j] = np.where(r < 0.1, 0.0, np.where(r < 0.2, 1.0, vals[:, j]))
    vals[:, channels.index("Z")] = zfront
    if "ZBack" in channels:
        vals[:, channels.index("ZBack")] = zfront + lengths
    assert pix.size == n
    return DeepImage(vals.astype(np.float32), offsets, channels, ids={"id": np.arange(n, dtype=np.uint32)},
                     data_window=(0, 0, width - 1, height - 1))


def pixel_rows(img: DeepImage, p: int) -> range:
    return range(int(img.offsets[p]), int(img.offsets[p + 1]))


# ---------------------------------------------------------------------------------------------------------
# references: the spec, one pixel at a time
# ---------------------------------------------------------------------------------------------------------
def ref_roles(channels):
    """Associated alpha per channel written straight from the spec's table (independent of the library)."""
    out = []
    for name in channels:
        if name in ("Z", "ZBack"):
            out.append(None)
            continue
        layer, _, base = name.rpartition(".")
        if base in ("A", "AR", "AG", "AB"):
            out.append(name)
            continue
        match = {"R": ["AR", "A"], "G": ["AG", "A"], "B": ["AB", "A"]}.get(base, ["A"])
        layers = [layer]
        while layers[-1]:
            layers.append(layers[-1].rpartition(".")[0])
        found = None
        for lay in layers:
            for m in match:
                cand = f"{lay}.{m}" if lay else m
                if cand in channels:
                    found = cand
                    break
            if found:
                break
        out.append(found or "")  # "" = no alpha
    return out


def spec_split(a, c, zf, zb, z):
    """splitVolumeSample from the spec's appendix (one colour channel), in double precision."""
    a = max(0.0, min(a, 1.0))
    if a == 1:
        return 1.0, c, 1.0, c
    xf, xb = (z - zf) / (zb - zf), (zb - z) / (zb - zf)
    if a > FLT_MIN:
        af = -math.expm1(xf * math.log1p(-a))
        ab = -math.expm1(xb * math.log1p(-a))
        return af, (af / a) * c, ab, (ab / a) * c
    return a * xf, c * xf, a * xb, c * xb


def spec_merge_pair(a1, c1, a2, c2, dtype=np.float32):
    """mergeOverlappingSamples from the spec's appendix, in float32 like the C++."""
    f = dtype
    a1, a2, c1, c2 = (f(max(0.0, min(a1, 1.0))), f(max(0.0, min(a2, 1.0))), f(c1), f(c2))
    am = a1 + a2 - a1 * a2
    if a1 == 1 and a2 == 1:
        return am, (c1 + c2) / f(2)
    if a1 == 1:
        return am, c1
    if a2 == 1:
        return am, c2
    mx = f(np.finfo(f).max)
    u1 = f(-np.log1p(-a1))
    v1 = u1 / a1 if u1 < a1 * mx else f(1)
    u2 = f(-np.log1p(-a2))
    v2 = u2 / a2 if u2 < a2 * mx else f(1)
    u = u1 + u2
    w = am / u if (u > 1 or am < u * mx) else f(1)
    return am, (c1 * v1 + c2 * v2) * w


class Sample:
    def __init__(self, vals, ids, index):
        self.v = [float(x) for x in vals]
        self.ids = ids
        self.index = index  # input bin, for the id tie-break


def ref_tidy_pixel(samples, channels):
    """Spec procedure: split partially overlapping samples until none, merge coincident ones, sort."""
    roles = ref_roles(channels)
    zi = channels.index("Z")
    zbi = channels.index("ZBack") if "ZBack" in channels else None
    col = {n: i for i, n in enumerate(channels)}

    def zf(s):
        return s.v[zi] + 0.0

    def zbk(s):
        return max(zf(s), s.v[zbi]) if zbi is not None else zf(s)

    def is_vol(s):
        return zbk(s) > zf(s)

    for s in samples:
        s.v[zi] = zf(s)
        if zbi is not None:
            s.v[zbi] = zbk(s)

    def split(s, z):
        front, back = Sample(s.v, s.ids, s.index), Sample(s.v, s.ids, s.index)
        z0, z1 = zf(s), zbk(s)
        for j, name in enumerate(channels):
            r = roles[j]
            if r is None:
                continue
            if r == "":  # no alpha: treated as alpha 0
                _, front.v[j], _, back.v[j] = spec_split(0.0, s.v[j], z0, z1, z)
            else:
                af, cf, ab, cb = spec_split(s.v[col[r]], s.v[j], z0, z1, z)
                front.v[j], back.v[j] = (af, ab) if r == name else (cf, cb)
        front.v[zbi], back.v[zi] = z, z
        return front, back

    changed = True
    while changed:
        changed = False
        for j, sj in enumerate(samples):
            if not is_vol(sj):
                continue
            for i, si in enumerate(samples):
                if i == j:
                    continue
                cut = None
                if zf(sj) < zf(si) < zbk(sj):
                    cut = zf(si)
                elif is_vol(si) and zf(sj) < zbk(si) < zbk(sj):
                    cut = zbk(si)
                if cut is not None:
                    samples[j:j + 1] = split(sj, np.float32(cut).item())
                    changed = True
                    break
            if changed:
                break

    groups: dict[tuple[float, float], list[Sample]] = {}
    for s in samples:
        groups.setdefault((zf(s), zbk(s)), []).append(s)
    out = []
    cov_name = "A" if "A" in channels else None
    for key in sorted(groups):
        g = groups[key]
        if len(g) == 1:
            out.append(g[0])
            continue
        m = Sample(g[0].v, None, None)
        for j, name in enumerate(channels):
            r = roles[j]
            if r is None:
                continue
            if r == "":
                m.v[j] = sum(s.v[j] for s in g)
                continue
            alphas = [max(0.0, min(s.v[col[r]], 1.0)) for s in g]
            am = 0.0
            for a in alphas:  # 1 - prod(1 - a) as the spec's robust a1 + a2 - a1 a2 (tiny alphas survive)
                am = am + a - am * a
            if 1.0 in alphas:  # exactly opaque (a1 + 1 - a1 can round to 1 - ulp)
                am = 1.0
            if r == name:
                m.v[j] = am
                continue
            opaque = [s.v[j] for s, a in zip(g, alphas) if a == 1.0]
            if opaque:  # spec: an opaque colour wins, two opaque colours average -> mean of the opaque ones
                m.v[j] = sum(opaque) / len(opaque)
                continue
            us = [-math.log1p(-a) if a > 0 else 0.0 for a in alphas]
            vs = [u / a if a > 0 else 1.0 for u, a in zip(us, alphas)]
            w = am / sum(us) if sum(us) != 0 else 1.0
            m.v[j] = w * sum(s.v[j] * v for s, v in zip(g, vs))
        # coverage as stored (float32): pieces of identical samples split in a different order can differ
        # by an ulp in double precision, which must not break the tie
        if cov_name is not None:
            cov = [np.float32(s.v[col[cov_name]]) for s in g]
        else:
            cov = [max(np.float32(s.v[col[n]]) for n in ("AR", "AG", "AB") if n in col) for s in g]
        best = max(cov)
        m.ids = min((s for s, cv in zip(g, cov) if cv == best), key=lambda s: s.index).ids
        out.append(m)
    return out


def ref_tidy(img: DeepImage):
    """list per pixel of (values list, ids tuple)."""
    names = sorted(img.ids)
    result = []
    for p in range(img.num_pixels):
        samples = [Sample(img.values[i], tuple(int(img.ids[k][i]) for k in names), i) for i in pixel_rows(img, p)]
        result.append([(s.v, s.ids) for s in ref_tidy_pixel(samples, img.channels)] if samples else [])
    return result


def ref_flatten_pixel(samples, channels):
    """Front-to-back over of tidy samples (list of value lists); Z/ZBack as documented in deep.flatten."""
    roles = ref_roles(channels)
    col = {n: i for i, n in enumerate(channels)}
    out = [0.0] * len(channels)
    for j, name in enumerate(channels):
        r = roles[j]
        if r is None:
            continue
        t = 1.0
        for s in samples:
            out[j] += s[j] * t
            if r != "":
                t *= 1.0 - max(0.0, min(s[col[r]], 1.0))
    if "Z" in channels:
        zi = col["Z"]
        zbi = col.get("ZBack")
        if "A" in col:
            cov = [s[col["A"]] for s in samples]
        elif any(n in col for n in ("AR", "AG", "AB")):
            cov = [max(s[col[n]] for n in ("AR", "AG", "AB") if n in col) for s in samples]
        else:
            cov = [0.5] * len(samples)
        contributing = []
        for s, cv in zip(samples, cov):
            if cv > 0:
                contributing.append((s, cv))
            if cv >= 1:
                break
        out[zi] = contributing[0][0][zi] if contributing else 0.0
        if zbi is not None:
            if contributing:
                s, cv = contributing[-1]
                out[zbi] = s[zi] if (cv >= 1 or s[zbi] <= s[zi]) else s[zbi]
            else:
                out[zbi] = 0.0
    return out


def assert_close(actual, expected, rtol=1e-5, atol=1e-6):
    np.testing.assert_allclose(np.asarray(actual, np.float64), np.asarray(expected, np.float64), rtol=rtol,
                               atol=atol)


# ---------------------------------------------------------------------------------------------------------
# channel roles, select
# ---------------------------------------------------------------------------------------------------------
def test_associated_alpha_follows_the_spec_example():
    ch = ["A", "AR", "AG", "R", "Z", "L1.A", "L1.AR", "L1.R", "L1.G", "L1.L2.G", "G", "B", "N.x", "ZBack", "L1.Z"]
    roles = associated_alpha(ch)
    named = {c: (ch[r] if r >= 0 else r) for c, r in zip(ch, roles)}
    assert named["R"] == "AR" and named["L1.R"] == "L1.AR" and named["L1.G"] == "L1.A"
    assert named["L1.L2.G"] == "L1.A" and named["G"] == "AG" and named["B"] == "A"
    assert named["N.x"] == "A" and named["L1.Z"] == "L1.A"
    assert named["A"] == "A" and named["AR"] == "AR" and named["Z"] == DEPTH and named["ZBack"] == DEPTH
    assert associated_alpha(["R", "extra", "Z"]) == [NO_ALPHA, NO_ALPHA, DEPTH]
    for chans in (CH_LAYERS, CH_RGB_ALPHA, CH_NO_ZBACK):  # the test reference agrees
        ref = ref_roles(chans)
        for name, r, rr in zip(chans, associated_alpha(chans), ref):
            assert (rr is None and r == DEPTH) or (rr == "" and r == NO_ALPHA) or chans[r] == rr, name


def test_columns_equal_the_stacked_channels_in_the_order_asked():
    img = make_messy(3, CH_LAYERS)
    names = ["spec.R", "A", "R", "A", "N.x"]          # any order, repeats allowed
    cols = img.columns(names)
    assert cols.flags["C_CONTIGUOUS"] and cols.dtype == img.values.dtype
    np.testing.assert_array_equal(cols, np.stack([img.channel(n) for n in names], 1))
    assert img.columns([]).shape == (img.num_bins, 0)
    with pytest.raises(KeyError):
        img.columns(["R", "nope"])


def test_select_by_name_and_layer():
    img = make_messy(0, CH_LAYERS)
    sub = img.select(["diffuse", "Z", "id"])
    assert sub.channels == ["Z", "diffuse.R", "diffuse.G", "diffuse.B", "diffuse.A"]
    for name in sub.channels:
        assert np.array_equal(sub.channel(name), img.channel(name))
    assert set(sub.ids) == {"id", "obj"} and np.array_equal(sub.ids["obj"], img.ids["obj"])
    assert np.array_equal(sub.offsets, img.offsets)
    assert set(sub.channel_types) == set(sub.channels) | set(sub.ids)
    assert img.select("spec").channels == ["spec.R"]
    assert img.select("R").channels == ["R"]  # exact name, not every *.R
    with pytest.raises(KeyError):
        img.select(["diffuse", "nope"])
    sub.values[:] = 0  # a copy
    assert img.channel("diffuse.R").any()


# ---------------------------------------------------------------------------------------------------------
# sorted / unsort
# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("channels", [CH_LAYERS, CH_NO_ZBACK])
def test_sorted_is_stable_front_to_back_and_unsort_inverts(channels):
    img = make_messy(1, channels)
    s, perm = img.sorted()
    assert perm.dtype == np.int64 and perm.shape == (img.num_bins,)
    assert np.array_equal(s.values, img.values[perm]) and np.array_equal(s.offsets, img.offsets)
    for k in img.ids:
        assert np.array_equal(s.ids[k], img.ids[k][perm])
    z = img.channel("Z")
    zb = img.channel("ZBack") if "ZBack" in channels else z
    for p in range(img.num_pixels):
        rows = list(pixel_rows(img, p))
        expected = sorted(rows, key=lambda i: (float(z[i]), float(zb[i])))  # Python's sort is stable
        assert list(perm[rows]) == expected
    assert np.array_equal(unsort(s.values, perm), img.values)
    assert np.array_equal(unsort(s.ids["id"], perm), img.ids["id"])
    torch = pytest.importorskip("torch")
    assert torch.equal(unsort(torch.from_numpy(s.values), perm), torch.from_numpy(img.values))
    s2, perm2 = s.sorted()  # already sorted: identity
    assert np.array_equal(perm2, np.arange(img.num_bins))
    same = unsort(s.values, perm2, copy=False)   # a reader's view where nothing moves; a copy by default
    assert same is s.values and unsort(s.values, perm2) is not s.values
    assert np.array_equal(unsort(s.values, perm, copy=False), img.values)   # a permutation still moves
    s3, perm3 = s.sorted(copy=False)   # sorted already, for an owner of the image: itself, not a copy
    assert s3 is s and np.array_equal(perm3, perm2)
    m, mperm = img.sorted(copy=False)  # out of order: sorted as by default, into new arrays
    assert np.array_equal(m.values, s.values) and np.array_equal(mperm, perm)
    assert not np.shares_memory(m.values, img.values)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_all_finite_finds_one_bad_value_anywhere(bad, monkeypatch):
    """all_finite agrees with np.isfinite(...).all(), whichever chunk (first, last, across a boundary, the short
    tail) holds the one non-finite value."""
    import ranad_core.deep as deep

    monkeypatch.setattr(deep, "FINITE_CHUNK", 64)   # many chunks on a small array
    v = np.random.default_rng(0).normal(size=(301, 7)).astype(np.float32)
    assert all_finite(v) and all_finite(v[:0]) and all_finite(np.arange(5))
    for at in (0, 63, 64, 65, 1000, v.size - 1):
        w = v.copy()
        w.reshape(-1)[at] = bad
        assert not all_finite(w), at
        assert all_finite(w[:, ::2]) == ((at % 7) % 2 == 1), at   # a strided view: its column kept or not
    assert all_finite(np.full(3, 7.0, np.float16)) and not all_finite(np.full(3, np.inf, np.float16))
    w = v.copy()
    w[[3, 3, 200], [0, 5, 6]] = bad                 # two bad values in one bin, one in another
    assert nonfinite_bins(w) == 2 and nonfinite_bins(v) == 0


def test_copy_values_is_an_equal_independent_array():
    v = np.random.default_rng(1).normal(size=(1000, 5)).astype(np.float32)
    c = copy_values(v)
    assert c.dtype == v.dtype and np.array_equal(c, v) and not np.shares_memory(c, v)
    c[0, 0] = 99
    assert v[0, 0] != 99
    assert copy_values(v[:0]).shape == (0, 5)


def test_sorted_needs_z():
    from ranad_core.errors import RanadError

    img = DeepImage(np.zeros((1, 2), np.float32), [0, 1], ["R", "A"])
    with pytest.raises(RanadError, match="no Z channel"):   # a problem of the file: ranad's one-line error
        img.sorted()
    with pytest.raises(RanadError, match="no Z channel"):
        img.tidy()
    with pytest.raises(RanadError, match="no Z channel"):
        flatten(img)
    assert flatten(img, tidy=False).shape == (1, 1, 2)  # compositing in stored order needs no depth
    img.ids["Z"] = np.ones(1, np.uint32)   # a Z of an id channel's type: said so, not "no Z"
    with pytest.raises(RanadError, match="channel Z stored as UINT"):
        img.sorted()


# ---------------------------------------------------------------------------------------------------------
# tidy
# ---------------------------------------------------------------------------------------------------------
def assert_tidy_matches_reference(img: DeepImage):
    t = img.tidy()
    ref = ref_tidy(img)
    names = sorted(img.ids)
    assert t.channels == img.channels and t.data_window == img.data_window
    assert [len(r) for r in ref] == list(t.counts)
    exp_vals = np.array([v for px in ref for v, _ in px], dtype=np.float64).reshape(-1, len(img.channels))
    assert_close(t.values, exp_vals)
    for j, k in enumerate(names):
        assert np.array_equal(t.ids[k], np.array([ids[j] for px in ref for _, ids in px], dtype=np.uint32)), k
    return t


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("channels", [CH_LAYERS, CH_RGB_ALPHA, CH_NO_ZBACK])
def test_tidy_matches_spec_reference(seed, channels):
    img = make_messy(seed, channels)
    t = assert_tidy_matches_reference(img)
    assert t.header == img.header  # tidy never makes a deepImageState claim false
    assert_is_tidy(t)
    t2 = t.tidy()  # idempotent, bit for bit
    assert np.array_equal(t2.offsets, t.offsets) and np.array_equal(t2.values, t.values)
    for k in t.ids:
        assert np.array_equal(t2.ids[k], t.ids[k])


def assert_is_tidy(t: DeepImage):
    """The spec's sorted and non-overlapping definitions, checked on neighbours (enough once sorted)."""
    z = t.channel("Z").astype(np.float64)
    zb = np.maximum(z, t.channel("ZBack")) if "ZBack" in t.channels else z
    same = t.pixel_index()[1:] == t.pixel_index()[:-1]
    zi, zj, bi, bj = z[:-1], z[1:], zb[:-1], zb[1:]
    ordered = (zi < zj) | ((zi == zj) & (bi <= bj))
    disjoint = ((zi < zj) & (bi <= zj)) | ((zi == zj) & (bi <= zi) & (bj > zj))
    assert np.all(ordered[same]) and np.all(disjoint[same])


def test_tidy_splits_and_merges_as_the_spec_functions():
    """Two volumes [0,2] (a=.5) and [1,3] (a=.75) -> [0,1], [1,2] merged, [2,3]; compare with the appendix
    functions applied by hand (float32 merge as in the C++)."""
    ch = ["R", "A", "Z", "ZBack"]
    v = np.array([[0.6, 0.5, 0.0, 2.0], [0.3, 0.75, 1.0, 3.0]], np.float32)
    t = DeepImage(v, [0, 2], ch, data_window=(0, 0, 0, 0)).tidy()
    a1f, c1f, a1b, c1b = spec_split(0.5, 0.6, 0.0, 2.0, 1.0)
    a2f, c2f, a2b, c2b = spec_split(0.75, 0.3, 1.0, 3.0, 2.0)
    am, cm = spec_merge_pair(a1b, c1b, a2f, c2f)
    assert t.counts.tolist() == [3]
    assert_close(t.values[:, 2:], [[0, 1], [1, 2], [2, 3]], atol=0)
    assert_close(t.values[:, :2], [[c1f, a1f], [cm, am], [c2b, a2b]])
    # alpha 0 + alpha 0 colours add; opaque + non-opaque: the opaque colour
    for (a1, c1, a2, c2) in [(0.0, 0.2, 0.0, 0.3), (1.0, 0.2, 0.4, 0.3), (0.3, 0.2, 1.0, 0.7), (1, 0.2, 1, 0.6),
                             (1e-39, 0.2, 0.5, 0.1), (1e-30, 0.2, 1e-30, 0.1)]:
        v = np.array([[c1, a1, 1.0, 1.0], [c2, a2, 1.0, 1.0]], np.float32)
        t = DeepImage(v, [0, 2], ch, data_window=(0, 0, 0, 0)).tidy()
        am, cm = spec_merge_pair(a1, c1, a2, c2)
        assert_close(t.values[0, :2], [cm, am], rtol=1e-6, atol=1e-30)


def test_nway_merge_equals_pairwise_fold_of_the_spec_function():
    """For non-opaque samples the spec's pairwise merge is associative, so merging n at once is the same."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        a = rng.uniform(0, 0.99, size=5)
        a[rng.random(5) < 0.3] = 0.0
        c = rng.uniform(0, 1, size=5)
        am, cm = a[0], c[0]
        for k in range(1, 5):
            am, cm = spec_merge_pair(am, cm, a[k], c[k], dtype=np.float64)
        v = np.stack([c, a, np.ones(5), np.ones(5)], axis=1).astype(np.float32)
        t = DeepImage(v, [0, 5], ["R", "A", "Z", "ZBack"], data_window=(0, 0, 0, 0)).tidy()
        am32, cm32 = a[0].astype(np.float32), c[0].astype(np.float32)  # fold again on the float32 inputs
        for k in range(1, 5):
            am32, cm32 = spec_merge_pair(float(am32), float(cm32), float(np.float32(a[k])), float(np.float32(c[k])),
                                         dtype=np.float64)
        assert_close(t.values[0, :2], [cm32, am32], rtol=1e-5)


def test_tidy_ids_follow_the_largest_alpha():
    ch = ["R", "A", "Z"]
    v = np.array([[1, 0.2, 5], [1, 0.7, 5], [1, 0.7, 5], [1, 0.1, 2]], np.float32)
    t = DeepImage(v, [0, 4], ch, ids={"id": np.array([10, 20, 30, 40], np.uint32)}, data_window=(0, 0, 0, 0)).tidy()
    assert t.ids["id"].tolist() == [40, 20]  # depth order; tie between 20 and 30 goes to the earlier bin


def test_tidy_of_an_empty_and_an_untouched_image():
    ch = ["R", "A", "Z", "ZBack"]
    empty = DeepImage(np.zeros((0, 4), np.float32), np.zeros(7, np.int64), ch, data_window=(0, 0, 2, 1))
    assert empty.tidy().num_bins == 0
    assert np.array_equal(flatten(empty), np.zeros((2, 3, 4), np.float32))
    img = make_tidy(4, ch)
    t = img.tidy()
    assert np.array_equal(t.values, img.values) and np.array_equal(t.offsets, img.offsets)


# ---------------------------------------------------------------------------------------------------------
# flatten
# ---------------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", [0, 5])
@pytest.mark.parametrize("channels", [CH_LAYERS, CH_RGB_ALPHA, CH_NO_ZBACK])
def test_flatten_matches_reference(seed, channels):
    img = make_messy(seed, channels)
    flat = flatten(img)
    assert flat.shape == (img.height, img.width, len(channels)) and flat.dtype == np.float32
    ref = ref_tidy(img)
    expected = np.array([ref_flatten_pixel([v for v, _ in px], channels) for px in ref]).reshape(flat.shape)
    assert_close(flat, expected)
    assert np.all(flat.reshape(-1, len(channels))[img.counts == 0] == 0)
    assert np.array_equal(img.flatten(), flat)


def test_flatten_depth_channels():
    ch = ["R", "A", "Z", "ZBack"]
    px = [
        [[1, 0.0, 1, 1], [1, 0.5, 2, 4], [1, 1.0, 6, 7], [1, 0.5, 8, 8]],  # Z=2 (first a>0), ZBack=6 (opaque)
        [[1, 0.5, 3, 3], [1, 0.2, 4, 7]],  # never opaque: ZBack = back of the last sample
        [[1, 0.0, 3, 3]],  # only alpha 0: 0, 0
        [],
    ]
    vals = np.array([s for p in px for s in p], np.float32)
    img = DeepImage(vals, np.concatenate([[0], np.cumsum([len(p) for p in px])]), ch, data_window=(0, 0, 3, 0))
    flat = flatten(img, tidy=False)[0]
    assert flat[:, 2].tolist() == [2, 3, 0, 0] and flat[:, 3].tolist() == [6, 7, 0, 0]
    assert_close(flat[:, 1], [1, 1 - 0.5 * 0.8, 0, 0])
    assert flat[2, 0] == 1  # alpha-0 emission still adds


def oiio_flatten(img: DeepImage) -> dict[str, np.ndarray]:
    oiio = pytest.importorskip("OpenImageIO")
    spec = oiio.ImageSpec(img.width, img.height, len(img.channels), oiio.FLOAT)
    spec.channelnames = tuple(img.channels)
    spec.deep = True
    buf = oiio.ImageBuf(spec)
    counts = img.counts
    for p in range(img.num_pixels):
        x, y = p % img.width, p // img.width
        buf.set_deep_samples(x, y, 0, int(counts[p]))
        for s, i in enumerate(pixel_rows(img, p)):
            for c in range(len(img.channels)):
                buf.set_deep_value(x, y, 0, c, s, float(img.values[i, c]))
    flat = oiio.ImageBufAlgo.flatten(buf)
    assert not flat.has_error, flat.geterror()
    pixels = flat.get_pixels(oiio.FLOAT).reshape(img.height, img.width, -1)
    return {name: pixels[..., k] for k, name in enumerate(flat.spec().channelnames)}


@pytest.mark.parametrize("seed", [0, 1])
def test_flatten_of_tidy_input_matches_openimageio(seed):
    ch = ["R", "G", "B", "A", "Z", "ZBack", "aux"]
    img = make_tidy(seed, ch)
    ours = flatten(img, tidy=False)
    assert np.array_equal(flatten(img), ours)  # tidy input: tidying changes nothing
    theirs = oiio_flatten(img)
    for k, name in enumerate(ch):
        if name in ("Z", "ZBack"):  # OpenImageIO blends depth its own way; ours is documented in flatten
            continue
        assert_close(ours[..., k], theirs[name], rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------------------------------------------------
# flatten_torch
# ---------------------------------------------------------------------------------------------------------
def test_flatten_torch_matches_flatten_and_has_finite_gradients():
    torch = pytest.importorskip("torch")
    for channels in (CH_LAYERS, CH_RGB_ALPHA):
        t = make_messy(7, channels).tidy()
        sub = t.select([c for c in channels if c not in ("Z", "ZBack")])
        values, offsets, ids = sub.to_torch()
        assert values.dtype == torch.float32 and offsets.dtype == torch.int64
        assert all(v.dtype == torch.int64 for v in ids.values())
        values = values.clone().requires_grad_(True)
        out = flatten_torch(values, offsets, associated_alpha(sub.channels))
        expected = flatten(sub, tidy=False).reshape(-1, len(sub.channels))
        assert_close(out.detach().numpy(), expected)
        weights = torch.rand(out.shape, generator=torch.Generator().manual_seed(0))
        (grad,) = torch.autograd.grad((out * weights).sum(), values)
        assert torch.isfinite(grad).all()
        a = sub.values[:, sub.channels.index("A" if "A" in sub.channels else "AR")]
        assert (a == 1).any() and (a == 0).any()


def test_flatten_torch_opaque_sample_gradient_and_exact_zeros():
    torch = pytest.importorskip("torch")
    # one pixel: c0 a=.5, c1 opaque, c2 and c3 (opaque) behind it, c4 behind two opaque; an empty pixel
    v = torch.tensor([[0.3, 0.5], [0.7, 1.0], [0.9, 0.4], [0.2, 1.0], [0.8, 0.3]], dtype=torch.float64,
                     requires_grad=True)
    offsets = torch.tensor([0, 5, 5])
    out = flatten_torch(v, offsets, 1)
    assert out[0, 0].item() == pytest.approx(0.3 + 0.5 * 0.7, abs=1e-15)
    assert out[0, 1].item() == 1.0 and out[1].tolist() == [0.0, 0.0]
    (g,) = torch.autograd.grad(out[0, 0], v)
    assert torch.isfinite(g).all()
    # d out / d a1 = -(1 - a0) (c2 + (1 - a2) c3): the one-sided derivative at a1 = 1, although everything
    # behind a1 contributes exactly 0; behind two opaque bins (c4) even the derivatives vanish
    assert g[1, 1].item() == pytest.approx(-0.5 * (0.9 + 0.6 * 0.2))
    assert g[2, 0].item() == 0.0 and g[3, 0].item() == 0.0 and g[3, 1].item() == 0.0
    assert g[4].tolist() == [0.0, 0.0]
    h = 1e-7
    w = v.detach().clone()
    w[1, 1] -= h
    fd = (out[0, 0].item() - flatten_torch(w, offsets, 1)[0, 0].item()) / h
    assert g[1, 1].item() == pytest.approx(fd, rel=1e-5)


def test_flatten_torch_gradcheck():
    torch = pytest.importorskip("torch")
    gen = torch.Generator().manual_seed(1)
    counts = torch.tensor([3, 0, 1, 5, 2])
    offsets = torch.cat([torch.zeros(1, dtype=torch.int64), counts.cumsum(0)])
    n = int(offsets[-1])
    v = torch.rand(n, 3, generator=gen, dtype=torch.float64)
    v[:, 2] = v[:, 2] * 0.9 + 0.05  # alpha away from the clamp kinks
    v.requires_grad_(True)
    assert torch.autograd.gradcheck(lambda x: flatten_torch(x, offsets, [2, -1, 2]), (v,))


def test_composite_kernel_matches_flatten_torch_and_the_thread_count():
    """baselines.composite_groups (the C++ one-pass kernel the flat prior uses) against flatten_torch, the
    differentiable composite, on bins with opaque, clear and out-of-range alphas, empty pixels and a deep pixel, for
    a premultiplied group and one normalised by the pixel's alpha; and the same bits with 1 and 2 threads."""
    torch = pytest.importorskip("torch")
    from ranad_core.baselines import EPS, composite_groups
    from ranad_core.rana.extension import cpu_extension_or_none

    if cpu_extension_or_none() is None:
        pytest.skip("the C++ kernels do not build here (composite_groups then uses flatten_torch itself)")
    rng = np.random.default_rng(3)
    counts = rng.integers(0, 6, 500)
    counts[:3] = (0, 40, 1)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    n = int(offsets[-1])
    values = rng.uniform(-0.5, 3, (n, 6)).astype(np.float32)
    values[:, 3] = rng.choice([0.0, 0.3, 0.9, 1.0, 1.5, -0.2], n)
    img = DeepImage(values=values, offsets=offsets, channels=["R", "G", "B", "A", "u", "v"],
                    data_window=(0, 0, len(counts) - 1, 0), display_window=(0, 0, len(counts) - 1, 0))
    groups = [(values[:, :3], True), (values[:, 4:], False)]
    v64 = torch.from_numpy(values).double()
    a = v64[:, 3:4]
    flat = flatten_torch(torch.cat([v64[:, :3], v64[:, 4:] * a, a], 1), torch.from_numpy(offsets), 5).numpy()
    expect = [flat[:, :3], flat[:, 3:5] / np.maximum(flat[:, 5:], EPS)]
    threads = torch.get_num_threads()
    try:
        torch.set_num_threads(1)
        one = composite_groups(img, groups)
        torch.set_num_threads(2)
        two = composite_groups(img, groups)
    finally:
        torch.set_num_threads(threads)
    for got, want, again in zip(one, expect, two):
        assert got.dtype == np.float32 and got.shape == want.shape
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-5)
        assert np.array_equal(got, again)
    assert (one[0][0] == 0).all() and (one[1][0] == 0).all()


# ---------------------------------------------------------------------------------------------------------
# crop / merge / gather
# ---------------------------------------------------------------------------------------------------------
def test_crop_pads_and_round_trips():
    img = make_messy(2, CH_LAYERS)  # data window (3, -2) .. (11, 4)
    window = (1, -3, 7, 0)  # partly outside
    c = img.crop(window)
    assert c.data_window == window and c.display_window == img.display_window
    x0, y0 = img.data_window[:2]
    for y in range(window[1], window[3] + 1):
        for x in range(window[0], window[2] + 1):
            q = (y - window[1]) * c.width + (x - window[0])
            rows_c = list(pixel_rows(c, q))
            inside = img.data_window[0] <= x <= img.data_window[2] and img.data_window[1] <= y <= img.data_window[3]
            rows_i = list(pixel_rows(img, (y - y0) * img.width + (x - x0))) if inside else []
            assert np.array_equal(c.values[rows_c], img.values[rows_i])
            assert np.array_equal(c.ids["obj"][rows_c], img.ids["obj"][rows_i])
    big = img.crop((0, -5, 15, 9))
    back = big.crop(img.data_window)
    assert np.array_equal(back.values, img.values) and np.array_equal(back.offsets, img.offsets)
    assert all(np.array_equal(back.ids[k], img.ids[k]) for k in img.ids)
    outside = img.crop((100, 100, 101, 102))
    assert outside.num_bins == 0 and outside.num_pixels == 6
    with pytest.raises(ValueError):
        img.crop((5, 5, 4, 5))


def test_merge_concatenates_per_pixel():
    a = make_messy(3, CH_LAYERS)
    b = make_messy(4, CH_LAYERS)
    b_shuffled = b.select(b.channels)  # same data, columns reordered below
    b_shuffled = b_shuffled.with_values(b.values[:, ::-1].copy(), b.channels[::-1])
    m = merge(a, b_shuffled)
    assert m.channels == a.channels and "deepImageState" not in m.header and m.header["comments"] == "kept"
    assert np.array_equal(m.counts, a.counts + b.counts)
    for p in range(a.num_pixels):
        rows = list(pixel_rows(m, p))
        ra, rb = list(pixel_rows(a, p)), list(pixel_rows(b, p))
        assert np.array_equal(m.values[rows], np.concatenate([a.values[ra], b.values[rb]]))
        assert np.array_equal(m.ids["id"][rows], np.concatenate([a.ids["id"][ra], b.ids["id"][rb]]))
    assert np.array_equal(a.merge(b).values, m.values)
    # flattening the merge is the spec's deep composite of both
    assert_tidy_matches_reference(m)
    with pytest.raises(ValueError):
        merge(a, a.crop((3, -2, 10, 4)))
    with pytest.raises(ValueError):
        merge(a, a.select(["R", "G", "B", "A", "Z", "ZBack"]))
    with pytest.raises(ValueError):
        merge(a, DeepImage(a.values, a.offsets, a.channels, ids={}, data_window=a.data_window))


def test_gather_bins_builds_layouts():
    img = make_messy(5, CH_NO_ZBACK)
    rev = np.concatenate([np.arange(img.offsets[p + 1] - 1, img.offsets[p] - 1, -1) for p in range(img.num_pixels)])
    g = gather_bins(img, rev, img.offsets)
    assert np.array_equal(g.values, img.values[rev]) and np.array_equal(g.ids["id"], img.ids["id"][rev])
    assert np.array_equal(flatten(g), flatten(img))  # tidy sorts, so bin order in the file does not matter


def test_chunked_work_matches_one_chunk(monkeypatch):
    """tidy/flatten run over chunks of whole pixels; tiny chunks (and a pixel larger than a chunk) must give
    bit-identical results to one chunk."""
    import ranad_core.deep as deep

    for channels in (CH_LAYERS, CH_NO_ZBACK):
        img = make_messy(6, channels)
        t1, f1, g1 = img.tidy(), flatten(img), flatten(img, tidy=False)
        monkeypatch.setattr(deep, "_CHUNK_BINS", 5)
        monkeypatch.setattr(deep, "_CHUNK_PIXELS", 3)
        assert len(list(deep.pixel_chunks(img.offsets))) > 20
        t2, f2, g2 = img.tidy(), flatten(img), flatten(img, tidy=False)
        monkeypatch.undo()
        assert np.array_equal(t1.offsets, t2.offsets) and np.array_equal(t1.values, t2.values)
        assert all(np.array_equal(t1.ids[k], t2.ids[k]) for k in t1.ids)
        assert np.array_equal(f1, f2) and np.array_equal(g1, g2)


@pytest.mark.parametrize("z, zb, expected", [
    ([1, 2, 3], [1, 2, 3], "tidy"),
    ([1, 2, 2], [1, 2, 2], "sorted"),            # coincident points
    ([1, 2, 3], [2.5, 2.5, 3], "sorted"),        # volume [1, 2.5] overlaps the next sample
    ([3, 1, 2], [3, 1, 2], "non_overlapping"),   # disjoint points out of order
    ([3, 1, 2], [3, 2.5, 2.5], "messy"),
])
def test_measured_state(z, zb, expected):
    # pixel 0 holds the three samples, pixel 1 one sample that must not be compared with pixel 0's last
    values = np.array([[0.5, a, b] for a, b in zip(z, zb)] + [[0.5, 0.0, 0.0]], dtype=np.float32)
    img = DeepImage(values=values, offsets=[0, 3, 4], channels=["A", "Z", "ZBack"], data_window=(0, 0, 1, 0))
    assert img.measured_state() == expected


def test_tidying_refuses_a_quadratic_split_before_making_it(monkeypatch):
    """n volume samples that all overlap split into up to n (2n - 1) pieces: 10000 in one pixel (a 129 KB file)
    took 10 GB and 50 s to flatten. A tidied pixel may hold as many samples as a read one (the per-pixel cap),
    checked before anything is cut; below it the split is as before."""
    from ranad_core.errors import RanadError

    def volumes(n):
        z = np.linspace(1.0, 2.0, n, dtype=np.float32)
        vals = np.column_stack([np.full((n, 3), 0.01), np.full(n, 0.01), z, z + 5.0]).astype(np.float32)
        return DeepImage(vals, [0, n], ["R", "G", "B", "A", "Z", "ZBack"])

    monkeypatch.setenv("RANAD_MAX_SAMPLES_PER_PIXEL", "1000")   # the piece cap: 64000
    with pytest.raises(RanadError, match=r"300 overlapping volume samples are cut into 90000 pieces when "
                                         r"tidied, more than the limit of 64000"):
        flatten(volumes(300))
    assert volumes(150).tidy().num_bins == 299      # 150 * 299 pieces, merged back to one per interval
    monkeypatch.setenv("RANAD_MAX_SAMPLES_PER_PIXEL", "2000")
    assert volumes(300).tidy().num_bins == 599 and np.isfinite(flatten(volumes(300))).all()
