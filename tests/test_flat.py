"""Flat EXR / PNG / JPEG outputs (ranad_core.exr.flat)."""

from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio
import pytest

from ranad_core.errors import RanadError
from ranad_core.exr import flat
from ranad_core.exr.flat import read_flat, srgb_oetf, write_flat


def srgb_ref(x):
    """Independent scalar sRGB OETF for checking."""
    x = min(max(float(x), 0.0), 1.0)
    return 12.92 * x if x <= 0.0031308 else 1.055 * x ** (1 / 2.4) - 0.055


def by_name(pixels, channels):
    return {c: pixels[..., i] for i, c in enumerate(channels)}


# --- EXR ----------------------------------------------------------------------------------------


@pytest.mark.parametrize("dtype", ["half", "float"])
def test_exr_round_trip_offset_windows(tmp_path, dtype):
    rng = np.random.default_rng(1)
    h, w = 5, 7
    pix = (rng.standard_normal((h, w, 5)) * 10).astype(np.float32)
    channels = ["R", "G", "B", "A", "Z"]
    dw = (-3, 12, -3 + w - 1, 12 + h - 1)
    fw = (0, 0, 63, 31)
    path = tmp_path / "out.exr"
    write_flat(path, pix, channels, dw, fw, dtype=dtype, attributes={"ranad:model": "m1", "ranad:spp": 64, "ranad:gain": 1.5})
    got, got_ch, got_dw, got_fw = read_flat(path)
    assert sorted(got_ch) == sorted(channels)
    assert got_dw == dw and got_fw == fw
    assert got.dtype == np.float32 and got.shape == (h, w, 5)
    expected = pix.astype(np.float16).astype(np.float32) if dtype == "half" else pix
    g = by_name(got, got_ch)
    for i, c in enumerate(channels):
        np.testing.assert_array_equal(g[c].view(np.uint32), expected[..., i].view(np.uint32))

    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    inp.close()
    want = oiio.HALF if dtype == "half" else oiio.FLOAT
    assert all(t == want for t in (spec.channelformats or [spec.format] * spec.nchannels))
    assert spec.getattribute("compression") == "zip"
    assert spec.getattribute("ranad:model") == "m1"
    assert spec.getattribute("ranad:spp") == 64
    assert spec.getattribute("ranad:gain") == pytest.approx(1.5)
    assert os.listdir(tmp_path) == ["out.exr"]  # no temporary left behind


def test_exr_per_channel_types_and_default_display_window(tmp_path):
    pix = np.full((2, 3, 2), 1.0001, np.float32)
    path = tmp_path / "z.exr"
    write_flat(path, pix, ["Y", "Z"], (10, 20, 12, 21), dtype=["half", "float"])
    got, ch, dw, fw = read_flat(path)
    assert dw == fw == (10, 20, 12, 21)
    g = by_name(got, ch)
    assert g["Y"][0, 0] == np.float32(np.float16(1.0001))
    assert g["Z"][0, 0] == np.float32(1.0001)


def test_exr_ignores_exposure(tmp_path):
    pix = np.full((2, 2, 1), 0.25, np.float32)
    write_flat(tmp_path / "e.exr", pix, ["Y"], (0, 0, 1, 1), exposure=3.0)
    assert read_flat(tmp_path / "e.exr")[0][0, 0, 0] == 0.25


def test_shape_mismatch_is_a_programming_error(tmp_path):
    with pytest.raises(ValueError):
        write_flat(tmp_path / "x.exr", np.zeros((2, 2, 3), np.float32), ["R", "G", "B"], (0, 0, 2, 1))
    with pytest.raises(ValueError):
        write_flat(tmp_path / "x.exr", np.zeros((2, 2, 3), np.float32), ["R", "G"], (0, 0, 1, 1))
    assert os.listdir(tmp_path) == []


# --- previews -----------------------------------------------------------------------------------


def test_srgb_oetf_matches_reference():
    xs = np.array([-1.0, 0.0, 0.001, 0.0031308, 0.01, 0.18, 0.5, 1.0, 4.0, np.nan], np.float32)
    got = srgb_oetf(xs)
    np.testing.assert_allclose(got[:-1], [srgb_ref(x) for x in xs[:-1]], atol=1e-6)
    assert got[-1] == 0.0


def test_png_rgba_unpremultiplied_and_srgb(tmp_path):
    # Premultiplied input: colour c * alpha.
    h, w = 4, 6
    colour = np.array([0.18, 0.5, 0.9], np.float32)
    alpha = np.linspace(0.0, 1.0, w, dtype=np.float32)[None, :].repeat(h, 0)
    pix = np.concatenate([colour * alpha[..., None], alpha[..., None]], axis=-1)
    path = tmp_path / "p.png"
    write_flat(path, pix, ["R", "G", "B", "A"], (0, 0, w - 1, h - 1))
    got, ch, dw, fw = read_flat(path)
    assert ch == ["R", "G", "B", "A"] and dw == fw == (0, 0, w - 1, h - 1)
    # Alpha stored linearly and not exposed.
    np.testing.assert_allclose(got[..., 3], np.rint(alpha * 255) / 255, atol=1e-6)
    # Where alpha > 0 the stored colour is the sRGB of the unpremultiplied colour.
    for c in range(3):
        want = np.rint(255 * srgb_ref(colour[c])) / 255
        np.testing.assert_allclose(got[:, 1:, c], want, atol=1e-6)
    np.testing.assert_array_equal(got[:, 0, :], 0.0)  # alpha 0: colour 0 (premultiplied 0), alpha 0


def test_jpg_drops_alpha_keeps_premultiplied_colour(tmp_path):
    pix = np.zeros((16, 16, 4), np.float32)
    pix[..., :3] = [0.1, 0.3, 0.6]
    pix[..., 3] = 0.5  # colour is premultiplied: over black it is the colour itself
    for name in ("p.jpg", "p.jpeg"):
        path = tmp_path / name
        write_flat(path, pix, ["R", "G", "B", "A"], (0, 0, 15, 15))
        got, ch, _, _ = read_flat(path)
        assert len(ch) == 3
        for c, v in enumerate([0.1, 0.3, 0.6]):
            assert np.abs(got[..., c] - srgb_ref(v)).max() < 3 / 255


def test_png_exposure(tmp_path):
    pix = np.full((2, 2, 3), 0.05, np.float32)
    write_flat(tmp_path / "x.png", pix, ["R", "G", "B"], (0, 0, 1, 1), exposure=2.0)
    got, ch, _, _ = read_flat(tmp_path / "x.png")
    assert ch == ["R", "G", "B"]
    np.testing.assert_allclose(got, np.rint(255 * srgb_ref(0.2)) / 255, atol=1e-6)
    write_flat(tmp_path / "y.png", pix, ["R", "G", "B"], (0, 0, 1, 1), exposure=-1.0)
    np.testing.assert_allclose(read_flat(tmp_path / "y.png")[0], np.rint(255 * srgb_ref(0.025)) / 255, atol=1e-6)


def test_png_clamps_and_handles_nan(tmp_path):
    pix = np.array([[[5.0, -1.0, np.nan]]], np.float32)
    write_flat(tmp_path / "c.png", pix, ["R", "G", "B"], (0, 0, 0, 0))
    np.testing.assert_array_equal(read_flat(tmp_path / "c.png")[0][0, 0], [1.0, 0.0, 0.0])


@pytest.mark.parametrize("channels", [["Y"], ["R"], ["Z"], ["Y", "A"], ["diffuse.R", "A"]])
def test_png_single_channel_is_grey(tmp_path, channels):
    pix = np.zeros((2, 2, len(channels)), np.float32)
    pix[..., 0] = 0.5
    if "A" in channels:
        pix[..., 0] = 0.25
        pix[..., 1] = 0.5
    write_flat(tmp_path / "g.png", pix, channels, (0, 0, 1, 1))
    got, ch, _, _ = read_flat(tmp_path / "g.png")
    assert len(ch) == (2 if "A" in channels else 1)
    np.testing.assert_allclose(got[..., 0], np.rint(255 * srgb_ref(0.5)) / 255, atol=1e-6)


def test_preview_places_data_window_in_display_window(tmp_path):
    pix = np.ones((2, 3, 4), np.float32)
    # Data window partly outside the display window (x = 8..10 of 0..9, y = -1..0 of 0..4).
    write_flat(tmp_path / "w.png", pix, ["R", "G", "B", "A"], (8, -1, 10, 0), (0, 0, 9, 4))
    got, _, dw, fw = read_flat(tmp_path / "w.png")
    assert got.shape == (5, 10, 4) and dw == fw == (0, 0, 9, 4)
    mask = np.zeros((5, 10), bool)
    mask[0, 8:10] = True
    np.testing.assert_array_equal(got[mask], 1.0)
    np.testing.assert_array_equal(got[~mask], 0.0)


def test_preview_display_window_offset(tmp_path):
    pix = np.full((1, 1, 3), 1.0, np.float32)
    write_flat(tmp_path / "o.jpg", pix, ["R", "G", "B"], (102, 51, 102, 51), (100, 50, 109, 59))
    got, ch, dw, _ = read_flat(tmp_path / "o.jpg")
    assert got.shape == (10, 10, 3)
    assert got[1, 2].min() > 0.8 and got[9, 9].max() < 0.1


# --- errors and atomicity -----------------------------------------------------------------------


@pytest.mark.parametrize("name, ext", [("x.tif", ".tif"), ("x.XYZ", ".xyz"), ("noext", "noext")])
def test_unsupported_extension(tmp_path, name, ext):
    with pytest.raises(RanadError) as e:
        write_flat(tmp_path / name, np.zeros((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
    assert e.value.problem == f"unsupported output format '{ext}' (use .exr, .png, .jpg)"
    assert e.value.path == str(tmp_path / name)
    assert os.listdir(tmp_path) == []


def test_unwritable_targets_leave_nothing(tmp_path):
    (tmp_path / "afile").write_bytes(b"x")
    before = sorted(os.listdir(tmp_path))
    for target in (tmp_path / "missing" / "x.exr", tmp_path / "afile" / "x.png"):
        with pytest.raises(RanadError):
            write_flat(target, np.zeros((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
    with pytest.raises(RanadError):  # a folder where the file should go
        write_flat(tmp_path, np.zeros((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
    assert sorted(os.listdir(tmp_path)) == before


@pytest.mark.skipif(hasattr(os, "geteuid") and os.geteuid() == 0, reason="root can write to read-only folders")
def test_read_only_folder(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        with pytest.raises(RanadError) as e:
            write_flat(ro / "x.exr", np.zeros((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
        assert "not writable" in e.value.problem
        assert os.listdir(ro) == []
    finally:
        ro.chmod(0o755)


def test_oiio_failure_leaves_no_temp(tmp_path):
    # A real OpenImageIO failure: JPEG cannot be wider than 65500 pixels.
    (tmp_path / "keep.txt").write_bytes(b"x")
    with pytest.raises(RanadError) as e:
        write_flat(tmp_path / "big.jpg", np.zeros((1, 70000, 3), np.float32), ["R", "G", "B"], (0, 0, 69999, 0))
    assert "65500" in e.value.problem
    assert os.listdir(tmp_path) == ["keep.txt"]


def test_failure_mid_write_leaves_no_partial_file(tmp_path, monkeypatch):
    real = flat._write_image

    def half_then_fail(tmp, spec, data, path=None):
        real(tmp, spec, data, path)  # a complete-looking file at the temporary name...
        assert os.path.exists(tmp)
        raise RanadError("disk full (simulated)", tmp)  # ...then the job dies before the rename

    monkeypatch.setattr(flat, "_write_image", half_then_fail)
    with pytest.raises(RanadError):
        write_flat(tmp_path / "x.exr", np.zeros((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
    assert os.listdir(tmp_path) == []


def test_overwrite_is_atomic_replace(tmp_path):
    path = tmp_path / "x.exr"
    write_flat(path, np.zeros((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
    write_flat(path, np.ones((1, 1, 1), np.float32), ["Y"], (0, 0, 0, 0))
    assert read_flat(path)[0][0, 0, 0] == 1.0
    assert os.listdir(tmp_path) == ["x.exr"]


def test_read_flat_errors(tmp_path):
    with pytest.raises(RanadError) as e:
        read_flat(tmp_path / "nope.exr")
    assert e.value.problem == "no such file"
    (tmp_path / "junk.exr").write_bytes(b"not an image at all")
    with pytest.raises(RanadError) as e:
        read_flat(tmp_path / "junk.exr")
    assert e.value.path == str(tmp_path / "junk.exr")


def test_read_flat_refuses_deep(tmp_path):
    spec = oiio.ImageSpec(2, 2, 2, oiio.FLOAT)
    spec.channelnames = ("A", "Z")
    spec.deep = True
    deep = oiio.DeepData()
    deep.init(spec)
    path = str(tmp_path / "deep.exr")
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_deep_image(deep)
    out.close()
    with pytest.raises(RanadError) as e:
        read_flat(path)
    assert "deep" in e.value.problem
