"""`ranad eval`: a model against the baselines on a held-out `ranad synth` set (centre frames).

Per scene, bin kind (deep-Z / deep-OID) and spp, every method gets the flat scores of its flattened beauty
against the flattened reference (SMAPE, DSSIM, HDR-FLIP) and, when it keeps the deep layout, the deep scores
(per-bin SMAPE, the compositing edit and the depth separation; see metrics.py). Methods: the noisy input, flat
OIDN, OIDN then recolour, and ranad. The summary averages over scenes per spp; a PNG grid shows the flattened
images and the compositing edit side by side.
"""

from __future__ import annotations

import csv
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np

from . import metrics
from .baselines import oidn_flat, recolour
from .channels import ALBEDO
from .denoise import denoise_window
from .exr import read_deep
from .train.data import find_pairs, read_manifest

METHODS = ("noisy", "oidn", "oidn-clean", "recolour", "recolour-clean", "ranad")
# the grid's image columns (Result.grid_columns); "oidn-clean" and "recolour-clean" (flat OIDN with prefiltered
# guides, and the recolour from it) are scored where a frame has albedo, not shown
GRID_METHODS = ("noisy", "oidn", "recolour", "ranad")
FLAT = ("smape", "dssim", "flip")
DEEP = ("bin_smape", "z_rel", "comp_flip", "comp_smape", "sep_smape", "sep_dssim")
COLUMNS = ("scene", "family", "group", "exposure", "kind", "spp", "ref_spp", "film", "sampler", "method", *FLAT,
           "light", *DEEP, "seconds")
# A reference with fewer than this many times its input's samples is noisy enough to be part of every score against
# it: at 8x, two tracings of a glass scene's reference differ by three quarters of what a 64-spp input does
# (runs/generalization-s25, section 3).
REF_SPP_RATIO = 16


def radiance_channels(channels) -> list:
    """The channels an exposure change scales: the beauty, every premultiplied colour layer and light group
    (not alpha, depth, albedo, normals, positions, motion, coverage or ids)."""
    from .channels import ALIASES

    colour = {a for k in ("diffuse", "specular", "emission") for a in ALIASES[k]}
    out = []
    for c in channels:
        layer, _, comp = c.rpartition(".")
        if c in ("R", "G", "B") or (comp in ("R", "G", "B", "r", "g", "b") and
                                    (layer in colour or layer.startswith("lg_"))):
            out.append(c)
    return out


def exposed(img, stops: float):
    """`img` with its radiance channels scaled by 2^stops (exact in float for whole stops)."""
    if not stops:
        return img
    vals = img.values.copy()
    for c in radiance_channels(img.channels):
        vals[:, img.channels.index(c)] *= np.float32(2.0 ** stops)
    return img.with_values(vals)


def scene_manifest(pair) -> dict:
    """A pair's scene manifest ({} where it cannot be read)."""
    import json

    manifest = pair.noisy.parent.parent / "manifest.json"
    try:
        m = json.loads(manifest.read_text())
    except (OSError, ValueError):
        return {}
    return m if isinstance(m, dict) else {}


def scene_family(m: dict) -> str:
    """The scene family (synth preset), from a scene's manifest (scene_manifest)."""
    return m.get("preset", "?")


def render_conditions(m: dict) -> tuple[str, str]:
    """(film, sampler) a synth scene was rendered with, from its manifest (scene_manifest; "box", "gaussian 2", ...;
    "stratified", "sobol", ...; "?" without one): what flat OIDN's figures depend on (see film_note)."""
    if not m:
        return "?", "?"
    f = m.get("pixel_filter")
    film = f"{f[0]} {float(f[1]):g}" if isinstance(f, list) and len(f) == 2 else "box"
    return film, str(m.get("sampler", "independent"))


def reference_spp(m: dict) -> int:
    """Samples per pixel of a scene's references, from its manifest (scene_manifest; 0: not recorded)."""
    v = m.get("ref_spp", 0)
    return int(v) if isinstance(v, (int, float)) and v > 0 else 0


@dataclass
class Result:
    rows: list = field(default_factory=list)        # one dict per (scene, kind, spp, method), COLUMNS keys
    grid: list = field(default_factory=list)        # per pair shown: (label, [H, W, 3] images per column)
    grid_columns: tuple = ("noisy", "oidn", "recolour", "ranad", "reference", "edit: recolour", "edit: ranad",
                           "edit: reference")


def evaluate(dataset: str, model, spps=None, kinds=None, max_scenes: int | None = None, grid_pairs: int = 4,
             progress=None, exposures=(0,), held_out=(), merge_gap: float | None = None,
             dark_radius: int | None = None, light_match: bool = True) -> Result:
    """Scores every selected pair; `model` is a RaNAD in eval mode.

    exposures: stops by which each noisy input is scaled before every method runs; the outputs are scaled back
    before scoring against the unscaled reference, so each row says how well a method does on the same scene
    rendered brighter or darker. held_out: scene families (synth presets) the model never trained on; rows get
    group "held-out" for them and "in-family" otherwise (the generalization protocol). merge_gap: ranad's
    thin-bin merging (binmerge; None: its default, 0: off); dark_radius: its black neighbourhoods (darkness; None:
    its default, 0: off); light_match: its light matching to the noisy render's local light (lightmatch)."""
    pairs = [p for p in find_pairs(dataset) if (not spps or p.spp in spps) and (not kinds or p.kind in kinds)]
    if max_scenes:
        keep = sorted({p.scene for p in pairs})[:max_scenes]
        pairs = [p for p in pairs if p.scene in keep]
    result = Result()
    for pair, stops in ((p, e) for p in pairs for e in exposures):
        manifest = scene_manifest(pair)   # read once for the family, the references' spp and the film
        family, ref_spp = scene_family(manifest), reference_spp(manifest)
        film, sampler = render_conditions(manifest)
        group = "held-out" if family in held_out else "in-family"
        noisy, ref = exposed(read_deep(pair.noisy), stops), read_deep(pair.reference)
        z = metrics.split_depth(ref)
        flat_ref = metrics.flat_rgb(ref)
        outputs, seconds = {}, {}
        t = time.perf_counter()
        outputs["oidn"] = oidn_flat(noisy)
        seconds["oidn"] = time.perf_counter() - t
        t = time.perf_counter()
        outputs["recolour"] = recolour(noisy, outputs["oidn"])
        seconds["recolour"] = time.perf_counter() - t + seconds["oidn"]
        if all(c in noisy.channels for c in ALBEDO):   # OIDN at its best: its guides prefiltered
            t = time.perf_counter()
            outputs["oidn-clean"] = oidn_flat(noisy, clean_aux=True)
            seconds["oidn-clean"] = time.perf_counter() - t
            t = time.perf_counter()
            outputs["recolour-clean"] = recolour(noisy, outputs["oidn-clean"])
            seconds["recolour-clean"] = time.perf_counter() - t + seconds["oidn-clean"]
        t = time.perf_counter()
        outputs["ranad"] = denoise_window(model, [noisy], 0, merge_gap=merge_gap, dark_radius=dark_radius,
                                          light_match=light_match).image
        seconds["ranad"] = time.perf_counter() - t
        outputs["noisy"], seconds["noisy"] = noisy, 0.0
        if stops:  # back to the reference's exposure
            outputs = {k: v * np.float32(2.0 ** -stops) if isinstance(v, np.ndarray) else exposed(v, -stops)
                       for k, v in outputs.items()}
        flats = {}
        for method in (m for m in METHODS if m in outputs):
            out = outputs[method]
            deep = not isinstance(out, np.ndarray)
            flats[method] = metrics.flat_rgb(out) if deep else out
            row = {"scene": pair.scene, "family": family, "group": group, "exposure": stops, "kind": pair.kind,
                   "spp": pair.spp, "ref_spp": ref_spp, "film": film, "sampler": sampler, "method": method,
                   **metrics.flat_scores(flat_ref, flats[method]), "light": metrics.light(flat_ref, flats[method]),
                   **(metrics.deep_scores(ref, out, z) if deep else dict.fromkeys(DEEP, math.nan)),
                   "seconds": seconds[method]}
            result.rows.append(row)
        if len(result.grid) < grid_pairs:
            edits = [metrics.composite_edit(metrics.with_depths_of(x, ref), z)
                     for x in (outputs["recolour"], outputs["ranad"], ref)]
            result.grid.append((f"{pair.scene} ({family}) {pair.kind} {pair.spp} spp {stops:+g} stops",
                                [flats[m] for m in GRID_METHODS] + [flat_ref] + edits))
        if progress:
            progress(1)
    return result


def count_pairs(dataset: str, spps=None, kinds=None, max_scenes: int | None = None) -> int:
    pairs = [p for p in find_pairs(dataset) if (not spps or p.spp in spps) and (not kinds or p.kind in kinds)]
    scenes = sorted({p.scene for p in pairs})[:max_scenes] if max_scenes else None
    return sum(1 for p in pairs if scenes is None or p.scene in scenes)


def summary(rows: list) -> list:
    """Means over scenes and kinds per (spp, method), methods in METHODS order."""
    out = []
    for spp in sorted({r["spp"] for r in rows}):
        for method in METHODS:
            sel = [r for r in rows if r["spp"] == spp and r["method"] == method]
            if not sel:
                continue
            agg = {"spp": spp, "method": method, "n": len(sel)}
            for k in (*FLAT, "light", *DEEP, "seconds"):
                vals = [r[k] for r in sel if k in r and not math.isnan(r[k])]
                agg[k] = float(np.mean(vals)) if vals else math.nan
            out.append(agg)
    return out


def _fmt(v) -> str:
    if isinstance(v, float):
        return "n/a" if math.isnan(v) else f"{v:.4f}"
    return str(v)


def markdown(rows: list, title: str = "") -> str:
    """The summary table in Markdown (lower is better everywhere but in `light`, the image's light over the
    reference's, best at 1; n/a: the method has no deep output)."""
    s = summary(rows)
    cols = ("spp", "method", "n", "flip", "smape", "dssim", "light", "bin_smape", "z_rel", "comp_flip",
            "comp_smape", "sep_smape", "sep_dssim", "seconds")
    lines = ([f"### {title}", ""] if title else []) + ["| " + " | ".join(cols) + " |",
                                                      "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in s]
    lines += reference_note(rows) + film_note(rows)
    return "\n".join(lines) + "\n"


def groups(rows: list) -> list:
    """(group, exposure, kind) keys present in rows, held-out first (the numbers to steer by)."""
    order = {"held-out": 0, "in-family": 1}
    keys = {(r.get("group", "in-family"), r.get("exposure", 0), r["kind"]) for r in rows}
    return sorted(keys, key=lambda k: (order.get(k[0], 2), k[1], k[2]))


def _spp_ratios(sel: list, noisy: bool = False) -> list:
    """Per spp of `sel`, means over its rows taken first: n, ranad's flat FLIP / OIDN's and its edit FLIP /
    OIDN+recolour's, the same against OIDN with prefiltered guides and the recolour from it (NaN where those were
    not scored), with `noisy` also OIDN's flat FLIP / the noisy input's; an spp lacking a method is left out."""
    by = {(r["spp"], r["method"]): r for r in summary(sel)}
    needs = ("noisy", "oidn", "recolour", "ranad") if noisy else ("ranad", "oidn")
    out = []
    for spp in sorted({r["spp"] for r in sel}):
        if not all((spp, m) in by for m in needs):
            continue
        ranad, oidn = by[(spp, "ranad")], by[(spp, "oidn")]
        row = {"spp": spp, "n": ranad["n"]}
        if noisy:
            row["oidn_vs_noisy"] = oidn["flip"] / by[(spp, "noisy")]["flip"]
        row["flip_vs_oidn"] = ranad["flip"] / oidn["flip"]
        row["edit_vs_recolour"] = ranad["comp_flip"] / by[(spp, "recolour")]["comp_flip"]
        clean, clean_edit = by.get((spp, "oidn-clean")), by.get((spp, "recolour-clean"))
        row["flip_vs_oidn_clean"] = ranad["flip"] / clean["flip"] if clean else math.nan
        row["edit_vs_recolour_clean"] = ranad["comp_flip"] / clean_edit["comp_flip"] if clean_edit else math.nan
        out.append(row)
    return out


def ratios(rows: list) -> list:
    """Per (group, exposure, kind, spp): ranad's flat FLIP / OIDN's and its edit FLIP / OIDN+recolour's (the
    issue's targets), means over scenes taken first."""
    out = []
    for g, e, kind in groups(rows):
        sel = [r for r in rows if (r.get("group", "in-family"), r.get("exposure", 0), r["kind"]) == (g, e, kind)]
        out += [{"group": g, "exposure": f"{e:+g}", "kind": kind, **r} for r in _spp_ratios(sel)]
    return out


def family_ratios(rows: list) -> list:
    """Per (family, spp), means over its scenes, kinds and exposures: OIDN's flat FLIP / the noisy input's (how much
    a flat denoiser helps on that family: below 1 it helps, above it loses detail the noise left), ranad's / OIDN's
    and ranad's edit FLIP / OIDN+recolour's. A set's overall ratio can hide a family where OIDN already does well
    and ranad's lead is small (a user's renders may all be of that kind)."""
    out = []
    for fam in sorted({r.get("family", "?") for r in rows}):
        sel = [r for r in rows if r.get("family", "?") == fam]
        out += [{"family": fam, **r} for r in _spp_ratios(sel, noisy=True)]
    return out


def grouped_markdown(rows: list, title: str = "") -> str:
    """One summary table per (group, exposure, kind), then the ratio tables: per group, and per family."""
    parts = [f"## {title}", ""] if title else []
    for g, e, kind in groups(rows):
        sel = [r for r in rows if (r.get("group", "in-family"), r.get("exposure", 0), r["kind"]) == (g, e, kind)]
        fams = ", ".join(sorted({r.get("family", "?") for r in sel}))
        parts.append(markdown(sel, f"{g} ({fams}), {kind}, exposure {e:+g} stops, "
                                   f"{len({r['scene'] for r in sel})} scenes"))
    rt = ratios(rows)
    if rt:
        cols = ("group", "exposure", "kind", "spp", "n", "flip_vs_oidn", "edit_vs_recolour", "flip_vs_oidn_clean",
                "edit_vs_recolour_clean")
        parts += ["### ranad / baseline (flat FLIP vs OIDN, edit FLIP vs OIDN+recolour; _clean: against OIDN with "
                  "prefiltered guides; < 1: ranad better)", "",
                  "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        parts += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in rt]
    fr = family_ratios(rows)
    if fr:
        cols = ("family", "spp", "n", "oidn_vs_noisy", "flip_vs_oidn", "edit_vs_recolour", "flip_vs_oidn_clean")
        parts += ["", "### per family (means over kinds and exposures; oidn_vs_noisy: flat OIDN's FLIP / the noisy "
                  "input's)", "", "| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
        parts += ["| " + " | ".join(_fmt(r[c]) for c in cols) + " |" for r in fr]
    parts += reference_note(rows) + film_note(rows)
    return "\n".join(parts) + "\n"


def reference_note(rows: list) -> list:
    """Markdown lines naming the sample counts whose references hold fewer than REF_SPP_RATIO times their input's
    samples (rows without a recorded reference count are left out): scores there carry the references' own
    noise, so a method that removes more noise than the reference has gains less than it should."""
    thin = sorted({(r["spp"], r["ref_spp"]) for r in rows if 0 < r.get("ref_spp", 0) < REF_SPP_RATIO * r["spp"]})
    if not thin:
        return []
    which = ", ".join(f"{spp} spp against {ref} ({ref / spp:.3g}x)" for spp, ref in thin)
    return ["", f"Reference noise: the references hold fewer than {REF_SPP_RATIO}x their inputs' samples at "
            f"{which}; the references' own noise is part of every method's score there."]


def film_note(rows: list) -> list:
    """Markdown lines naming the pixel filters other than box among the rows' frames: a wide film filter spreads
    each sample over neighbouring pixels, so their noise is correlated, which flat OIDN (trained on noise
    uncorrelated between pixels) leaves largely in place as if it were detail; ratios against OIDN and the
    recolour baseline on such frames flatter the deep denoiser (runs/generalization-s27, section 4)."""
    wide = sorted({r["film"] for r in rows if r.get("film", "box") not in ("box", "?")})
    if not wide:
        return []
    return ["", f"Film: frames filtered through {', '.join(wide)}: their noise is correlated between pixels, which "
            "flat OIDN leaves largely in place; ratios against OIDN and OIDN-then-recolour there flatter ranad "
            "(score box-filtered frames too)."]


def write_csv(rows: list, path: str, columns=COLUMNS) -> None:
    from .fileutil import atomic_output

    with atomic_output(path) as tmp, open(tmp, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        for r in rows:
            w.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})


def grid_image(result: Result, pad: int = 2) -> np.ndarray:
    """[H, W, 3] linear image: one row per shown pair, one column per entry of `grid_columns`."""
    if not result.grid:
        return np.zeros((1, 1, 3), np.float32)
    h = max(imgs[0].shape[0] for _, imgs in result.grid)
    w = max(imgs[0].shape[1] for _, imgs in result.grid)
    n = len(result.grid_columns)
    out = np.zeros((len(result.grid) * (h + pad), n * (w + pad), 3), np.float32)
    for r, (_, imgs) in enumerate(result.grid):
        for c, img in enumerate(imgs):
            out[r * (h + pad): r * (h + pad) + img.shape[0], c * (w + pad): c * (w + pad) + img.shape[1]] = img
    return out


TEMPORAL_METHODS = ("noisy", "oidn", "ranad", "ranad-xf")


def temporal_scenes(dataset: str) -> list:
    """(scene folder, manifest) of scenes with references on at least two consecutive frames."""
    from pathlib import Path

    out = []
    for manifest in sorted(Path(dataset).glob("scene_*/manifest.json")):
        m = read_manifest(manifest)
        refs = m.get("reference_frames", [m["centre_frame"]])
        if any(f + 1 in refs for f in refs):
            out.append((manifest.parent, m))
    return out


def evaluate_temporal(dataset: str, single, cross, spps=None, kinds=None, max_scenes: int | None = None,
                      window: int = 3, progress=None) -> list:
    """Per scene, kind and spp: FLIP (mean over the referenced frames) and temporal error (consecutive
    referenced frames) of the noisy input, flat OIDN, the single-frame model and the cross-frame model (each
    frame denoised with its window of up to `window` frames, shorter at the shot's ends), plus seconds per
    frame. Rows: dicts with scene, kind, spp, method, flip, temporal, seconds."""
    from .denoise import denoise_window
    from .shot import window_of
    from .exr.sequence import Frame

    scenes = temporal_scenes(dataset)[:max_scenes] if max_scenes else temporal_scenes(dataset)
    rows = []
    for folder, m in scenes:
        refs_at = sorted(m["reference_frames"])
        for kind in ("deepz", "deepoid"):
            if kinds and kind not in kinds:
                continue
            for spp in m["spp"]:
                if spps and spp not in spps:
                    continue
                seq = [Frame(str(folder / kind / f"noisy_spp{spp}.{f:04d}.exr"), f) for f in range(m["frames"])]
                if not all(os.path.isfile(f.path) for f in seq):
                    continue
                images = [read_deep(f.path) for f in seq]
                refs = [metrics.flat_rgb(read_deep(folder / kind / f"reference_spp{spp}.{f:04d}.exr"))
                        for f in refs_at]
                outs = {k: [] for k in TEMPORAL_METHODS}
                secs = dict.fromkeys(TEMPORAL_METHODS, 0.0)
                for f in refs_at:
                    img = images[f]
                    outs["noisy"].append(metrics.flat_rgb(img))
                    t = time.perf_counter()
                    outs["oidn"].append(oidn_flat(img))
                    secs["oidn"] += time.perf_counter() - t
                    t = time.perf_counter()
                    outs["ranad"].append(metrics.flat_rgb(denoise_window(single, [img], 0).image))
                    secs["ranad"] += time.perf_counter() - t
                    members, centre = window_of(seq[f], seq, window)
                    t = time.perf_counter()
                    res = denoise_window(cross, [images[x.frame] for x in members], centre)
                    secs["ranad-xf"] += time.perf_counter() - t
                    outs["ranad-xf"].append(metrics.flat_rgb(res.image))
                for method in TEMPORAL_METHODS:
                    rows.append({"scene": folder.name, "kind": kind, "spp": spp, "ref_spp": m["ref_spp"],
                                 "method": method,
                                 "flip": float(np.mean([metrics.flip(r, o) for r, o in zip(refs, outs[method])])),
                                 "temporal": metrics.temporal_error(outs[method], refs),
                                 "seconds": secs[method] / len(refs_at)})
                if progress:
                    progress(1)
    return rows


def temporal_markdown(rows: list, title: str = "") -> str:
    cols = ("spp", "method", "n", "flip", "temporal", "seconds")
    lines = ([f"### {title}", ""] if title else []) + ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for spp in sorted({r["spp"] for r in rows}):
        for method in TEMPORAL_METHODS:
            sel = [r for r in rows if r["spp"] == spp and r["method"] == method]
            if sel:
                agg = {"spp": spp, "method": method, "n": len(sel),
                       **{k: float(np.mean([r[k] for r in sel])) for k in ("flip", "temporal", "seconds")}}
                lines.append("| " + " | ".join(_fmt(agg[c]) for c in cols) + " |")
    lines += equivalent_spp_table(rows)
    floors = reference_noise_floor(rows)
    if floors:
        lines += ["", "The references' own noise puts a floor under every temporal error. Estimated from the noisy "
                  "input's, as temporal x sqrt(spp / (spp + ref_spp)): "
                  + ", ".join(f"{f:.4f} at {spp} spp" for spp, f in floors.items()) + "."]
    return "\n".join(lines) + "\n"


def reference_noise_floor(rows: list) -> dict:
    """spp -> the temporal error a perfect denoiser would still score against these references, estimated from the
    noisy input's: its frame differences differ from the reference's by the two renders' independent noise, whose
    spread goes as 1/sqrt(samples), so the reference's share is sqrt(spp / (spp + ref_spp)) of it."""
    out = {}
    for spp in sorted({r["spp"] for r in rows}):
        sel = [r for r in rows if r["spp"] == spp and r["method"] == "noisy" and "ref_spp" in r]
        if sel:
            out[spp] = float(np.mean([r["temporal"] * np.sqrt(spp / (spp + r["ref_spp"])) for r in sel]))
    return out


def _means(rows: list, method: str, key: str) -> dict:
    """spp -> mean of `key` over the rows of `method`."""
    return {spp: float(np.mean([r[key] for r in rows if r["spp"] == spp and r["method"] == method]))
            for spp in sorted({r["spp"] for r in rows if r["method"] == method})}


def equivalent_spp(curve: dict, value: float) -> tuple[float | None, str]:
    """The sample count at which a method with errors `curve` (spp -> error, measured) would score `value`: the
    first crossing of the piecewise-linear interpolation in log(spp), log(error) between measured points.
    (spp, "") when found; (None, "<" or ">") when `value` lies above the curve's first point or below all of it
    (no extrapolation)."""
    pts = sorted((s, e) for s, e in curve.items() if e > 0)
    if not pts or value <= 0:
        return None, ">"
    if value > pts[0][1]:
        return None, "<"
    if value == pts[0][1]:
        return float(pts[0][0]), ""
    for (s0, e0), (s1, e1) in zip(pts, pts[1:]):
        if value == e1:
            return float(s1), ""
        if e1 < value < e0:
            t = (np.log(value) - np.log(e0)) / (np.log(e1) - np.log(e0))
            return float(np.exp(np.log(s0) + t * (np.log(s1) - np.log(s0)))), ""
    return None, ">"


def equivalent_spp_table(rows: list) -> list:
    """Markdown lines: for each spp, the single-frame sample count whose FLIP / temporal error the cross-frame
    model matches (the paper's "cross-frame at N spp matches single-frame at 2-4x N"), interpolated between the
    single-frame rows; empty with fewer than two single-frame spp."""
    if len({r["spp"] for r in rows if r["method"] == "ranad"}) < 2:
        return []

    def cell(curve, value, spp):
        eq, side = equivalent_spp(curve, value)
        if eq is None:
            bound = max(curve) if side == ">" else min(curve)
            return f"{side} {bound} spp ({side} {bound / spp:.3g}x)"
        return f"{eq:.3g} spp ({eq / spp:.2f}x)"

    lines = ["", "Cross-frame at N spp against the single-frame model at more samples (log-log interpolation between "
             "the single-frame rows; no extrapolation):", "",
             "| spp | ranad-xf's flip = single-frame at | ranad-xf's temporal = single-frame at |", "|---|---|---|"]
    for spp, xf_flip in _means(rows, "ranad-xf", "flip").items():
        xf_temporal = _means(rows, "ranad-xf", "temporal")[spp]
        lines.append(f"| {spp} | {cell(_means(rows, 'ranad', 'flip'), xf_flip, spp)} | "
                     f"{cell(_means(rows, 'ranad', 'temporal'), xf_temporal, spp)} |")
    return lines
