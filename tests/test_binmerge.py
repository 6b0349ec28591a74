"""Thin bins of one surface (binmerge): merged before the model so that a frame a renderer binned finely denoises
like the same frame binned as ranad's training data, and shared back so that the output keeps every input bin,
composites to the merged result and stays linear (light groups through the cached kernels still sum)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner

from ranad_cli.main import cli
from ranad_core import binmerge
from ranad_core.aov import aov_layers, denoise_aovs
from ranad_core.channels import canonical, detect
from ranad_core.deep import DeepImage, flatten
from ranad_core.errors import RanadError
from ranad_core.denoise import denoise_window
from ranad_core.exr import read_deep, write_deep
from ranad_core.model import RaNAD, feature_dim, get_config
from ranad_core.model.crossframe import CrossFrameRaNAD
from ranad_core.model.store import load_model

from model_factory import input_keys_config
from test_aov import GROUPS, exact_groups, sums

ROOT = Path(__file__).resolve().parents[1]
SHOT = ROOT / "examples" / "synth_shot"
STACK = Path(__file__).resolve().parent / "data" / "ranad-synth" / "layer_stack_noisy_spp16.exr"
COLOURS = ("R", "G", "B", "diffuse.", "specular.", "emission.", "lg_")


def thin(img: DeepImage, k: int = 3, step: float = 0.002) -> DeepImage:
    """Every bin as k thin members 0.2% apart in depth, as a renderer that merges less writes one surface: each
    takes an equal share of the bin's coverage, alpha 1 - (1 - a)^(1/k) and the bin's colour at that alpha, so
    the members composite exactly to the bin."""
    ch, n = img.channels, img.num_bins
    rows = np.repeat(np.arange(n), k)
    member = np.tile(np.arange(k), n)
    vals = img.values[rows].astype(np.float64)
    a = np.clip(img.channel("A").astype(np.float64), 0, 1)
    ak = 1 - (1 - a) ** (1.0 / k)
    f = np.repeat(np.where(a > 0, ak / np.maximum(a, 1e-300), 1.0 / k), k)
    for i, c in enumerate(ch):
        if c == "A":
            vals[:, i] = np.repeat(ak, k)
        elif c in ("Z", "ZBack"):
            vals[:, i] *= 1 + step * member
        elif c == "coverage":
            vals[:, i] /= k
        elif c in ("R", "G", "B") or c.startswith(COLOURS[3:]):
            vals[:, i] *= f
    types = {c: ("uint" if c in img.ids else "float") for c in list(ch) + list(img.ids)}
    return DeepImage(values=vals.astype(np.float32), offsets=img.offsets * k, channels=list(ch),
                     ids={name: v[rows] for name, v in img.ids.items()}, data_window=img.data_window,
                     display_window=img.display_window, channel_types=types)


def sorted_canonical(img):
    canon, _ = canonical(img, detect(img))
    return canon.sorted()


def frame(i=1, crop=None):
    img = read_deep(SHOT / f"noisy_spp16.{i:04d}.exr")
    img = img.with_values(img.values.astype(np.float32))
    return img.crop(crop) if crop else img


def stack():
    """A deep-Z crop of ranad's tracer (its bins are over 3% apart, so thin members never interleave; deep-OID
    bins of touching objects can sit closer and then keep apart by their ids)."""
    img = read_deep(STACK)
    return img.with_values(img.values.astype(np.float32))


def test_training_like_bins_never_merge():
    """ranad's own binning starts a new bin at a 3% jump: its files (the bundled shot, a held-out layer stack)
    have nothing within the default gap, so merging leaves them, and every model score, as they were."""
    for img in (frame(0), frame(1), read_deep(STACK)):
        srt, perm = sorted_canonical(img)
        assert binmerge.groups_of(srt, img, perm) is None


def _pixel(zs, alphas, zbacks=None, ids=None):
    n = len(zs)
    chans = ["A", "B", "G", "R", "Z"] + (["ZBack"] if zbacks is not None else [])
    cols = [alphas, [0.1] * n, [0.2] * n, [0.3] * n, zs] + ([zbacks] if zbacks is not None else [])
    img = DeepImage(values=np.asarray(cols, np.float32).T.copy(), offsets=np.array([0, n]), channels=chans,
                    ids={} if ids is None else {"id": np.asarray(ids, np.uint32)})
    return binmerge.find_groups(sorted_canonical(img)[0], img.ids)


def test_what_merges():
    g = _pixel([10.0, 10.05, 10.1, 20.0], [0.3, 0.3, 0.3, 0.5])   # a chain of 0.5% steps, then another surface
    assert g is not None and list(g.index) == [0, 0, 0, 1] and list(g.offsets) == [0, 2]
    assert _pixel([10.0, 10.05], [0.3, 0.3], ids=[1, 2]) is None                 # other objects
    assert _pixel([10.0, 10.05], [0.3, 0.3], zbacks=[10.5, 10.55]) is None       # volumes
    assert _pixel([10.0, 10.4], [0.3, 0.3]) is None                              # 4% apart: two layers
    assert _pixel([10.0, 10.05], [0.3, 0.3], ids=[4, 4]) is not None
    assert _pixel([0.0, 0.0], [0.3, 0.3]) is None and _pixel([np.nan, np.nan], [0.3, 0.3]) is None   # no depths


def test_merge_keeps_the_composite_and_sharing_back_composites_to_any_result():
    img = stack()
    srt0, _ = sorted_canonical(img)
    srt, _ = sorted_canonical(thin(img))
    g = binmerge.find_groups(srt)
    assert g is not None and g.merged == srt0.num_bins
    merged = binmerge.merge(srt, g)
    for c in ("A", "diffuse.R", "specular.G", "albedo.B", "N.X", "Z"):
        np.testing.assert_allclose(merged.channel(c), srt0.channel(c), atol=2e-5, rtol=1e-4, err_msg=c)
    np.testing.assert_allclose(merged.channel("ZBack"), srt0.channel("ZBack") * 1.004, rtol=1e-6)  # the back's
    rng = np.random.default_rng(0)
    a_new = rng.uniform(0, 1, g.merged)
    a_new[::7] = 1.0                                                  # opaque results too
    c_new = rng.uniform(0, 2, (g.merged, 3))
    f = binmerge.split_factors(g, a_new)
    a_m = binmerge.split_alpha(a_new, g, f).astype(np.float64)
    c_m = binmerge.split(c_new, g, f)
    # the members composited front to back, per group, give the group's result exactly
    alpha, colour = np.zeros(g.merged), np.zeros((g.merged, 3))
    t = np.ones(g.merged)
    for i, grp in enumerate(g.index):
        alpha[grp] += t[grp] * a_m[i]
        colour[grp] += t[grp] * c_m[i]
        t[grp] *= 1 - a_m[i]
    np.testing.assert_allclose(alpha, a_new, atol=1e-9)
    np.testing.assert_allclose(colour, c_new, atol=1e-9)
    # noisy alphas in, the members' own alphas out (hidden members keep the group's)
    f0 = binmerge.split_factors(g, merged.channel("A"))
    seen = g.trans > 1e-6
    np.testing.assert_allclose(binmerge.split_alpha(merged.channel("A"), g, f0)[seen], srt.channel("A")[seen],
                               atol=1e-5)


def test_merge_equals_the_groups_summed_bin_by_bin():
    """merge against a plain loop over the bins: each group's float64 sum of its members' weighted values in bin
    order from 0.0, as np.bincount adds them, rounded to float32; bit for bit, signed zeros and NaN included."""
    srt, _ = sorted_canonical(thin(stack(), k=2))
    values = srt.values.copy()
    values[::11] = -0.0                       # a lone -0.0 sums to +0.0
    values[5::97, srt.channels.index("diffuse.G")] = np.nan
    values[::13, srt.channels.index("A")] = 1.5   # alpha clipped to 1 before compositing
    srt = srt.with_values(values)
    g = binmerge.find_groups(srt)
    assert g is not None and 0 < g.merged < srt.num_bins
    weight = {"composite": g.trans, "sum": np.ones(srt.num_bins), "mean": g.share}
    expect = np.zeros((g.merged, len(srt.channels)), np.float64)
    first = np.full(g.merged, -1)
    for i, grp in enumerate(g.index):
        first[grp] = i if first[grp] < 0 else first[grp]
        for j, c in enumerate(srt.channels):
            v = float(values[i, j])
            if c == "A":
                expect[grp, j] += min(max(v, 0.0), 1.0) * g.trans[i]
            elif c == "Z":
                expect[grp, j] = values[first[grp], j]
            elif c == "ZBack":
                expect[grp, j] = v                                        # the last member's
            else:
                how = ("composite" if c in binmerge.PREMULTIPLIED else "sum" if c in binmerge.SUMMED else "mean")
                expect[grp, j] += v * weight[how][i]
    merged = binmerge.merge(srt, g)
    assert merged.values.dtype == np.float32 and merged.values.flags.c_contiguous
    assert merged.values.tobytes() == expect.astype(np.float32).tobytes()
    assert list(merged.offsets) == list(g.offsets) and merged.channels == srt.channels


def test_thin_bins_denoise_like_whole_surface_bins():
    """The shipped default on a frame and on the same frame binned thinly: the same flattened image, the thin
    input's bins kept; without merging the thin frame denoises differently (what the merge is for)."""
    model = load_model(None).model
    img = stack()
    fine = thin(img)
    whole = flatten(denoise_window(model, [img], 0).image)
    res = denoise_window(model, [fine], 0)
    out = res.image
    np.testing.assert_array_equal(out.offsets, fine.offsets)
    assert res.merges is not None and res.bins == fine.num_bins and res.offsets[0][-1] == img.num_bins
    ch = out.channels
    rgb = [ch.index(c) for c in ("R", "G", "B", "A")]
    scale = np.abs(whole[..., rgb]).max()
    assert np.abs(flatten(out)[..., rgb] - whole[..., rgb]).max() < 2e-3 * scale
    off = denoise_window(model, [fine], 0, merge_gap=0)
    assert off.merges is None
    assert np.abs(flatten(off.image)[..., rgb] - whole[..., rgb]).max() > 2e-2 * scale


def _models():
    torch.manual_seed(0)
    single = RaNAD(get_config("cpu-small-pdl-gza"), feature_dim("prior")).eval()
    keyed = CrossFrameRaNAD.from_single(RaNAD(get_config("cpu-small"), feature_dim()).eval(), input_keys_config(),
                                        feature_dim()).eval()
    for gate in keyed.temporal_gate.values():
        torch.nn.init.constant_(gate.bias, 0.0)
    return {"single": single, "input-keys": keyed}


@pytest.mark.parametrize("kind", ["single", "input-keys"])
def test_light_groups_sum_to_the_denoised_beauty_through_merged_bins(kind):
    model = _models()[kind]
    frames = [thin(exact_groups(frame(i, (0, 0, 47, 47)))) for i in range(3)]
    images, centre = (frames, 1) if kind != "single" else ([frames[1]], 0)
    res = denoise_window(model, images, centre, want_embeddings=True, tile=16)
    assert res.merges is not None
    layers = aov_layers(frames[1].channels, "lg_*")
    out = denoise_aovs(model, images, centre, detect(frames[1]), layers, res.embeddings, res.perms, res.offsets,
                       None, res.merge_gap, res.merges, res.split, res.dark_radius, res.gain)
    lg_d = sum(out[g].astype(np.float64) for g in GROUPS)
    _, rgb_d = sums(res.image)
    lg, _ = sums(frames[1])
    scale = np.abs(rgb_d).max()
    assert np.abs(lg_d - rgb_d).max() < 1e-5 * scale
    assert np.abs(lg_d - lg).max() > 1e-2 * scale
    with pytest.raises(RanadError, match="merged thin bins not given"):   # the merges are not optional
        denoise_aovs(model, images, centre, detect(frames[1]), layers, res.embeddings, res.perms, res.offsets)


def test_aov_command_through_the_cache_of_merged_bins(tmp_path):
    """`ranad denoise --cache` then `ranad aov` on a thinly binned frame: the groups keep the file's bins and sum
    to the denoised beauty; a cache whose merge tensors were damaged is refused; `--bin-merge 0` denoises it
    otherwise."""
    from safetensors.torch import save_file

    net = _models()["single"]
    model = tmp_path / "m.safetensors"
    save_file({k: v.contiguous() for k, v in net.state_dict().items()}, str(model),
              metadata={"model_config": json.dumps(net.config.to_dict())})
    src = thin(exact_groups(frame(1, (0, 0, 47, 47))))
    write_deep(tmp_path / "b.exr", src)
    run = lambda *a: CliRunner().invoke(cli, [str(x) for x in a])  # noqa: E731
    r = run("info", tmp_path / "b.exr")
    thin_count = int(r.output.split("thin bins: ")[1].split()[0])    # at most two of every three members merge away
    assert r.exit_code == 0 and 0.6 * src.num_bins < thin_count <= src.num_bins - src.num_bins // 3, r.output
    assert "thin bins" not in run("info", SHOT / "noisy_spp16.0001.exr").output
    r = run("denoise", tmp_path / "b.exr", "-o", tmp_path / "d.exr", "--model", model, "--cache", tmp_path / "c")
    assert r.exit_code == 0, r.output
    r = run("aov", tmp_path / "c", "--layers", "lg_*", "-o", tmp_path / "lg.exr")
    assert r.exit_code == 0, r.output
    a, d = read_deep(tmp_path / "lg.exr"), read_deep(tmp_path / "d.exr")
    np.testing.assert_array_equal(a.offsets, src.offsets)
    lg, _ = sums(a)
    _, rgb = sums(d)
    assert np.abs(lg - rgb).max() < 1e-5 * np.abs(rgb).max()
    from safetensors.numpy import load_file, save_file as save_np
    from safetensors import safe_open

    from ranad_core.cache import tensors_checksum

    cache = next((tmp_path / "c").iterdir())
    with safe_open(str(cache), framework="np") as f:
        meta = f.metadata()
    tensors = load_file(str(cache))
    for key, bad, message in (("split", tensors["split"][:-1], "share-back factors"),
                              ("merge.0", tensors["merge.0"][::-1].copy(), "cached bin merges")):
        tampered = {**tensors, key: bad}   # consistent with its checksum: the cache's own checks must catch it
        save_np(tampered, str(cache), metadata={**meta, "tensors_crc32": tensors_checksum(tampered)})
        r = run("aov", tmp_path / "c", "--layers", "lg_*", "-o", tmp_path / "bad.exr")
        assert r.exit_code == 2 and message in r.output and str(cache) in r.output, r.output
        assert not (tmp_path / "bad.exr").exists()
    r = run("denoise", tmp_path / "b.exr", "-o", tmp_path / "d0.exr", "--model", model, "--bin-merge", "0")
    assert r.exit_code == 0, r.output
    assert np.abs(flatten(read_deep(tmp_path / "d0.exr")) - flatten(d)).max() > 0


def test_info_counts_thin_bins_a_chunk_at_a_time(monkeypatch):
    """`ranad info`'s thin-bin count (exr.inspect.thin_bins) works on alpha, depths and ids a chunk of pixels at a
    time (the whole canonical frame sorted took 2 GB at 16.7 M bins): it equals the count over the whole
    canonical frame, as denoise finds the groups, with ids kept apart and non-finite depths filled from the whole
    frame, when the chunks are forced small."""
    from ranad_core import deep as deep_mod
    from ranad_core.channels import DEPTHS
    from ranad_core.deep import replace_nonfinite
    from ranad_core.exr.inspect import thin_bins

    img = thin(frame(1, (0, 0, 31, 23)))
    vals = img.values.copy()
    vals[::97, img.channels.index("Z")] = np.nan
    img = img.with_values(vals)
    m = detect(img)
    srt, perm = replace_nonfinite(canonical(img, m)[0], DEPTHS)[0].sorted()
    whole = img.num_bins - binmerge.groups_of(srt, img, perm).merged
    assert whole > img.num_bins // 2 and "id" in img.ids
    monkeypatch.setattr(deep_mod, "_CHUNK_BINS", 50)
    assert len(list(deep_mod.pixel_chunks(img.offsets))) > 20
    assert thin_bins(img, m) == whole


def test_float_object_ids_keep_objects_apart():
    """An object id channel stored as half/float (some tools write ids so) was not seen as one: bins of two
    objects 1% apart in depth merged, each object taking the other's colour, and the frame read as deep-Z."""
    from ranad_core.exr.inspect import guess_kind, id_columns, object_id_channel

    n_pix = 6
    z = np.tile([10.0, 10.1], n_pix).astype(np.float32)
    rgb = np.tile([[1, 0.05, 0.05], [0.05, 0.05, 1]], (n_pix, 1)).astype(np.float32)
    ids = np.tile([1.0, 2.0], n_pix).astype(np.float32)
    vals = np.column_stack([rgb, np.full(2 * n_pix, 0.5, np.float32), z, ids])
    img = DeepImage(vals, np.arange(0, 2 * n_pix + 1, 2), ["R", "G", "B", "A", "Z", "id"],
                    data_window=(0, 0, n_pix - 1, 0),
                    channel_types={"R": "half", "G": "half", "B": "half", "A": "half", "Z": "float", "id": "float"})
    assert object_id_channel(img) == "id" and list(id_columns(img)) == ["id"] and guess_kind(img) == "deep-OID"
    srt, perm = canonical(img, detect(img))[0].sorted()
    assert binmerge.groups_of(srt, img, perm) is None                # the objects keep apart
    plain = img.select(["R", "G", "B", "A", "Z"])
    assert binmerge.groups_of(srt, plain, perm).merged == n_pix      # without the ids they would merge


def test_describing_a_file_with_thin_bins_does_not_load_torch(tmp_path):
    """`ranad info`'s reading path (exr.inspect.describe, which counts thin bins with find_groups) stays free of
    torch, whose import costs seconds of CPU: the fuzz harness times each case's describe against a 5 s limit, and
    a torch import at binmerge's top once pushed its first case over it."""
    import subprocess
    import sys

    path = tmp_path / "thin.exr"
    write_deep(str(path), thin(stack()))
    code = ("import sys; from ranad_core.exr.inspect import describe; d = describe(sys.argv[1]); "
            "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code, str(path)], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "False"
