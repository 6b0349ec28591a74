"""`ranad denoise` options through the command line (click's CliRunner), each checked by what it must change:
the README's shot with the shipped cross-frame default and --reference, --threads, --max-memory, --tile,
--halo, --kind, --device and --map."""

from __future__ import annotations

import json
import os
import re
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from deep_factory import openexr_deep_channel
from ranad_cli.main import cli
from ranad_core import cache as cache_io
from ranad_core import denoise as denoise_mod
from ranad_core import shot as shot_mod
from ranad_core.exr import read_deep, write_deep
from test_denoise import tiny_model

SHOT = Path(__file__).resolve().parents[1] / "examples" / "synth_shot"
FRAME = SHOT / "noisy_spp16.0001.exr"


def run(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


@pytest.fixture(scope="module")
def model_file(tmp_path_factory):
    """A tiny untrained single-frame model (receptive field 13 px, halo 16) as a .safetensors file."""
    from safetensors.torch import save_file

    m = tiny_model()
    path = tmp_path_factory.mktemp("model") / "tiny.safetensors"
    save_file({k: v.contiguous() for k, v in m.state_dict().items()}, str(path),
              metadata={"model_config": json.dumps(m.config.to_dict())})
    return str(path)


@pytest.fixture
def keep_torch_threads():
    n = torch.get_num_threads()
    yield
    torch.set_num_threads(n)


def smape(ref, test, eps=1e-2):
    """The README's figure, written out here: mean |test - ref| / (|test| + |ref| + eps)."""
    ref, test = np.asarray(ref, np.float64), np.asarray(test, np.float64)
    return float(np.mean(np.abs(test - ref) / (np.abs(test) + np.abs(ref) + eps)))


def flat_rgb(img):
    """The composited beauty (R, G, B over A, bins in depth order)."""
    names = [c for c in ("R", "G", "B", "A", "Z", "ZBack") if c in img.channels]
    b = img.with_values(img.values[:, [img.channels.index(c) for c in names]], names)
    b.ids = {}
    return b.flatten()[..., :3]


def test_readme_shot_with_the_shipped_cross_frame_default_and_reference(tmp_path):
    """The README's main job: a 3-frame shot without --model picks the shipped cross-frame default
    (DEFAULT_CROSS_MODEL), denoises each frame with its
    neighbours, and --reference reports the centre frame's SMAPE before and after, which the written files
    confirm (and which must improve)."""
    out = tmp_path / "denoised" / "beauty.####.exr"
    r = run("denoise", SHOT / "noisy_spp16.####.exr", "-o", out, "--reference", SHOT / "reference_spp16.####.exr",
            "--cache", tmp_path / "cache")
    assert r.exit_code == 0, r.output
    from ranad_core.model.store import DEFAULT_CROSS_MODEL

    assert re.search(rf"model {re.escape(DEFAULT_CROSS_MODEL)}@[0-9a-f]+;", r.output), r.output
    assert "denoised 3 frame(s)" in r.output
    written = sorted(p.name for p in (tmp_path / "denoised").iterdir())
    assert written == ["beauty.0000.exr", "beauty.0001.exr", "beauty.0002.exr"]
    # frame 1 was denoised with both neighbours (the model's window, 3 or more frames)
    _, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "cache"),
                                                      str(tmp_path / "denoised" / "beauty.0001.exr")))
    assert [Path(p).name for p in json.loads(meta["window"])] == [f"noisy_spp16.000{f}.exr" for f in (0, 1, 2)]
    # only frame 1 has a reference: one report line, whose numbers the files reproduce
    reports = re.findall(r"(\S+): flattened SMAPE vs reference ([\d.]+) -> ([\d.]+)", r.output)
    assert [name for name, _, _ in reports] == ["noisy_spp16.0001.exr"], r.output
    before, after = float(reports[0][1]), float(reports[0][2])
    noisy, ref = read_deep(FRAME), read_deep(SHOT / "reference_spp16.0001.exr")
    den = read_deep(tmp_path / "denoised" / "beauty.0001.exr")
    np.testing.assert_array_equal(den.offsets, noisy.offsets)
    assert smape(flat_rgb(ref), flat_rgb(noisy)) == pytest.approx(before, abs=1e-4)
    # the file is stored in half precision, the report was made before writing
    assert smape(flat_rgb(ref), flat_rgb(den)) == pytest.approx(after, abs=2e-4)
    assert after < 0.6 * before, (before, after)


def spy_on_windows(monkeypatch, probe) -> list:
    """Records probe() as each window of a shot starts denoising (shot.py's denoise_window, which still runs)."""
    seen = []
    real = shot_mod.denoise_window

    def spy(*a, **k):
        seen.append(probe())
        return real(*a, **k)

    monkeypatch.setattr(shot_mod, "denoise_window", spy)
    return seen


def test_threads_sets_torchs_threads_for_the_run(tmp_path, model_file, keep_torch_threads, monkeypatch):
    seen = spy_on_windows(monkeypatch, torch.get_num_threads)
    for n in (1, 2):
        r = run("denoise", FRAME, "-o", tmp_path / f"t{n}.exr", "--model", model_file, "--threads", n)
        assert r.exit_code == 0, r.output
    assert seen == [1, 2]
    np.testing.assert_array_equal(read_deep(tmp_path / "t1.exr").values, read_deep(tmp_path / "t2.exr").values)
    r = run("denoise", FRAME, "-o", tmp_path / "t0.exr", "--model", model_file, "--threads", 0)
    assert r.exit_code == 2 and "--threads" in r.output and not (tmp_path / "t0.exr").exists()


def test_the_cycle_collector_skips_what_was_loaded_and_thaws_afterwards(tmp_path, model_file, monkeypatch):
    """The denoise freezes the objects alive once the model is loaded (so the collector's passes during the tiles
    skip them) and thaws them when the command ends, so a caller in the same process (this one) collects as
    before."""
    import gc

    seen = spy_on_windows(monkeypatch, gc.get_freeze_count)
    assert gc.get_freeze_count() == 0
    r = run("denoise", FRAME, "-o", tmp_path / "g.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    assert len(seen) == 1 and seen[0] > 10_000   # torch alone is tens of thousands of objects
    assert gc.get_freeze_count() == 0


def test_every_frame_is_read_once(tmp_path, model_file, monkeypatch):
    """The first frame, read before the shot for its channel map and kind, is the frame the shot denoises: it is
    not read a second time (a whole read, 0.8 s of a 1080p frame), and the output is what a fresh read gives."""
    reads = []
    real = shot_mod.read_deep

    def spy(path, *a, **k):
        reads.append(os.path.basename(str(path)))
        return real(path, *a, **k)

    monkeypatch.setattr(shot_mod, "read_deep", spy)
    r = run("denoise", SHOT / "noisy_spp16.####.exr", "-o", tmp_path / "s.####.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    assert sorted(reads) == [f"noisy_spp16.000{i}.exr" for i in range(3)]
    reads.clear()
    r = run("denoise", FRAME, "-o", tmp_path / "one.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    assert reads == [FRAME.name]
    np.testing.assert_array_equal(read_deep(tmp_path / "one.exr").values, read_deep(tmp_path / "s.0001.exr").values)


def spy_on_tile_choice(monkeypatch) -> list:
    """Records (budget, tile) of every tile choice shot.py makes (the real choice still decides)."""
    calls = []
    real = shot_mod.choose_tile

    def spy(offsets, width, height, halo, budget, frames=1, max_bins=None):
        calls.append((budget, real(offsets, width, height, halo, budget, frames, max_bins)))
        return calls[-1][1]

    monkeypatch.setattr(shot_mod, "choose_tile", spy)
    return calls


def test_max_memory_is_the_tile_budget(tmp_path, model_file, monkeypatch):
    """--max-memory reaches the tile choice as bytes, less what the process holds and the frame's working copies
    and the kernels' buffers need (so a larger ceiling gives the tiles exactly that much more), and the tile chosen
    is the one used (recorded in the cache); a ceiling too small for one tile is an error."""
    from ranad_core import memory

    calls = spy_on_tile_choice(monkeypatch)
    monkeypatch.setenv(memory.KERNEL_CACHE_ENV, "256")
    img = read_deep(FRAME)
    working = memory.frame_working_bytes([img], 0)
    budgets = {}
    for text, size in (("2.5G", 2.5 * 2**30), ("3G", 3 * 2**30), ("1536MiB", 1536 * 2**20)):  # 1st: warm-up
        r = run("denoise", FRAME, "-o", tmp_path / "m.exr", "--model", model_file, "--max-memory", text,
                "--cache", tmp_path / "c")
        assert r.exit_code == 0, r.output
        budgets[size] = calls[-1][0]
        assert calls[-1][0] < size * (1 - memory.MARGIN) - working - 256 * 2**20 - memory.resident_bytes() / 2
        _, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c"), str(tmp_path / "m.exr")))
        assert int(meta["tile"]) == calls[-1][1]
    # the process's resident set moves a little between runs; the ceiling's share moves the budget one for one
    assert budgets[3 * 2**30] - budgets[1536 * 2**20] == pytest.approx(1.5 * 2**30 * (1 - memory.MARGIN), abs=100e6)
    r = run("denoise", FRAME, "-o", tmp_path / "bad.exr", "--model", model_file, "--max-memory", "lots")
    assert r.exit_code == 2 and "--max-memory" in r.output and not (tmp_path / "bad.exr").exists()
    r = run("denoise", FRAME, "-o", tmp_path / "small.exr", "--model", model_file, "--max-memory", "300M")
    assert r.exit_code == 2 and not (tmp_path / "small.exr").exists()
    line = r.output.strip().splitlines()[-1]
    assert "--max-memory 300 MB is too small for this frame" in line and "use at least --max-memory" in line
    need = float(line.rsplit("--max-memory ", 1)[1].split()[0]) * (2**30 if line.endswith("GB") else 2**20)
    r = run("denoise", FRAME, "-o", tmp_path / "enough.exr", "--model", model_file, "--max-memory",
            f"{int(need / 2**20) + 64}M")   # the size the error names is enough (a little for RSS jitter)
    assert r.exit_code == 0, r.output


def test_max_memory_covers_the_flat_prior(tmp_path, monkeypatch):
    """A model on the flat prior: making the frame's inputs and prior (OIDN's buffers) has to fit the ceiling too.
    Its peak (memory.prior_peak_bytes, about 1 KB per pixel, small for this frame) is stood in for: above the
    ceiling, a one-line error naming the prior and a size, no output; with that size the frame is denoised."""
    from ranad_core import memory

    monkeypatch.setattr(memory, "prior_peak_bytes", lambda images, centre: 3 * 2**30)
    r = run("denoise", FRAME, "-o", tmp_path / "p.exr", "--model", "cpu-small-pd-v4", "--max-memory", "3G")
    assert r.exit_code == 2 and not (tmp_path / "p.exr").exists()
    line = r.output.strip().splitlines()[-1]
    assert "--max-memory 3.00 GB is too small for this frame" in line and "flat prior" in line
    need = float(line.rsplit("--max-memory ", 1)[1].split()[0]) * (2**30 if line.endswith("GB") else 2**20)
    assert need > 3 * 2**30
    r = run("denoise", FRAME, "-o", tmp_path / "p.exr", "--model", "cpu-small-pd-v4", "--max-memory",
            f"{int(need / 2**20) + 64}M")
    assert r.exit_code == 0, r.output


def test_a_cross_frame_window_counts_only_the_flat_priors_it_still_makes(tmp_path, monkeypatch):
    """A cross-frame model on the flat prior makes each frame's prior once per shot and carries it to the later
    windows (denoise_window), so a window's memory check counts the prior's peak (memory.prior_peak_bytes) of the
    frames whose prior is still to be made only: window (0, 1) both, (0, 1, 2) frame 2's, (1, 2) none. Before, every
    window counted all of its frames again, and a 3-frame 1080p shot at --max-memory 4G was refused at frame 1 for
    priors it already held. The bundled 3-frame shot with the shipped cross-frame default."""
    from ranad_core import memory
    from ranad_core.model.store import DEFAULT_CROSS_MODEL

    asked = []
    real = memory.prior_peak_bytes

    def spy(images, centre):
        asked.append(tuple(im.num_bins for im in images))
        return real(images, centre)

    monkeypatch.setattr(memory, "prior_peak_bytes", spy)
    r = run("denoise", SHOT / "noisy_spp16.####.exr", "-o", tmp_path / "d.####.exr", "--model", DEFAULT_CROSS_MODEL)
    assert r.exit_code == 0, r.output
    bins = [read_deep(SHOT / f"noisy_spp16.{n:04d}.exr").num_bins for n in range(3)]
    assert len(set(bins)) == 3   # the frames tell apart by their bins
    windows = [a for i, a in enumerate(asked) if i == 0 or a != asked[i - 1]]   # a window may size its tiles twice
    assert windows == [(bins[0], bins[1]), (bins[2],)]


def test_gpu_free_memory_bounds_the_tiles(tmp_path, model_file, monkeypatch):
    """A model on a GPU gets tiles sized to the GPU's free memory as well as to --max-memory: the smaller budget
    reaches the tile choice, and a GPU too full for one minimal tile is a one-line error with no output. The GPU's
    free memory is stood in for here (memory.device_free_bytes reads the driver; the CPU is unbounded)."""
    from ranad_core import memory

    assert memory.device_free_bytes("cpu") == float("inf")
    calls = spy_on_tile_choice(monkeypatch)
    img = read_deep(FRAME)
    need = denoise_mod.tile_bytes(img.offsets, img.width, img.height, denoise_mod.ALIGN, 0)
    used = []   # the last choice of each run is the tile used (shot.choose_frame_tile may size a frame twice)
    for free in (float("inf"), 2 * need):
        monkeypatch.setattr(memory, "device_free_bytes", lambda device, free=free: free)
        r = run("denoise", FRAME, "-o", tmp_path / "m.exr", "--model", model_file, "--halo", "0")
        assert r.exit_code == 0, r.output
        used.append(calls[-1])
    (host, host_tile), (gpu, gpu_tile) = used
    assert host > 2 * need and gpu == 2 * need and gpu_tile < host_tile
    assert denoise_mod.tile_bytes(img.offsets, img.width, img.height, gpu_tile, 0) <= 2 * need
    monkeypatch.setattr(memory, "device_free_bytes", lambda device: need / 2)
    r = run("denoise", FRAME, "-o", tmp_path / "full.exr", "--model", model_file, "--halo", "0")
    assert r.exit_code == 2 and not (tmp_path / "full.exr").exists()
    line = r.output.strip().splitlines()[-1]
    assert "ranad: error:" in line and "the GPU has" in line and "run with --device cpu" in line, r.output


def test_tile_and_halo(tmp_path, model_file):
    """--tile 16 with the default halo (the receptive field) equals the whole frame; --halo 0 makes seams; both
    are recorded in the cache; a tile under 16 is refused."""
    whole = tmp_path / "whole.exr"
    assert run("denoise", FRAME, "-o", whole, "--model", model_file).exit_code == 0
    cases = {"tiled": ("--tile", 16), "tiled_halo16": ("--tile", 16, "--halo", 16),
             "cut": ("--tile", 16, "--halo", 0)}
    for name, opts in cases.items():
        r = run("denoise", FRAME, "-o", tmp_path / f"{name}.exr", "--model", model_file, *opts,
                "--cache", tmp_path / "c")
        assert r.exit_code == 0, r.output
        _, meta = cache_io.read_cache(cache_io.cache_path(str(tmp_path / "c"), str(tmp_path / f"{name}.exr")))
        assert (meta["tile"], meta["halo"]) == ("16", "0" if name == "cut" else "16"), name
    ref = read_deep(whole).values
    for name in ("tiled", "tiled_halo16"):
        np.testing.assert_allclose(read_deep(tmp_path / f"{name}.exr").values, ref, rtol=2e-3, atol=1e-3)
    assert np.abs(read_deep(tmp_path / "cut.exr").values - ref).max() > 1e-2
    r = run("denoise", FRAME, "-o", tmp_path / "small.exr", "--model", model_file, "--tile", 8)
    assert r.exit_code == 2 and "--tile" in r.output and not (tmp_path / "small.exr").exists()
    r = run("denoise", FRAME, "-o", tmp_path / "neg.exr", "--model", model_file, "--halo", -1)
    assert r.exit_code == 2 and "--halo" in r.output


def test_keep_depth_writes_the_input_depths_and_denoises_the_rest(tmp_path, model_file):
    """--keep-depth: Z and ZBack are the input's bit for bit, every other denoised channel is what the run without
    it writes (the depth layer only feeds its own output); without it the depths change."""
    assert run("denoise", FRAME, "-o", tmp_path / "d.exr", "--model", model_file).exit_code == 0
    r = run("denoise", FRAME, "-o", tmp_path / "k.exr", "--model", model_file, "--keep-depth")
    assert r.exit_code == 0, r.output
    src, den, kept = (read_deep(p) for p in (FRAME, tmp_path / "d.exr", tmp_path / "k.exr"))
    for c in ("Z", "ZBack"):
        np.testing.assert_array_equal(kept.channel(c), src.channel(c))
        assert not np.array_equal(den.channel(c), src.channel(c))
    others = [c for c in src.channels if c not in ("Z", "ZBack")]
    np.testing.assert_array_equal(kept.select(others).values, den.select(others).values)
    assert not np.array_equal(kept.channel("R"), src.channel("R"))


def test_kind_names_and_checks_the_input_kind(tmp_path, model_file):
    """The example is deep-OID (one bin per object id per pixel): auto and --kind deepoid report it; the same
    bins with one id for all of them are deep-Z, reported by auto and accepted by --kind deepz. A frame of the
    other kind than --kind asks for is refused in one line naming it, on any frame of a shot."""
    for kind in ("auto", "deepoid"):
        r = run("denoise", FRAME, "-o", tmp_path / f"{kind}.exr", "--model", model_file, "--kind", kind)
        assert r.exit_code == 0 and "deep-OID input" in r.output, (kind, r.output)
    img = read_deep(FRAME)
    img.ids = {"id": np.zeros(img.num_bins, np.uint32)}
    write_deep(tmp_path / "z.exr", img)
    for kind in ("auto", "deepz"):
        r = run("denoise", tmp_path / "z.exr", "-o", tmp_path / f"z_{kind}.exr", "--model", model_file,
                "--kind", kind)
        assert r.exit_code == 0 and "deep-Z input" in r.output, (kind, r.output)
    for path, kind in ((FRAME, "deepz"), (tmp_path / "z.exr", "deepoid")):
        out = tmp_path / f"refused_{kind}.exr"
        r = run("denoise", path, "-o", out, "--model", model_file, "--kind", kind)
        assert r.exit_code == 2 and r.output.count("\n") == 1, r.output
        assert r.output.startswith(f"ranad: error: {path}: --kind {kind}") and not out.exists()
    shot = tmp_path / "shot"
    shot.mkdir()
    shutil.copy(FRAME, shot / "b.0001.exr")
    shutil.copy(tmp_path / "z.exr", shot / "b.0002.exr")                  # the second frame is deep-Z
    r = run("denoise", shot / "b.####.exr", "-o", tmp_path / "o" / "b.####.exr", "--model", model_file,
            "--kind", "deepoid")
    assert r.exit_code == 2 and f"ranad: error: {shot / 'b.0002.exr'}: --kind deepoid" in r.output, r.output
    assert not (tmp_path / "o" / "b.0002.exr").exists()
    r = run("denoise", FRAME, "-o", tmp_path / "x.exr", "--model", model_file, "--kind", "flat")
    assert r.exit_code == 2 and "--kind" in r.output


def test_device_cpu_runs_and_cuda_is_refused_cleanly_without_it(tmp_path, model_file, monkeypatch):
    r = run("denoise", FRAME, "-o", tmp_path / "auto.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    r = run("denoise", FRAME, "-o", tmp_path / "cpu.exr", "--model", model_file, "--device", "cpu")
    assert r.exit_code == 0, r.output
    np.testing.assert_array_equal(read_deep(tmp_path / "cpu.exr").values, read_deep(tmp_path / "auto.exr").values)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    r = run("denoise", FRAME, "-o", tmp_path / "gpu" / "cuda.exr", "--model", model_file, "--device", "cuda")
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ranad: error: ") and "cuda" in lines[0].lower()
    assert "Traceback" not in r.output and not (tmp_path / "gpu" / "cuda.exr").exists()
    r = run("denoise", FRAME, "-o", tmp_path / "tpu.exr", "--model", model_file, "--device", "tpu")
    assert r.exit_code == 2 and "--device" in r.output


def renamed_split(img, names=("kd", "ks")):
    """`img` with its diffuse/specular layers renamed (a renderer's own AOV names)."""
    rename = {f"{old}.{c}": f"{new}.{c}" for old, new in zip(("diffuse", "specular"), names) for c in "RGB"}
    channels = [rename.get(c, c) for c in img.channels]
    out = img.with_values(img.values.copy(), channels)
    out.channel_types = {rename.get(c, c): t for c, t in img.channel_types.items()}
    return out, rename


def test_map_finds_renamed_layers(tmp_path, model_file):
    """A frame whose diffuse/specular layers are called kd/ks, mapped with --map, denoises exactly like the
    same frame with the standard names; unmapped, it runs without the split (and differs)."""
    img = read_deep(FRAME)
    ren, rename = renamed_split(img)
    write_deep(tmp_path / "kd.exr", ren)
    assert run("denoise", FRAME, "-o", tmp_path / "std.exr", "--model", model_file).exit_code == 0
    r = run("denoise", tmp_path / "kd.exr", "-o", tmp_path / "mapped.exr", "--model", model_file,
            "--map", "diffuse=kd", "--map", "specular=ks")
    assert r.exit_code == 0, r.output
    std, mapped = read_deep(tmp_path / "std.exr"), read_deep(tmp_path / "mapped.exr")
    assert sorted(mapped.channels) == sorted(ren.channels)
    for c in std.channels:
        np.testing.assert_array_equal(mapped.channel(rename.get(c, c)), std.channel(c), err_msg=c)
    r = run("denoise", tmp_path / "kd.exr", "-o", tmp_path / "unmapped.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    unmapped = read_deep(tmp_path / "unmapped.exr")
    np.testing.assert_array_equal(unmapped.channel("kd.R"), ren.channel("kd.R"))   # not found, so not denoised
    assert not np.array_equal(unmapped.channel("R"), mapped.channel("R"))
    r = run("denoise", tmp_path / "kd.exr", "-o", tmp_path / "bad.exr", "--model", model_file, "--map", "diffuse")
    assert r.exit_code == 2 and "--map" in r.output and not (tmp_path / "bad.exr").exists()


def test_profile_reports_every_stage_and_changes_nothing(tmp_path, model_file):
    """--profile prints seconds per stage whose top-level stages add up to the total, the tile summary matches the
    tiling (4 tiles of 32 px with a 16-px halo on the 64x64 example), and the output is the same as without it."""
    plain, profiled = tmp_path / "plain.exr", tmp_path / "profiled.exr"
    assert run("denoise", FRAME, "-o", plain, "--model", model_file, "--tile", "32", "--halo", "16").exit_code == 0
    r = run("denoise", FRAME, "-o", profiled, "--model", model_file, "--tile", "32", "--halo", "16", "--profile")
    assert r.exit_code == 0, r.output
    np.testing.assert_array_equal(read_deep(plain).values, read_deep(profiled).values)
    rows = dict(re.findall(r"^\| ([a-z -]+?) \| ([\d.]+) \|", r.output, re.M))
    cpu = {k: (float(c), float(b)) for k, c, b in
           re.findall(r"^\| ([a-z -]+?) \| [\d.]+ \| [\d.]+% \| \d* ?\| ([\d.]+) \| ([\d.]+) \|", r.output, re.M)}
    assert set(cpu) == set(rows), r.output
    for k, (c, busy) in cpu.items():   # threads busy = CPU / wall seconds (both printed rounded to 0.005 s)
        wall = float(rows[k])
        if wall >= 0.1:   # (shorter stages: CPU clocks of a few ms are too coarse to compare)
            assert busy == pytest.approx(c / wall, abs=0.01 + 0.005 * (1 + busy) / wall), (k, r.output)
            assert busy <= os.cpu_count() + 0.5, (k, busy)
    for stage in ("read", "inputs", "tiles", "  - backbone", "  - reconstruction", "assemble", "write", "total"):
        assert stage in rows, (stage, r.output)
    top = sum(float(v) for k, v in rows.items() if not k.startswith("  - ") and k != "total")
    assert top == pytest.approx(float(rows["total"]), abs=0.02)
    parts = sum(float(rows[k]) for k in rows if k.startswith("  - ") and k != "  - sort and prior")
    assert parts <= float(rows["tiles"]) + 0.02
    img = read_deep(FRAME)
    m = re.search(r"(\d+) tile\(s\): (\d+)-(\d+) bins with the halo, ([\d.]+)x", r.output)
    assert m and int(m.group(1)) == 4
    counts = np.diff(img.offsets).reshape(img.height, img.width)
    windows = [counts[max(0, y - 16):y + 48, max(0, x - 16):x + 48].sum() for y in (0, 32) for x in (0, 32)]
    assert (int(m.group(2)), int(m.group(3))) == (min(windows), max(windows))
    assert float(m.group(4)) == pytest.approx(sum(windows) / img.num_bins, abs=0.01)


def test_a_frame_and_its_result_are_gone_when_the_next_frame_is_denoised(tmp_path, model_file, monkeypatch):
    """A shot of single frames holds one frame at a time: when frame t+1 is denoised, frame t's image (the frame
    store kept two for a window of one) and its result (the loop's variables held it) are freed. On a 1080p shot
    at --max-memory 4G they were 0.9 GB that frame 2 found held, and it was refused after frame 1 was written."""
    import gc
    import weakref

    alive = []   # per denoise_window call: (weak refs to what earlier frames read and returned)
    read, done = [], []
    real_read, real_window = shot_mod.read_deep, shot_mod.denoise_window

    def reading(*a, **k):
        img = real_read(*a, **k)
        read.append(weakref.ref(img))
        return img

    def denoising(*a, **k):
        gc.collect()
        alive.append(([r() is not None for r in read[:-1]], [r() is not None for r in done]))
        result = real_window(*a, **k)
        done.append(weakref.ref(result.image))
        return result

    monkeypatch.setattr(shot_mod, "read_deep", reading)
    monkeypatch.setattr(shot_mod, "denoise_window", denoising)
    r = run("denoise", SHOT / "noisy_spp16.####.exr", "-o", tmp_path / "s.####.exr", "--model", model_file)
    assert r.exit_code == 0, r.output
    assert alive == [([], []), ([False], [False]), ([False, False], [False, False])], alive


def test_the_first_frames_read_counts_in_the_profile_and_the_time(tmp_path, model_file, monkeypatch):
    """The first frame is read before the shot (for the report) and not again: that read is still the profile's
    "read" stage and part of the "denoised ... in N s" time (a read made slow here shows in both)."""
    real = shot_mod.read_deep

    def slow(*a, **k):
        time.sleep(0.5)
        return real(*a, **k)

    monkeypatch.setattr(shot_mod, "read_deep", slow)
    r = run("denoise", FRAME, "-o", tmp_path / "p.exr", "--model", model_file, "--profile")
    assert r.exit_code == 0, r.output
    read = re.search(r"^\| read \| ([\d.]+) \|", r.output, re.M)
    assert read and 0.5 <= float(read.group(1)) < 1.0, r.output   # one read: the frame's
    assert float(re.search(r"denoised 1 frame\(s\), \d+ bins, in ([\d.]+) s", r.output).group(1)) >= 0.5


def test_profile_cpu_seconds_tell_a_waiting_stage_from_a_working_one():
    """The profile's CPU seconds are the process's, per stage: a stage that sleeps keeps no thread busy, one that
    computes keeps one busy."""
    from ranad_core.profile import profiling, stage

    with profiling() as prof:
        with stage("read"):
            time.sleep(0.3)
        with stage("write"):
            t = time.perf_counter()
            while time.perf_counter() - t < 0.3:
                sum(range(1000))
    assert prof.cpu["read"] < 0.1 * prof.seconds["read"]
    assert prof.cpu["write"] > 0.6 * prof.seconds["write"]
    assert "| read |" in prof.table() and "| total |" in prof.table()


def test_negative_depths_are_a_convention_error(tmp_path, model_file):
    """Depths behind the camera: a frame written as camera-space z (every depth negative) is refused, exit 2 and no
    output; a stray negative bin is denoised (read as 0) with a message, and refused with --strict."""
    img = read_deep(FRAME)
    z = img.channels.index("Z")
    flipped = img.values.copy()
    flipped[:, z] *= -1
    write_deep(tmp_path / "neg.exr", img.with_values(flipped))
    r = run("denoise", tmp_path / "neg.exr", "-o", tmp_path / "out.exr", "--model", model_file)
    assert r.exit_code == 2 and "negative depth 'Z'" in r.output and str(tmp_path / "neg.exr") in r.output
    assert not (tmp_path / "out.exr").exists()
    one = img.values.copy()
    one[0, z] = -1.0
    write_deep(tmp_path / "one.exr", img.with_values(one))
    r = run("denoise", tmp_path / "one.exr", "-o", tmp_path / "one_out.exr", "--model", model_file)
    assert r.exit_code == 0 and "1 bin(s) with a negative depth" in r.output, r.output
    r = run("denoise", tmp_path / "one.exr", "-o", tmp_path / "strict.exr", "--model", model_file, "--strict")
    assert r.exit_code == 2 and not (tmp_path / "strict.exr").exists()


def test_an_empty_frame_needs_no_flat_prior(tmp_path):
    """A frame without bins (an element's layer with nothing in view) gets no OIDN run, so its memory estimate
    drops OIDN's 600 B per pixel: an empty 4000 x 4000 frame was refused at the default 8G for 10 GB. It
    denoises to an empty frame of the same window, with the shipped (flat-prior) default."""
    from ranad_core import memory
    from ranad_core.deep import DeepImage

    def frame(counts, w, h):
        offsets = np.concatenate([[0], np.cumsum(counts)])
        n = int(offsets[-1])
        vals = np.column_stack([np.full((n, 4), 0.5, np.float32), np.arange(1, n + 1, dtype=np.float32)])
        return DeepImage(values=vals, offsets=offsets, channels=["R", "G", "B", "A", "Z"],
                         data_window=(0, 0, w - 1, h - 1),
                         channel_types={"R": "half", "G": "half", "B": "half", "A": "half", "Z": "float"})

    w, h = 96, 64
    counts = np.zeros(w * h, np.int64)
    empty = frame(counts, w, h)
    assert memory.prior_peak_bytes([empty], 0) == 64.0 * w * h
    counts[7] = 1
    assert memory.prior_peak_bytes([frame(counts, w, h)], 0) > 600.0 * w * h
    write_deep(tmp_path / "empty.exr", empty)
    r = run("denoise", tmp_path / "empty.exr", "-o", tmp_path / "out.exr")
    assert r.exit_code == 0, r.output
    out = read_deep(tmp_path / "out.exr")
    assert out.num_bins == 0 and out.data_window == empty.data_window and set(out.channels) >= {"R", "A", "Z"}


def test_no_cursor_codes_in_a_log(tmp_path, model_file):
    """With stderr not a terminal (a farm's log; CliRunner's too) the tiles' bar, which moves the cursor up to sit
    under the frames' bar, stays off: its escape codes used to stand in front of the one-line error."""
    img = read_deep(FRAME)
    vals = img.values.copy()
    vals[:, img.channels.index("Z")] *= -1
    write_deep(tmp_path / "neg.exr", img.with_values(vals))
    r = run("denoise", tmp_path / "neg.exr", "-o", tmp_path / "o.exr", "--model", model_file)
    assert r.exit_code == 2 and "\x1b[" not in r.output and not (tmp_path / "o.exr").exists()
    assert r.output.splitlines()[-1].startswith("ranad: error: ") and "negative depth" in r.output
    r = run("denoise", FRAME, "-o", tmp_path / "ok.exr", "--model", model_file)
    assert r.exit_code == 0 and "\x1b[" not in r.output


def test_a_mipmapped_deep_part_is_said_to_lose_its_levels(tmp_path, model_file):
    """A mipmapped deep tiled file (OpenEXR writes them) came out as one scan-line level without a word: the run
    says so, and `ranad info` shows the levels."""
    import OpenEXR

    h, w = 16, 20
    rng = np.random.default_rng(0)
    counts = rng.integers(1, 3, (h, w))

    chan = lambda dtype, make: openexr_deep_channel(counts, dtype, make)  # noqa: E731

    z = chan("f", lambda n: np.sort(rng.uniform(1, 10, n)))
    rgb, a = chan("e", lambda n: np.full(n, 0.3)), chan("e", lambda n: np.full(n, 0.5))
    desc = OpenEXR.TileDescription()
    desc.xSize, desc.ySize, desc.mode = 8, 8, OpenEXR.LevelMode.MIPMAP_LEVELS
    src = str(tmp_path / "mip.exr")
    OpenEXR.File({"type": OpenEXR.deeptile, "compression": OpenEXR.ZIPS_COMPRESSION, "tiles": desc},
                 {"R": rgb, "G": rgb, "B": rgb, "A": a, "Z": z}).write(src)
    r = run("info", src, "--no-stats")
    assert r.exit_code == 0 and "mipmap levels (ranad reads the full-resolution one)" in r.output, r.output
    r = run("denoise", src, "-o", tmp_path / "d.exr", "--model", model_file)
    assert r.exit_code == 0 and "a mipmapped deep part: its full-resolution level is denoised and written as scan " \
                                "lines, without the other levels" in r.output, r.output
    assert read_deep(tmp_path / "d.exr").counts.reshape(h, w).tolist() == counts.tolist()
