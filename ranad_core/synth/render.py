"""One scene's frames: trace samples, add motion vectors, bin them, and build the deep images ranad writes.

Channel convention (also what `ranad denoise` expects by default; README "Synthetic data"):
``R G B A`` (half, premultiplied, EXR alpha), ``Z ZBack`` (float), ``diffuse.* specular.* emission.*`` (half,
premultiplied like RGB; they sum to RGB), ``lg_<group>.R/G/B`` (half, premultiplied; they sum to RGB),
``albedo.R/G/B`` and ``N.X/Y/Z`` (half, per-bin means), ``P.X/Y/Z`` (float, world position), ``coverage``
(half, the bin's share of the pixel's samples), ``motion_prev.X/Y`` and ``motion_next.X/Y`` (float, pixels to the
bin's position in the previous/next frame; 0 where that frame does not exist), and ``id`` (uint, deep-OID).
"""

from __future__ import annotations

import math

import numpy as np

from ..deep import DeepImage
from .binning import Z_GAP_REL, BinLayout, accumulate, assign_to_layout, bin_values, layout_from_samples
from .pixel_filter import copies_per_sample, splat
from .scene import SceneSpec, look_at, pose_at
from .trace import REFERENCE_FIELDS, load_frame, shutter_offsets, trace_range

CHUNK = 1 << 19   # samples traced per call (bounds the memory of one reference frame)


def project(spec: SceneSpec, frame: int, points: np.ndarray) -> np.ndarray:
    """Film coordinates (x, y in pixels, y down) of world points seen by the camera of `frame` (pinhole model)."""
    cam = look_at(spec.camera.origin[frame], spec.camera.target[frame])
    local = (points - cam[:3, 3]) @ cam[:3, :3]  # camera space: x left, y up, z forward
    tan_x = math.tan(math.radians(spec.camera.fov) / 2)
    tan_y = tan_x * spec.height / spec.width
    z = np.maximum(local[:, 2], 1e-6)
    x = (1 - local[:, 0] / (z * tan_x)) * 0.5 * spec.width
    y = (1 - local[:, 1] / (z * tan_y)) * 0.5 * spec.height
    return np.stack([x, y], 1)


def add_motion(spec: SceneSpec, frame: int, s: dict) -> None:
    """Per-sample motion vectors to the previous and next frame from the hit object's transforms. A motion-blurred
    sample (`slot`) is first carried to where its point is at the frame's own instant (the shutter's centre)."""
    pos = s["position"].astype(np.float64)
    if "slot" in s:
        pos = pos.copy()
        objects = {o.id: o for o in spec.objects}
        for k, dt in enumerate(shutter_offsets(spec)):
            for oid in np.unique(s["obj"][s["hit"] & (s["slot"] == k)]):
                o = objects.get(int(oid))
                if o is None:   # media do not move
                    continue
                sel = s["hit"] & (s["slot"] == k) & (s["obj"] == oid)
                m = pose_at(spec, o, frame, 0.0) @ np.linalg.inv(pose_at(spec, o, frame, dt))
                pos[sel] = pos[sel] @ m[:3, :3].T + m[:3, 3]
    here = project(spec, frame, pos)
    mats = {o.id: [np.asarray(m) for m in o.transforms] for o in spec.objects}
    mats.update({m.id: [np.eye(4)] * spec.frames for m in spec.media})   # media do not move
    for name, other in (("motion_prev", frame - 1), ("motion_next", frame + 1)):
        mv = np.zeros((len(pos), 2), np.float32)
        if 0 <= other < spec.frames:
            moved = pos.copy()
            for oid in np.unique(s["obj"][s["hit"]]):
                sel = s["hit"] & (s["obj"] == oid)
                m = mats[int(oid)][other] @ np.linalg.inv(mats[int(oid)][frame])
                moved[sel] = pos[sel] @ m[:3, :3].T + m[:3, 3]
            mv = (project(spec, other, moved) - here).astype(np.float32)
            mv[~s["hit"]] = 0
        s[name] = mv


def trace_all(fs, spp: int, seed: int, sampler: str = "independent", through_specular: bool = False) -> dict:
    n = fs.spec.width * fs.spec.height * spp
    parts = [trace_range(fs, spp, seed, start, min(CHUNK, n - start), sampler=sampler,
                         through_specular=through_specular) for start in range(0, n, CHUNK)]
    return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}


def deep_image(spec: SceneSpec, lay: BinLayout, vals: dict, with_motion: bool) -> DeepImage:
    """The DeepImage of a layout and its per-bin values, in the channel convention above."""
    cols, types = {}, {}

    def put(name, data, typ="half"):
        cols[name] = np.asarray(data, np.float32)
        types[name] = typ

    total = vals["diffuse"] + vals["specular"] + vals["emission"]
    for i, c in enumerate("RGB"):
        put(c, total[:, i])
    put("A", vals["A"])
    put("Z", vals["Z"], "float")
    put("ZBack", vals["ZBack"], "float")
    for layer in ("diffuse", "specular", "emission"):
        for i, c in enumerate("RGB"):
            put(f"{layer}.{c}", vals[layer][:, i])
    for g, gname in enumerate(spec.light_groups):
        for i, c in enumerate("RGB"):
            put(f"lg_{gname}.{c}", vals["groups"][:, g * 3 + i])
    if "albedo" in vals:  # noisy images carry the auxiliary features; references only what is compared
        for i, c in enumerate("RGB"):
            put(f"albedo.{c}", vals["albedo"][:, i])
        for i, c in enumerate("XYZ"):
            put(f"N.{c}", vals["normal"][:, i])
        for i, c in enumerate("XYZ"):
            put(f"P.{c}", vals["position"][:, i], "float")
    put("coverage", vals["coverage"])
    if with_motion:
        for name in ("motion_prev", "motion_next"):
            for i, c in enumerate("XY"):
                put(f"{name}.{c}", vals[name][:, i], "float")
    ids = {}
    if lay.kind == "oid":
        ids["id"] = lay.obj.astype(np.uint32)
        types["id"] = "uint"
    names = list(cols)
    values = np.stack([cols[n] for n in names], 1) if names else np.zeros((0, 0), np.float32)
    return DeepImage(values=values, offsets=lay.offsets, channels=names, ids=ids,
                     data_window=(0, 0, spec.width - 1, spec.height - 1),
                     display_window=(0, 0, spec.width - 1, spec.height - 1), channel_types=types)


def noisy_samples(spec: SceneSpec, frame: int, spp: int, seed: int, fs=None, sampler: str = "independent",
                  through_specular: bool = False, pixel_filter: tuple = ("box", 1.0)) -> dict:
    """One noisy frame's samples with their motion vectors (binned by bin_noisy, once per deep kind), splatted
    by `pixel_filter` (name, width in pixels; pixel_filter.py)."""
    s = trace_all(fs or load_frame(spec, frame), spp, seed, sampler, through_specular)
    add_motion(spec, frame, s)
    return splat(s, spec.width, spec.height, *pixel_filter)


def bin_noisy(spec: SceneSpec, s: dict, spp: int, kind: str, gap_rel: float = Z_GAP_REL):
    """(DeepImage, layout) of noisy samples as a deep-Z ("z") or deep-OID ("oid") image (`gap_rel`: the deep-Z
    split rule, binning.layout_from_samples)."""
    lay, sample_bin = layout_from_samples(s, spec.width, spec.height, kind, gap_rel)
    vals = bin_values(accumulate(s, sample_bin, len(lay.pixel), npixels=spec.width * spec.height), lay, spp)
    return deep_image(spec, lay, vals, True), lay


def render_noisy(spec: SceneSpec, frame: int, spp: int, kind: str, seed: int, fs=None):
    """(DeepImage, layout, samples) of one noisy frame."""
    s = noisy_samples(spec, frame, spp, seed, fs)
    img, lay = bin_noisy(spec, s, spp, kind)
    return img, lay, s


def render_reference(spec: SceneSpec, frame: int, ref_spp: int, layouts: list, seed: int, fs=None,
                     pixel_filter: tuple = ("box", 1.0)):
    """References of one frame binned into each of `layouts` (one tracing pass): [(DeepImage, unbinned share)].
    `pixel_filter` as for the noisy frames (the reference is what the same film makes of many samples)."""
    fs = fs or load_frame(spec, frame)
    n = spec.width * spec.height * ref_spp
    # a filter's copies are binned `chunk` samples at a time (their memory); the samples are traced in calls of
    # about CHUNK (a trace call's fixed cost is the loop's recording: 16-25x fewer calls through a Gaussian
    # filter), each sample with the random numbers of its `chunk`-sample call, as when every chunk was traced alone
    chunk = max(1, CHUNK // copies_per_sample(*pixel_filter))
    calls = chunk * max(1, CHUNK // chunk)   # whole chunks per trace call
    accs = [None] * len(layouts)
    for big in range(0, n, calls):
        traced = trace_range(fs, ref_spp, seed, big, min(calls, n - big), fields=REFERENCE_FIELDS,
                             chunk=chunk if chunk < calls else None)
        for start in range(big, min(big + calls, n), chunk):
            part = slice(start - big, min(start + chunk, n) - big)
            s = splat({k: v[part] for k, v in traced.items()}, spec.width, spec.height, *pixel_filter)
            for i, lay in enumerate(layouts):
                accs[i] = accumulate(s, assign_to_layout(s, lay), len(lay.pixel), accs[i], spec.width * spec.height)
    out = []
    for lay, acc in zip(layouts, accs):
        vals = bin_values(acc, lay, ref_spp)
        out.append((deep_image(spec, lay, vals, False), vals["unbinned_energy"]))
    return out
