"""The generalization protocol of `ranad eval` (issue 24): the exposure sweep scales exactly the radiance channels,
held-out families are reported apart, and the ratio table divides the right means."""

from __future__ import annotations

import numpy as np
import pytest

from ranad_core.deep import DeepImage
from ranad_core.evaluate import exposed, family_ratios, grouped_markdown, radiance_channels, ratios


def test_exposure_scales_radiance_only():
    chans = ["R", "G", "B", "A", "Z", "ZBack", "diffuse.R", "diffuse.G", "diffuse.B", "albedo.R", "N.X",
             "lg_key.R", "motion_prev.X", "coverage", "specular.B", "emission.G"]
    assert radiance_channels(chans) == ["R", "G", "B", "diffuse.R", "diffuse.G", "diffuse.B", "lg_key.R",
                                        "specular.B", "emission.G"]
    rng = np.random.default_rng(0)
    img = DeepImage(values=rng.random((5, len(chans))).astype(np.float32), offsets=np.array([0, 2, 5]),
                    channels=chans, data_window=(0, 0, 1, 0))
    up = exposed(img, 3)
    scale = np.array([8.0 if c in radiance_channels(chans) else 1.0 for c in chans], np.float32)
    np.testing.assert_array_equal(up.values, img.values * scale)
    np.testing.assert_array_equal(exposed(up, -3).values, img.values)


def _rows():
    rows = []
    for group, fam, ranad_flip in (("held-out", "glass", 0.08), ("in-family", "easy", 0.05)):
        for scene, mult in (("a", 1.0), ("b", 3.0)):
            for method, flip, comp in (("noisy", 0.2, 0.1), ("oidn", 0.1, float("nan")), ("recolour", 0.1, 0.06),
                                       ("ranad", ranad_flip, 0.03)):
                rows.append({"scene": f"{scene}{group}", "family": fam, "group": group, "exposure": 0,
                             "kind": "deepz", "spp": 16, "method": method, "flip": flip * mult,
                             "smape": 0.0, "dssim": 0.0, "bin_smape": 0.0, "z_rel": 0.0, "comp_flip": comp * mult,
                             "comp_smape": 0.0, "sep_smape": 0.0, "sep_dssim": 0.0, "seconds": 0.0})
    return rows


def test_ratios_per_group():
    rt = {r["group"]: r for r in ratios(_rows())}
    assert rt["held-out"]["flip_vs_oidn"] == pytest.approx(0.8)
    assert rt["in-family"]["flip_vs_oidn"] == pytest.approx(0.5)
    assert rt["held-out"]["edit_vs_recolour"] == pytest.approx(0.5)
    text = grouped_markdown(_rows(), "t")
    assert text.index("held-out (glass)") < text.index("in-family (easy)")
    assert "| held-out | +0 | deepz | 16 | 2 | 0.8000 | 0.5000 |" in text


def test_ratios_per_family():
    """The per-family table divides each family's own means: OIDN's flat FLIP is half the noisy input's in both
    families, ranad's 0.8x / 0.5x OIDN's, its edit half of recolour's."""
    rows = _rows()
    rows += [{**r, "scene": "c", "exposure": 2} for r in rows[:4]]   # glass at another exposure
    fr = {(r["family"], r["spp"]): r for r in family_ratios(_rows())}
    assert fr[("glass", 16)]["oidn_vs_noisy"] == pytest.approx(0.5)
    assert fr[("glass", 16)]["flip_vs_oidn"] == pytest.approx(0.8)
    assert fr[("easy", 16)]["flip_vs_oidn"] == pytest.approx(0.5)
    assert fr[("easy", 16)]["edit_vs_recolour"] == pytest.approx(0.5)
    assert {r["n"] for r in family_ratios(rows) if r["family"] == "glass"} == {3}
    text = grouped_markdown(_rows(), "t")
    assert "| glass | 16 | 2 | 0.5000 | 0.8000 | 0.5000 |" in text


def test_reference_note_names_the_sample_counts_whose_references_are_thin():
    """eval.md says where a reference holds under REF_SPP_RATIO times its input's samples (its own noise then part of
    every score), and says nothing where every reference is ample or its count was not recorded."""
    from ranad_core.evaluate import REF_SPP_RATIO, reference_note

    rows = [{**r, "ref_spp": 512} for r in _rows()] + [{**r, "spp": 64, "ref_spp": 512} for r in _rows()]
    note = "\n".join(reference_note(rows))
    assert "64 spp against 512 (8x)" in note and "16 spp" not in note          # 32x at 16 spp is ample
    assert note in grouped_markdown(rows, "t")
    assert reference_note([{**r, "ref_spp": REF_SPP_RATIO * 16} for r in _rows()]) == []
    assert reference_note(_rows()) == []                                        # no count recorded
    assert "Reference noise" not in grouped_markdown(_rows(), "t")


def test_film_note_flags_frames_whose_noise_flat_oidn_keeps(tmp_path):
    """eval.md says when frames went through a wide pixel filter (their noise correlated between pixels, which flat
    OIDN leaves in place, so ratios against it flatter ranad); box-filtered frames and sets without a manifest get
    no note. The film and sampler come from the scene's manifest (box and independent where it names none)."""
    import json
    from types import SimpleNamespace

    from ranad_core.evaluate import film_note, render_conditions, scene_manifest

    box = [{**r, "film": "box"} for r in _rows()]
    wide = box + [{**r, "film": "gaussian 2"} for r in _rows()]
    note = "\n".join(film_note(wide))
    assert "gaussian 2" in note and "box" not in note.split("through")[1].split(":")[0]
    assert note in grouped_markdown(wide, "t")
    assert film_note(box) == [] and film_note([{**r, "film": "?"} for r in _rows()]) == [] and film_note(_rows()) == []
    scene = tmp_path / "scene_0000"
    (scene / "deepz").mkdir(parents=True)
    pair = SimpleNamespace(noisy=scene / "deepz" / "noisy_spp4.0000.exr")
    assert render_conditions(scene_manifest(pair)) == ("?", "?")
    (scene / "manifest.json").write_text(json.dumps({"preset": "glass"}))
    assert render_conditions(scene_manifest(pair)) == ("box", "independent")
    (scene / "manifest.json").write_text(json.dumps({"pixel_filter": ["gaussian", 2.0], "sampler": "sobol"}))
    assert render_conditions(scene_manifest(pair)) == ("gaussian 2", "sobol")


def test_ratios_against_oidn_with_prefiltered_guides():
    """Where the frames were also scored by OIDN with prefiltered guides, the ratio table divides ranad's means by
    that baseline's (and its recolour's edit); where they were not (frames without albedo), n/a, not a number made
    up from the plain baseline."""
    rows = _rows()
    for r in [r for r in rows if r["group"] == "held-out" and r["method"] in ("oidn", "recolour")]:
        rows.append({**r, "method": r["method"] + "-clean", "flip": r["flip"] * 0.5,
                     "comp_flip": r["comp_flip"] * 0.75})
    rt = {r["group"]: r for r in ratios(rows)}
    assert rt["held-out"]["flip_vs_oidn_clean"] == pytest.approx(1.6)       # 0.08 / (0.1 * 0.5)
    assert rt["held-out"]["edit_vs_recolour_clean"] == pytest.approx(0.5 / 0.75)
    assert rt["held-out"]["flip_vs_oidn"] == pytest.approx(0.8)             # the plain baseline's ratio unchanged
    assert np.isnan(rt["in-family"]["flip_vs_oidn_clean"])
    text = grouped_markdown(rows, "t")
    assert "| held-out | +0 | deepz | 16 | 2 | 0.8000 | 0.5000 | 1.6000 | 0.6667 |" in text
    assert "| in-family | +0 | deepz | 16 | 2 | 0.5000 | 0.5000 | n/a | n/a |" in text
