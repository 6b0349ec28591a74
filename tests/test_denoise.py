"""`ranad denoise`: tiles equal the whole frame, the file's layout survives, reduced modes run, bad input fails
cleanly with nothing written, shards cover a shot once, the AOV cache is written and refused when stale."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core import cache as cache_io
from ranad_core.channels import detect, parse_overrides
from ranad_core.denoise import denoise_frame, halo_for, receptive_field
from ranad_core.errors import RanadError
from ranad_core.exr import read_deep, write_deep
from ranad_core.model import RaNAD, ReconConfig, feature_dim
from ranad_core.model.config import ModelConfig

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
FRAME = SHOT / "noisy_spp16.0001.exr"


def tiny_model(radius=1.5, growth=0.5, heads=4, seed=0, name="tiny"):
    """A small untrained model (by default receptive field 13 px, halo 16, so tiling a 48x48 frame is a real
    test); wider radii give a wider receptive field."""
    torch.manual_seed(seed)
    rc = ReconConfig(scales=2, heads=2, head_dim=8, radius=radius, radius_growth=growth)
    cfg = ModelConfig(name, dim=16, unets=1, levels=1, blocks_per_level=1, heads=heads, head_dim=8, radius=radius,
                      radius_growth=growth, recon={"diffuse": rc, "specular": rc, "alpha": rc, "depth": rc})
    return RaNAD(cfg, feature_dim()).eval()


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    """The tiny model as a .safetensors file the CLI can load."""
    from safetensors.torch import save_file
    import json

    m = tiny_model()
    path = tmp_path_factory.mktemp("model") / "tiny.safetensors"
    save_file({k: v.contiguous() for k, v in m.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(m.config.to_dict())})
    return str(path)


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def test_tiles_equal_the_whole_frame():
    model = tiny_model()
    assert receptive_field(model) == 13 and halo_for(model) == 16
    img = read_deep(FRAME)
    whole = denoise_frame(model, img)
    tiled = denoise_frame(model, img, tile=16)
    assert whole.tiles == 1 and tiled.tiles == 9
    np.testing.assert_allclose(tiled.image.values, whole.image.values, rtol=1e-5, atol=1e-6)
    cut = denoise_frame(model, img, tile=16, halo=0)       # without a halo the seams differ: the test can fail
    assert np.abs(cut.image.values - whole.image.values).max() > 1e-3


def test_tiles_of_a_lattice_dropout_model_equal_the_whole_frame():
    """A model whose U-Net has two levels and whose reconstructions three scales on the lattice bin dropout (the
    parity of levels 2-3 depends on pixel coordinates modulo 2-4): tiles with any halo at least its receptive
    field equal the whole frame, because windows start at multiples of ALIGN (the halo is rounded up to it), where
    the lattices keep their phase."""
    torch.manual_seed(0)
    rc = ReconConfig(scales=3, heads=2, head_dim=8, radius=1.0, radius_growth=0.5)
    cfg = ModelConfig("tiny-lattice", dim=16, unets=1, levels=2, blocks_per_level=1, heads=2, head_dim=8,
                      radius=1.0, radius_growth=0.5, recon={"diffuse": rc, "specular": rc, "alpha": rc, "depth": rc},
                      dropout_lattice=True)
    model = RaNAD(cfg, feature_dim()).eval()
    from deep_factory import random_deep

    img = random_deep(80, 80, max_bins=2, seed=3)    # windows of inner tiles start inside the frame
    whole = denoise_frame(model, img)
    rf = receptive_field(model)
    assert rf < 32
    for halo in (rf, rf + 1, rf + 3):
        tiled = denoise_frame(model, img, tile=16, halo=halo)
        assert tiled.tiles == 25
        np.testing.assert_allclose(tiled.image.values, whole.image.values, rtol=1e-4, atol=1e-5)   # sum order


def test_output_keeps_layout_ids_header_and_channels(tmp_path, model_file):
    out = tmp_path / "den.exr"
    r = run("denoise", FRAME, "-o", out, "--model", model_file, "--keep-noisy", "noisy.")
    assert r.exit_code == 0, r.output
    a, b = read_deep(FRAME), read_deep(out)
    np.testing.assert_array_equal(a.offsets, b.offsets)
    np.testing.assert_array_equal(a.ids["id"], b.ids["id"])
    assert set(a.channels) <= set(b.channels) and b.header.keys() == a.header.keys()
    kept = [c for c in b.channels if c.startswith("noisy.")]
    assert {"noisy.R", "noisy.A", "noisy.Z", "noisy.diffuse.R", "noisy.specular.B"} <= set(kept)
    np.testing.assert_array_equal(b.channel("noisy.R"), a.channel("R"))
    assert not np.array_equal(b.channel("R"), a.channel("R"))
    untouched = [c for c in a.channels if c.split(".")[0] in ("albedo", "N", "emission", "lg_key", "motion_next")]
    for c in untouched:
        np.testing.assert_array_equal(b.channel(c), a.channel(c))
    assert not list(tmp_path.glob("*.tmp*")) and sorted(p.name for p in tmp_path.iterdir()) == ["den.exr"]


def test_reduced_modes(tmp_path, model_file):
    img = read_deep(FRAME)
    beauty_only = img.select(["R", "G", "B", "A", "Z"])
    assert detect(beauty_only).mode() == "no split (beauty through the diffuse kernels), without guides"
    path = tmp_path / "rgbaz.exr"
    write_deep(path, beauty_only)
    r = run("denoise", path, "-o", tmp_path / "out.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    out = read_deep(tmp_path / "out.exr")
    assert out.channels == beauty_only.channels and np.isfinite(out.values).all()
    assert 0 <= out.channel("A").min() and out.channel("A").max() <= 1
    assert not np.array_equal(out.channel("G"), beauty_only.channel("G"))
    # a renamed split found through --map
    ren = img.select([c for c in img.channels if not c.startswith(("diffuse.", "specular."))])
    vals = np.concatenate([ren.values, img.select([f"diffuse.{c}" for c in "RGB"]).values], 1)
    renamed = ren.with_values(vals, ren.channels + ["kd.R", "kd.G", "kd.B"])
    assert detect(renamed, parse_overrides(["diffuse=kd"])).layers["diffuse"] == ("kd.R", "kd.G", "kd.B")
    with pytest.raises(RanadError, match="no such channels"):
        detect(renamed, parse_overrides(["diffuse=nothing"]))


def copy_shot(dst: Path, frames=(0, 1, 2)) -> str:
    dst.mkdir(parents=True, exist_ok=True)
    for f in frames:
        shutil.copy(SHOT / f"noisy_spp16.{f:04d}.exr", dst / f"beauty.{f:04d}.exr")
    return str(dst / "beauty.####.exr")


def test_bad_inputs_fail_with_one_line_and_write_nothing(tmp_path, model_file):
    out = tmp_path / "out"
    out.mkdir()
    # mismatched resolution (display window) inside a sequence; data windows may differ (tests/test_windows.py)
    pattern = copy_shot(tmp_path / "a")
    img = read_deep(FRAME)
    small = img.crop((0, 0, 31, 31))
    small.display_window = (0, 0, 31, 31)
    write_deep(tmp_path / "a" / "beauty.0002.exr", small)
    r = run("denoise", pattern, "-o", out / "d.####.exr", "--model", model_file)
    assert r.exit_code == 2 and "differs from" in r.output and "beauty.0002.exr" in r.output
    assert r.output.count("\n") == 1 and not list(out.iterdir())
    # a missing frame of a range
    pattern = copy_shot(tmp_path / "b", (0, 2))
    r = run("denoise", pattern, "--frames", "0-2", "-o", out / "d.####.exr", "--model", model_file)
    assert r.exit_code == 2 and "frame 1 is missing" in r.output and not list(out.iterdir())
    # a missing required channel
    write_deep(tmp_path / "noz.exr", img.select(["R", "G", "B", "A"]))
    r = run("denoise", tmp_path / "noz.exr", "-o", out / "x.exr", "--model", model_file)
    assert r.exit_code == 2 and "missing required channel(s) Z" in r.output and not list(out.iterdir())
    # ... or stored as UINT (an id channel's type): said so, not "missing"
    noa = img.select([c for c in img.channels if c != "A"])
    noa.ids["A"] = np.ones(noa.num_bins, np.uint32)
    noa.channel_types["A"] = "uint"
    write_deep(tmp_path / "uinta.exr", noa)
    r = run("denoise", tmp_path / "uinta.exr", "-o", out / "x.exr", "--model", model_file)
    assert r.exit_code == 2 and "channel(s) A stored as UINT" in r.output and not list(out.iterdir())
    # NaN/Inf samples: refused with --strict, replaced (and reported) otherwise
    vals = img.values.copy()
    vals[5, img.channels.index("diffuse.R")] = np.nan
    vals[9, img.channels.index("Z")] = np.inf
    write_deep(tmp_path / "nan.exr", img.with_values(vals))
    r = run("denoise", tmp_path / "nan.exr", "-o", out / "x.exr", "--model", model_file, "--strict")
    assert r.exit_code == 2 and "2 bin(s) with NaN/Inf" in r.output and not list(out.iterdir())
    r = run("denoise", tmp_path / "nan.exr", "-o", out / "x.exr", "--model", model_file)
    assert r.exit_code == 0 and "warning" in r.output
    res = read_deep(out / "x.exr")
    replaced = [res.channels.index(c) for c in ("R", "G", "B", "A", "Z", "diffuse.R", "specular.R")]
    assert np.isfinite(res.values[:, replaced]).all()
    # an unwritable output
    (tmp_path / "afile").write_text("")
    r = run("denoise", FRAME, "-o", tmp_path / "afile" / "x.exr", "--model", model_file)
    assert r.exit_code == 2 and "cannot create the output folder" in r.output
    r = run("denoise", FRAME, "-o", tmp_path / "new" / "folder" / "x.exr", "--model", model_file)
    assert r.exit_code == 0 and (tmp_path / "new" / "folder" / "x.exr").is_file()
    # not a deep file
    (tmp_path / "junk.exr").write_bytes(b"junk")
    r = run("denoise", tmp_path / "junk.exr", "-o", out / "j.exr", "--model", model_file)
    assert r.exit_code == 2 and "junk.exr" in r.output and not (out / "j.exr").exists()


def test_shards_cover_the_shot_once_and_skip_existing_resumes(tmp_path, model_file):
    pattern = copy_shot(tmp_path / "shot")
    out = tmp_path / "out"
    out.mkdir()
    for i in (1, 2):
        r = run("denoise", pattern, "-o", out / "d.####.exr", "--model", model_file, "--shard", f"{i}/2")
        assert r.exit_code == 0, r.output
        assert f"denoised {2 if i == 1 else 1} frame(s)" in r.output
    assert sorted(p.name for p in out.iterdir()) == ["d.0000.exr", "d.0001.exr", "d.0002.exr"]
    os.remove(out / "d.0001.exr")
    r = run("denoise", pattern, "-o", out / "d.####.exr", "--model", model_file, "--skip-existing")
    assert r.exit_code == 0 and "denoised 1 frame(s)" in r.output and "skipped 2 existing" in r.output
    r = run("denoise", pattern, "-o", out / "d.####.exr", "--model", model_file, "--shard", "3/2")
    assert r.exit_code == 2 and "shard" in r.output
    # an empty output (somebody else's: ranad renames whole files into place) is not a done frame; with --cache a
    # frame is done only with its cache too (ranad aov found none for frames a resumed run had skipped)
    (out / "d.0002.exr").write_bytes(b"")
    r = run("denoise", pattern, "-o", out / "d.####.exr", "--model", model_file, "--skip-existing", "--cache",
            tmp_path / "c")
    assert r.exit_code == 0 and "denoised 3 frame(s)" in r.output, r.output
    assert len(list((tmp_path / "c").glob("*.ranadcache"))) == 3 and (out / "d.0002.exr").stat().st_size > 0
    os.remove(tmp_path / "c" / "d.0000.ranadcache")
    r = run("denoise", pattern, "-o", out / "d.####.exr", "--model", model_file, "--skip-existing", "--cache",
            tmp_path / "c")
    assert r.exit_code == 0 and "denoised 1 frame(s)" in r.output and "skipped 2 existing" in r.output


def test_cache_is_written_and_refused_when_stale(tmp_path, model_file):
    out, cache = tmp_path / "d.exr", tmp_path / "cache"
    r = run("denoise", FRAME, "-o", out, "--model", model_file, "--cache", cache)
    assert r.exit_code == 0, r.output
    path = cache_io.cache_path(str(cache), str(out))
    tensors, meta = cache_io.read_cache(path)
    img = read_deep(FRAME)
    assert tensors["embeddings.0"].shape == (img.num_bins, 16) and tensors["embeddings.0"].dtype == np.float16
    np.testing.assert_array_equal(tensors["offsets.0"], img.offsets)
    assert meta["centre"] == "0" and "embeddings.1" not in tensors
    assert meta["input"] == os.path.abspath(FRAME) and meta["model_id"].startswith("tiny@")
    cache_io.check_cache(meta, path, meta["model_id"], img)
    with pytest.raises(RanadError, match="made with model"):
        cache_io.check_cache(meta, path, "other@123", img)
    with pytest.raises(RanadError, match="bin layout"):
        cache_io.check_cache(meta, path, None, read_deep(SHOT / "noisy_spp16.0002.exr"))
    (tmp_path / "bad.ranadcache").write_bytes(b"x" * 20)
    with pytest.raises(RanadError, match="not a ranad cache"):
        cache_io.read_cache(str(tmp_path / "bad.ranadcache"))


def _haloed_bins_by_hand(counts: np.ndarray, tile: int, halo: int) -> list:
    """Bins of each haloed window, counted from the per-pixel counts with plain slicing (no integral image)."""
    from ranad_core.denoise import tile_windows

    h, w = counts.shape
    return [int(counts[y0:y1 + 1, x0:x1 + 1].sum()) for _, (x0, y0, x1, y1) in tile_windows(w, h, tile, halo)]


def _halving_tile(counts: np.ndarray, halo: int, limit: int) -> int:
    """The tile choice before the cost model: halve from the frame's size until the fullest window fits."""
    from ranad_core.denoise import ALIGN

    tile = ALIGN * max(1, -(-max(counts.shape) // ALIGN))
    while tile > ALIGN and max(_haloed_bins_by_hand(counts, tile, halo)) > limit:
        tile = max(ALIGN, (tile // 2) // ALIGN * ALIGN)
    return tile


@pytest.mark.parametrize("shape,limit_px", [((1080, 1920), 1.2e6), ((1080, 1920), 1.8e6), ((270, 480), 5e4),
                                            ((200, 100), 1e6), ((77, 301), 9e3)])
def test_tile_choice_fits_the_budget_and_computes_the_fewest_bins(shape, limit_px):
    """choose_tile: every haloed window fits the budget, no more bins are computed than with the halving choice it
    replaced (1080p: 960 px tiles leave a 120-row sliver that pays a whole halo), and a frame that fits whole is
    one tile. Bin counts vary across the frame (1-3 per pixel), and windows are counted here by hand."""
    from ranad_core.denoise import BYTES_PER_BIN, choose_tile

    rng = np.random.default_rng(shape[0])
    counts = rng.integers(1, 4, size=shape)
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    halo = 16
    limit = int(limit_px * 2)   # about 2 bins per pixel
    tile = choose_tile(offsets, shape[1], shape[0], halo, limit * BYTES_PER_BIN)
    chosen = _haloed_bins_by_hand(counts, tile, halo)
    capped = _haloed_bins_by_hand(counts, choose_tile(offsets, shape[1], shape[0], halo, limit * BYTES_PER_BIN,
                                                      max_bins=limit // 3), halo)
    assert max(capped) <= limit // 3 or len(capped) == (-(-shape[0] // 16)) * (-(-shape[1] // 16))
    assert max(chosen) <= limit
    old = _halving_tile(counts, halo, limit)
    assert sum(chosen) <= sum(_haloed_bins_by_hand(counts, old, halo))
    if counts.sum() <= limit:
        assert len(chosen) == 1
    if shape == (1080, 1920) and limit_px == 1.2e6:
        assert old == 960 and sum(chosen) < 0.98 * sum(_haloed_bins_by_hand(counts, old, halo))


def test_write_columns_is_the_column_by_column_write():
    """The assembly's column writer equals numpy writes one column at a time in order, a channel named twice
    keeping its last column (a grey layer mapped as Y,Y,Y), 1-D data as one column, other channels untouched."""
    from ranad_core.denoise import write_columns

    rng = np.random.default_rng(3)
    chans = ["R", "G", "B", "A", "Z", "spec.Y"]
    base = rng.normal(size=(257, len(chans))).astype(np.float32)
    for names in (["R", "G", "B"], ["spec.Y", "spec.Y", "spec.Y"], ["Z", "R", "Z"], ["A"]):
        data = rng.normal(size=(257, len(names)))   # float64: written as float32, as numpy's assignment casts
        got, want = base.copy(), base.copy()
        write_columns(got, chans, names, data)
        for i, name in enumerate(names):
            want[:, chans.index(name)] = data[:, i]
        np.testing.assert_array_equal(got, want)
    got, want = base.copy(), base.copy()
    one = rng.normal(size=257).astype(np.float32)
    write_columns(got, chans, ["A"], one)
    want[:, 3] = one
    np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("kept_gb,worth_it", [(0.0, False), (0.3, False), (2.5, True)])
def test_kept_memory_goes_back_before_sizing_only_when_the_tiles_would_pay_for_it(monkeypatch, kept_gb, worth_it):
    """shot.choose_frame_tile sizes a frame's tiles with the heap's kept memory counted as in use; it gives that
    memory back (to be faulted in again) and sizes again only when the tiles it allowed would compute more than
    memory.GIVE_BACK_WORTH times the work the give-back would allow. The process's memory is stood in for: 0.2 GB
    in use plus kept_gb kept, a 3 GB ceiling, nothing else counted; the tile used is checked against the choice
    made by hand from the budget each case leaves."""
    from ranad_core import heap, memory, shot
    from ranad_core.deep import DeepImage
    from ranad_core.denoise import choose_tile, tile_bytes, tiling_work

    rng = np.random.default_rng(3)
    counts = rng.integers(1, 4, size=(1080, 1920))
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    img = DeepImage(values=np.zeros((int(offsets[-1]), 1), np.float32), offsets=offsets, channels=["R"],
                    data_window=(0, 0, 1919, 1079))
    gb, in_use, kept = 2**30, 0.2 * 2**30, kept_gb * 2**30
    gave_back = []

    def resident(give_back=True):
        if give_back:
            gave_back.append(True)
        return in_use if give_back or gave_back else in_use + kept

    monkeypatch.setattr(memory, "resident_bytes", resident)
    monkeypatch.setattr(heap, "kept_bytes", lambda: kept)
    monkeypatch.setattr(memory, "frame_working_bytes", lambda images, centre: 0.0)
    monkeypatch.setattr(memory, "kernel_cache_bytes", lambda: 0.0)
    ceiling, halo = 3 * gb, 16
    tile = shot.choose_frame_tile([img], 0, halo, ceiling, "f.exr")

    def by_hand(resident_bytes):
        return choose_tile(offsets, 1920, 1080, halo, ceiling * (1 - memory.MARGIN) - resident_bytes)

    kept_tile, given_tile = by_hand(in_use + kept), by_hand(in_use)
    work = lambda t: tiling_work(offsets, 1920, 1080, t, halo)  # noqa: E731
    assert (work(kept_tile) > memory.GIVE_BACK_WORTH * work(given_tile)) == worth_it   # the cases are what they say
    assert bool(gave_back) == worth_it
    assert tile == (given_tile if worth_it else kept_tile)
    counted = in_use if worth_it else in_use + kept
    assert tile_bytes(offsets, 1920, 1080, tile, halo) <= ceiling * (1 - memory.MARGIN) - counted


def test_kept_bytes_counts_what_the_heap_keeps():
    """heap.kept_bytes (mallinfo2) sees freed memory the heap keeps under the policy; None without the policy."""
    import subprocess
    import sys

    code = ("import numpy as np; from ranad_core import heap; print(heap.kept_bytes()); heap.keep_freed_memory(); "
            "k0 = heap.kept_bytes(); a = np.ones(64 << 20, np.uint8); del a; print(k0, heap.kept_bytes())")
    if not sys.platform.startswith("linux"):
        pytest.skip("glibc's allocator: Linux only")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    if out[1] == "None":
        pytest.skip("the C library is not glibc 2.33 or later: no mallinfo2")
    assert out[0] == "None"
    assert int(out[2]) - int(out[1]) >= 60 << 20
