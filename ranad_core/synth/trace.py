"""The path tracer behind `ranad synth`: one Dr.Jit loop (Mitsuba 3, ``llvm_ad_rgb``) returning every sample.

For each camera sample it returns what deep binning needs: the pixel and sub-pixel position; the FIRST STOP
(the first surface the sample stops at: view depth, distance, object id, whether anything was hit, albedo,
shading normal, world position); and its radiance split three ways and by light group:

* emission seen directly at the first stop;
* diffuse and specular: everything else, split at the first stop by lobe. Next-event estimation there evaluates
  the BSDF's diffuse and glossy parts separately; the BSDF-sampled continuation is weighted by
  f_diffuse/pdf and f_glossy/pdf (one sample, both parts), so each part is unbiased and they sum to the total;
* per light group: every contribution (emission hit or light sample) is added to the group of its emitter, so
  the groups sum to diffuse + specular + emission.

Semi-transparent surfaces: at every intersection a sample first decides whether it passes through (probability
1 - opacity, times an alpha cutout for foliage cards), before any shading, so all of a sample's radiance
belongs to the surface where it stops. Shadow rays treat every surface as opaque (panes cast full shadows);
noisy and reference renders share that rule. Paths are traced with next-event estimation and MIS up to
`max_depth` bounces. Camera rays that miss everything leave their pixel empty (deep renders hold no sky); a path
that leaves the scene after its first stop collects the environment light where the scene has one (scene.Sky),
with MIS against its importance-sampled next-event estimate like any other emitter.

Participating media (scene.Medium: homogeneous, in analytic ellipsoids, no Mitsuba shapes): along every segment a
free-flight distance is drawn per medium (exponential in its extinction); the nearest one before the surface is a
scatter event: isotropic phase function, next-event estimation with the media's transmittance on the shadow ray
(surface next-event estimates get it too), and the throughput times the medium's albedo. A sample whose first
stop is a scatter event is a volume sample (`volume`), with the depths where its ray enters and leaves the medium
(`zin`, `zout`: its bin's Z and ZBack); its radiance is all diffuse. Scenes without media draw no extra random
numbers, so their samples are as before.

Motion blur (SceneSpec.shutter > 0): the frame's scene is loaded at TIME_SLOTS instants of the shutter and each
sample is traced in the one its index picks (time_slot), with the random numbers it would have had anyway.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from . import sobol
from .mitsuba_env import mitsuba
from .scene import CUTOUT_FENCE, CUTOUT_LEAF, SceneSpec, camera_at, convert_transforms, mitsuba_dict

MAX_PASS_THROUGH = 16   # surfaces a sample may pass through before it is stopped at the next one
MAX_GROUPS = 3          # light groups the loop carries
SAMPLERS = ("independent", "stratified", "sobol")   # noisy frames' samplers (trace)
# the Sobol sampler's dimension pairs of one loop iteration, by draw (one pair each; media's free flights after)
SLOT_PASS, SLOT_PICK, SLOT_LIGHT, SLOT_LOBE, SLOT_BSDF, SLOT_VOL_PICK, SLOT_VOL_LIGHT, SLOT_VOL_DIR = range(8)
SLOTS = 8
TIME_SLOTS = 8          # motion blur: instants the shutter interval is sampled at (one Mitsuba scene each)


@dataclass
class FrameScene:
    """A loaded Mitsuba scene of one frame plus the tables that map Mitsuba's shapes to ranad's objects."""
    mi_scene: object
    spec: SceneSpec
    frame: int
    object_of_shape: np.ndarray   # registry id -> object id (0: none)
    opacity_of_shape: np.ndarray  # registry id -> opacity
    cutout_of_shape: np.ndarray   # registry id -> cutout pattern
    group_of_emitter: np.ndarray  # registry id -> light group (-1: none)
    cam_origin: np.ndarray
    cam_forward: np.ndarray
    emitters: list                # in object-id order (Mitsuba's own emitter order changes between loads)
    slots: list = field(default_factory=list)   # motion blur: the scene at each of the shutter's instants


def shutter_offsets(spec: SceneSpec) -> list:
    """The instants (frames from the frame's own) motion blur samples: the centres of TIME_SLOTS equal parts of
    the shutter interval, which is centred on the frame."""
    return [((k + 0.5) / TIME_SLOTS - 0.5) * spec.shutter for k in range(TIME_SLOTS)]


def time_slot(indices: np.ndarray, spp: int) -> np.ndarray:
    """Each sample's instant: a pixel's samples take consecutive slots from an offset of their own, so every
    pixel's samples are spread over the shutter (stratified in time) and neighbours start at different instants."""
    return (indices % spp + 3 * (indices // spp)) % TIME_SLOTS


def load_frame(spec: SceneSpec, frame: int, dt: float = 0.0) -> FrameScene:
    mi = mitsuba()
    import drjit as dr

    scene = mi.load_dict(convert_transforms(mitsuba_dict(spec, frame, dt)))
    shapes = scene.shapes()
    regs = [int(dr.reinterpret_array(mi.UInt32, mi.ShapePtr(s))[0]) for s in shapes]
    size = max(regs + [0]) + 1
    obj = np.zeros(size, np.uint32)
    opac = np.ones(size, np.float32)
    cut = np.zeros(size, np.uint32)
    group_size = 1
    em_groups = {}
    emitters = []
    for s, reg in zip(shapes, regs):
        o = spec.object(int(s.id()[3:]))
        obj[reg], opac[reg], cut[reg] = o.id, o.opacity, o.cutout
        if s.emitter() is not None:
            em_reg = int(dr.reinterpret_array(mi.UInt32, mi.EmitterPtr(s.emitter()))[0])
            em_groups[em_reg] = o.light_group
            group_size = max(group_size, em_reg + 1)
            emitters.append((o.id, s.emitter()))
    groups = np.full(group_size, -1, np.int32)
    env = scene.environment()
    if env is not None:   # the sky: after the shapes' emitters in the next-event list, in its light group
        env_reg = int(dr.reinterpret_array(mi.UInt32, mi.EmitterPtr(env))[0])
        em_groups[env_reg] = spec.sky.light_group
        groups = np.full(max(group_size, env_reg + 1), -1, np.int32)
    for reg, g in em_groups.items():
        groups[reg] = g
    cam = camera_at(spec, frame, dt)
    fs = FrameScene(scene, spec, frame, obj, opac, cut, groups, cam[:3, 3].copy(), cam[:3, 2].copy(),
                    [e for _, e in sorted(emitters, key=lambda t: t[0])] + ([env] if env is not None else []))
    if spec.shutter > 0 and dt == 0:
        fs.slots = [load_frame(spec, frame, t) for t in shutter_offsets(spec)]
    return fs


def trace_range(fs: FrameScene, spp: int, seed: int, start: int, count: int, **kw) -> dict:
    """trace() of samples start..start+count-1, each at its own instant of the shutter where the scene has motion
    blur (the samples of each instant traced in its scene, then put back in order; `slot` says which)."""
    if not fs.slots:
        return trace(fs, spp, seed, start, count, **kw)
    idx = np.arange(start, start + count, dtype=np.int64)
    slot = time_slot(idx, spp)
    out = None
    for k, fk in enumerate(fs.slots):
        sel = np.flatnonzero(slot == k)
        if len(sel) == 0:
            continue
        part = trace(fk, spp, seed, start, len(sel), **{**kw, "indices": idx[sel]})
        if out is None:
            out = {name: np.zeros((count,) + v.shape[1:], v.dtype) for name, v in part.items()}
        for name, v in part.items():
            out[name][sel] = v
    out["slot"] = slot
    return out


REFERENCE_FIELDS = ("diffuse", "specular", "emission", "groups", "hit", "obj", "z", "volume")


def trace(fs: FrameScene, spp: int, seed: int, start: int, count: int, max_depth: int = 4,
          fields: tuple | None = None, sampler: str = "independent", through_specular: bool = False,
          indices: np.ndarray | None = None, chunk: int | None = None) -> dict:
    """Samples start..start+count-1 of the frame (sample i belongs to pixel i // spp), or the samples `indices` of
    that range, as numpy arrays, with the random numbers they get in the whole range, or with `chunk`, in the
    calls of `chunk` samples from `start` that cover it (one call then does the work of many, as before).

    fields: the outputs to return besides pixel/sx/sy (default: all); references need only REFERENCE_FIELDS.
    sampler: "independent" (PCG32 numbers); "stratified": the pixel and lens positions jittered in a pixel's n x n
    strata (n = floor(sqrt(spp)), the lens strata in another order than the pixel's), as production renderers'
    stratified and low-discrepancy samplers make coverage and defocus far less noisy than independent samples do,
    the rest independent; "sobol": every dimension, the light and BSDF choices of each bounce too, from shuffled,
    Owen-scrambled Sobol pairs per pixel (sobol.py), as production renderers' low-discrepancy samplers draw them.
    through_specular: albedo and normal where a path starting at a smooth (delta) surface first reaches a surface
    with a non-delta lobe, the albedo times the delta bounces' throughput (what OIDN asks of its guides, and what
    renderers' denoising AOVs write for glass and mirrors); default: the first surface's own (a glass's is flat).
    Radiance and every random number are the same either way.
    """
    mi = mitsuba()
    import drjit as dr

    spec = fs.spec
    W, H = spec.width, spec.height
    state = seed * 2654435761 + 12345
    if indices is None and chunk is None:
        idx = dr.arange(mi.UInt32, count) + dr.opaque(mi.UInt32, start)
        # streams differ per sample index and per seed; opaque seeds keep the compiled kernel reusable
        rng = mi.PCG32(count, initstate=dr.opaque(mi.UInt64, state), initseq=mi.UInt64(idx))
    else:
        # PCG32 adds each lane's number to its state and stream; take it off again, so that sample i gets the
        # generator it gets in the contiguous call from `start` (or from its chunk's start): the same random
        # numbers, whatever the subset and however many calls
        ind = np.arange(start, start + count, dtype=np.int64) if indices is None else np.asarray(indices, np.int64)
        count = len(ind)
        first = start if chunk is None else start + (ind - start) // chunk * chunk
        lane = np.arange(count, dtype=np.int64)
        idx = mi.UInt32(ind.astype(np.uint32))
        offset = (ind - first - lane).astype(np.uint64)   # >= 0: a sample's index is at least its lane's
        rng = mi.PCG32(count, initstate=mi.UInt64(np.uint64(state % 2 ** 64) + offset),
                       initseq=mi.UInt64((2 * ind - first - lane).astype(np.uint64)))
    pix = idx // dr.opaque(mi.UInt32, spp)
    sx, sy = rng.next_float32(), rng.next_float32()
    lx, ly = rng.next_float32(), rng.next_float32()
    if sampler not in SAMPLERS:
        raise ValueError(f"unknown sampler {sampler!r} (one of {', '.join(SAMPLERS)})")
    sob = None
    if sampler == "sobol":
        j = idx % dr.opaque(mi.UInt32, spp)
        mask = dr.opaque(mi.UInt32, sobol.index_mask(spp))
        pseed = sobol.pixel_seed(pix, seed)
        sob = (j, pseed, mask)
        pair = lambda p: sobol.draw_pair(j, pseed, mi.UInt32(p), mask, dr.select, mi.UInt32(0))  # noqa: E731
        (sx, sy), (lx, ly) = [[sobol.to_unit(v, mi.Float) for v in pair(p)] for p in (0, 1)]
    n = int(math.isqrt(spp))
    if sampler == "stratified" and n > 1:
        j = idx % dr.opaque(mi.UInt32, spp)
        inside = j < n * n                  # samples beyond the n x n strata stay independent
        jl = (j * 7 + 3) % (n * n)          # the lens visits the strata in another order (7 is prime to n * n
        jl = dr.select(inside, jl, j)       # unless n is a multiple of 7)
        inv = 1.0 / n
        sx = dr.select(inside, (mi.Float(j % n) + sx) * inv, sx)
        sy = dr.select(inside, (mi.Float(j // n) + sy) * inv, sy)
        lx = dr.select(inside, (mi.Float(jl % n) + lx) * inv, lx)
        ly = dr.select(inside, (mi.Float(jl // n) + ly) * inv, ly)
    px, py = mi.Float(pix % W) + sx, mi.Float(pix // W) + sy
    sensor = fs.mi_scene.sensors()[0]
    ray, _ = sensor.sample_ray(0.0, 0.5, mi.Point2f(px / W, py / H), mi.Point2f(lx, ly))
    tables = (mi.UInt32(fs.object_of_shape), mi.Float(fs.opacity_of_shape), mi.UInt32(fs.cutout_of_shape),
              mi.Int32(fs.group_of_emitter))
    out = _loop(mi, dr, fs.mi_scene, mi.EmitterPtr(fs.emitters), len(fs.emitters), ray, rng, tables,
                mi.Point3f(*map(float, fs.cam_origin)), mi.Vector3f(*map(float, fs.cam_forward)), max_depth,
                through_specular, spec.media, sob)
    dr.eval(out)
    res = {"pixel": np.asarray(pix, dtype=np.int64), "sx": np.asarray(sx), "sy": np.asarray(sy)}
    want = set(fields or out)
    if "groups" in want:
        want |= {f"group{g}" for g in range(len(spec.light_groups))}
    for name, val in out.items():
        if name in want:
            a = np.asarray(val)
            res[name] = a.T.copy() if a.ndim == 2 and a.shape[0] == 3 else a
    res["groups"] = np.stack([res.pop(f"group{g}") for g in range(len(spec.light_groups))], axis=1)
    res["hit"] = res["hit"].astype(bool)
    if "volume" in res:
        res["volume"] = res["volume"].astype(bool)
    return res


def _leaf_alpha(mi, dr, uv):
    """A foliage-card cutout on the card's uv square: an ellipse cut by gaps between leaflets."""
    u, v = uv.x, uv.y
    ell = dr.square((u - 0.5) / 0.47) + dr.square((v - 0.5) / 0.3) < 1.0
    gaps = (dr.abs(v - 0.5) < 0.03) | ((u * 6.0 - dr.floor(u * 6.0)) < 0.12)
    return dr.select(ell & ~gaps, 1.0, 0.0)


def _fence_alpha(mi, dr, uv):
    """A fence's cutout: vertical and horizontal bars (a wire grid) on the card's uv square."""
    fu, fv = uv.x * 9.0 - dr.floor(uv.x * 9.0), uv.y * 6.0 - dr.floor(uv.y * 6.0)
    return dr.select((fu < 0.16) | (fv < 0.1), 1.0, 0.0)


def _mis(a, b):
    import drjit as dr

    a2 = dr.square(a)
    return dr.detach(dr.select(a > 0, a2 / (a2 + dr.square(b)), 0.0))


def _medium_span(mi, dr, o, d, med):
    """(hit, t0, t1): where the ray o + t d (d unit) is inside `med`'s ellipsoid, t0 clamped to >= 0."""
    c, r = mi.Vector3f(*map(float, med.centre)), mi.Vector3f(*map(float, med.radii))
    lo, ld = (o - c) / r, d / r
    a, b, cc = dr.dot(ld, ld), dr.dot(lo, ld), dr.dot(lo, lo) - 1.0
    disc = b * b - a * cc
    sq = dr.sqrt(dr.maximum(disc, 0.0))
    t0, t1 = dr.maximum((-b - sq) / a, 0.0), (-b + sq) / a
    return (disc > 0) & (t1 > t0), t0, t1


def _transmittance(mi, dr, media, o, d, length):
    """exp(-optical depth) of the media along o + t d, 0 <= t <= length (shadow rays)."""
    tr = mi.Float(1.0)
    for med in media:
        hit, t0, t1 = _medium_span(mi, dr, o, d, med)
        inside = dr.maximum(dr.minimum(t1, length) - t0, 0.0)
        tr *= dr.select(hit, dr.exp(-float(med.sigma_t) * inside), 1.0)
    return tr


def _loop(mi, dr, scene, emitters, n_emitters, ray, rng, tables, cam_o, cam_f, max_depth, through=False,
          media=(), sob=None):
    """The path loop. Its random numbers come from Draws (sobol.py): the PCG32 stream `rng` in call order, or with
    `sob` = (index in the pixel, pixel seed, mask) Sobol pairs by slot (SLOT_*; media draws after them), a
    counter in the loop state numbering the iterations."""
    obj_t, opac_t, cut_t, grp_t = tables
    n = dr.width(ray.o)
    black = mi.Color3f(0.0)
    ctx = mi.BSDFContext()
    ctx_d = mi.BSDFContext()
    ctx_d.type_mask = mi.BSDFFlags.Diffuse
    ctx_s = mi.BSDFContext()
    ctx_s.type_mask = mi.BSDFFlags.Glossy | mi.BSDFFlags.Delta
    state = dict(
        ray=mi.Ray3f(ray), active=mi.Bool(True), first=mi.Bool(True), depth=mi.UInt32(0), passes=mi.UInt32(0),
        beta_d=mi.Color3f(0.0), beta_s=mi.Color3f(0.0), prev_si=dr.zeros(mi.SurfaceInteraction3f, n),
        prev_pdf=mi.Float(1.0), prev_delta=mi.Bool(True), dist=mi.Float(0.0),
        diffuse=mi.Color3f(0.0), specular=mi.Color3f(0.0), emission=mi.Color3f(0.0),
        group0=mi.Color3f(0.0), group1=mi.Color3f(0.0), group2=mi.Color3f(0.0),
        hit=mi.Bool(False), obj=mi.UInt32(0), z=mi.Float(0.0), distance=mi.Float(0.0), albedo=mi.Color3f(0.0),
        normal=mi.Vector3f(0.0), position=mi.Point3f(0.0), rng=rng,
        gopen=mi.Bool(False), gbeta=mi.Color3f(1.0),   # through-specular guides: still looking, and the throughput
        volume=mi.Bool(False), zin=mi.Float(0.0), zout=mi.Float(0.0))
    pairs = SLOTS + len(media)
    if sob is not None:
        state["sob_it"] = mi.UInt32(0)

    def draws(st):
        if sob is None:
            return sobol.Draws(mi, dr, st["rng"])
        j, pseed, mask = sob
        return sobol.Draws(mi, dr, None, (j, pseed, st["sob_it"], mask), pairs)

    def add_group(st, g, value, mask):
        for k in range(MAX_GROUPS):
            st[f"group{k}"] = dr.select(mask & (g == k), st[f"group{k}"] + value, st[f"group{k}"])

    def body(st):
        r = draws(st)
        active = st["active"]
        si = scene.ray_intersect(st["ray"], mi.RayFlags.All, st["depth"] == 0, active)
        ray_o, ray_d = st["ray"].o, st["ray"].d
        scatter = mi.Bool(False)
        if media:   # free flight through each medium; the nearest scatter before the surface wins
            t_end = dr.select(si.is_valid(), si.t, dr.inf)
            t_sc = mi.Float(dr.inf)
            m_id, m_alb, m_in, m_out = mi.UInt32(0), mi.Color3f(0.0), mi.Float(0.0), mi.Float(0.0)
            for m, med in enumerate(media):
                hit_m, t0, t1 = _medium_span(mi, dr, ray_o, ray_d, med)
                t_m = t0 - dr.log(1.0 - r.u1(SLOTS + m)) / float(med.sigma_t)
                here = active & hit_m & (t_m < dr.minimum(t1, t_end)) & (t_m < t_sc)
                t_sc = dr.select(here, t_m, t_sc)
                m_id = dr.select(here, mi.UInt32(int(med.id)), m_id)
                m_alb = dr.select(here, mi.Color3f(*map(float, med.albedo)), m_alb)
                m_in = dr.select(here, t0, m_in)
                m_out = dr.select(here, dr.minimum(t1, t_end), m_out)
            scatter = active & dr.isfinite(t_sc)
        valid = active & si.is_valid() & ~scatter
        reg = dr.reinterpret_array(mi.UInt32, si.shape)
        alpha = dr.gather(mi.Float, opac_t, reg, valid)
        cut = dr.gather(mi.UInt32, cut_t, reg, valid)
        alpha = dr.select(cut == CUTOUT_LEAF, alpha * _leaf_alpha(mi, dr, si.uv), alpha)
        alpha = dr.select(cut == CUTOUT_FENCE, alpha * _fence_alpha(mi, dr, si.uv), alpha)
        u = r.u1(SLOT_PASS)
        passes = valid & (u >= alpha) & (st["passes"] < MAX_PASS_THROUGH)
        shade = valid & ~passes
        first_now = shade & st["first"]
        later = shade & ~st["first"]
        st["dist"] = dr.select(passes & st["first"], st["dist"] + si.t, st["dist"])

        # emitters hit by the path; a path that leaves the scene after its first stop sees the environment (an
        # invalid interaction's emitter), a camera ray that misses sees nothing
        lit = shade | (active & ~si.is_valid() & ~scatter & ~st["first"])
        later_lit = lit & ~st["first"]
        em = si.emitter(scene, lit)
        em_reg = dr.reinterpret_array(mi.UInt32, em)
        has_em = lit & (em_reg != 0)
        le = em.eval(si, has_em)
        ds_hit = mi.DirectionSample3f(scene, si, st["prev_si"])
        em_pdf = scene.pdf_emitter_direction(st["prev_si"], ds_hit, has_em & ~st["prev_delta"])
        w_hit = dr.select(st["prev_delta"], 1.0, _mis(st["prev_pdf"], em_pdf))
        g_hit = dr.gather(mi.Int32, grp_t, em_reg, has_em)
        st["emission"] = dr.select(first_now & has_em, st["emission"] + le, st["emission"])
        c_d, c_s = st["beta_d"] * le * w_hit, st["beta_s"] * le * w_hit
        st["diffuse"] = dr.select(later_lit & has_em, st["diffuse"] + c_d, st["diffuse"])
        st["specular"] = dr.select(later_lit & has_em, st["specular"] + c_s, st["specular"])
        add_group(st, g_hit, dr.select(first_now, le, c_d + c_s), has_em)

        # first-stop attributes
        bsdf = si.bsdf(st["ray"])
        st["hit"] = st["hit"] | first_now
        st["obj"] = dr.select(first_now, dr.gather(mi.UInt32, obj_t, reg, first_now), st["obj"])
        st["z"] = dr.select(first_now, dr.dot(si.p - cam_o, cam_f), st["z"])
        st["distance"] = dr.select(first_now, st["dist"] + si.t, st["distance"])
        st["albedo"] = dr.select(first_now, bsdf.eval_diffuse_reflectance(si, first_now), st["albedo"])
        st["normal"] = dr.select(first_now, si.sh_frame.n, st["normal"])
        st["position"] = dr.select(first_now, si.p, st["position"])
        rough = mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)   # a lobe that is not a delta
        if through:   # the first surface behind smooth glass or mirrors gives the guides
            land = later & st["gopen"] & rough
            st["albedo"] = dr.select(land, st["gbeta"] * bsdf.eval_diffuse_reflectance(si, land), st["albedo"])
            st["normal"] = dr.select(land, si.sh_frame.n, st["normal"])
            st["gopen"] = st["gopen"] & ~land

        # next-event estimation (light sampling), split by lobe at the first stop
        nee = shade & mi.has_flag(bsdf.flags(), mi.BSDFFlags.Smooth)
        # (the emitter is picked here, uniformly in object-id order, rather than by scene.sample_emitter_direction,
        # whose emitter order, and so the sample drawn for a given random number, changes between loads)
        pick = dr.minimum(mi.UInt32(r.u1(SLOT_PICK) * n_emitters), n_emitters - 1)
        emitter = dr.gather(mi.EmitterPtr, emitters, pick, nee)
        ds, em_w = emitter.sample_direction(si, r.u2(SLOT_LIGHT), nee)
        nee &= ds.pdf > 0
        visible = ~scene.ray_test(si.spawn_ray_to(ds.p), nee)
        em_w = dr.select(nee & visible, em_w * n_emitters, 0.0)
        if media:
            em_w *= _transmittance(mi, dr, media, si.p, ds.d, ds.dist)
        ds.pdf /= n_emitters
        wo = si.to_local(ds.d)
        f_all, pdf_b = bsdf.eval_pdf(ctx, si, wo, nee)
        w_nee = dr.select(ds.delta, 1.0, _mis(ds.pdf, pdf_b))
        f_d = bsdf.eval(ctx_d, si, wo, nee & st["first"])
        f_s = bsdf.eval(ctx_s, si, wo, nee & st["first"])
        n_d = dr.select(st["first"], f_d, st["beta_d"] * f_all) * em_w * w_nee
        n_s = dr.select(st["first"], f_s, st["beta_s"] * f_all) * em_w * w_nee
        st["diffuse"] = dr.select(nee, st["diffuse"] + n_d, st["diffuse"])
        st["specular"] = dr.select(nee, st["specular"] + n_s, st["specular"])
        em_reg_nee = dr.reinterpret_array(mi.UInt32, ds.emitter)
        add_group(st, dr.gather(mi.Int32, grp_t, em_reg_nee, nee), n_d + n_s, nee & (em_reg_nee != 0))

        # continue by sampling the BSDF (the continuation split the same way at the first stop)
        lobe = r.u1(SLOT_LOBE)
        bs, w = bsdf.sample(ctx, si, lobe, r.u2(SLOT_BSDF), shade)
        delta = mi.has_flag(bs.sampled_type, mi.BSDFFlags.Delta)
        ok = shade & (bs.pdf > 0)
        if through:
            follow = shade & ~rough & delta & ok & (first_now | st["gopen"])
            st["gbeta"] = dr.select(follow, st["gbeta"] * w, st["gbeta"])
            st["gopen"] = dr.select(shade, follow, st["gopen"])   # passing through a cutout keeps looking
        bd = dr.select(delta, black, bsdf.eval(ctx_d, si, bs.wo, first_now & ~delta) / bs.pdf)
        bsp = dr.select(delta, w, bsdf.eval(ctx_s, si, bs.wo, first_now & ~delta) / bs.pdf)
        st["beta_d"] = dr.select(first_now, bd, dr.select(later, st["beta_d"] * w, st["beta_d"]))
        st["beta_s"] = dr.select(first_now, bsp, dr.select(later, st["beta_s"] * w, st["beta_s"]))
        new_ray = si.spawn_ray(si.to_world(bs.wo))
        pass_ray = si.spawn_ray(st["ray"].d)
        st["ray"] = dr.select(shade, new_ray, dr.select(passes, pass_ray, st["ray"]))
        st["prev_si"] = dr.select(shade, si, st["prev_si"])
        st["prev_pdf"] = dr.select(shade, bs.pdf, st["prev_pdf"])
        st["prev_delta"] = dr.select(shade, delta, st["prev_delta"])
        if media:
            _scatter_event(st, r, scatter, t_sc, ray_o + ray_d * t_sc, m_id, m_alb, ray_o + ray_d * m_in,
                           ray_o + ray_d * m_out)
        st["passes"] = dr.select(passes, st["passes"] + 1, st["passes"])
        st["depth"] = dr.select(shade | scatter, st["depth"] + 1, st["depth"])
        st["first"] = st["first"] & ~shade & ~scatter
        alive = dr.max(st["beta_d"] + st["beta_s"]) > 0
        st["active"] = (passes | ((ok | scatter) & alive)) & (st["depth"] < max_depth)
        if sob is not None:
            st["sob_it"] = st["sob_it"] + 1
        return st

    def _scatter_event(st, r, scatter, t_sc, p, m_id, m_alb, p_in, p_out):
        """A scatter event inside a medium: first-stop attributes (a volume sample), next-event estimation with
        the isotropic phase function and the media's transmittance, and an isotropic continuation."""
        first_m = scatter & st["first"]
        st["hit"] = st["hit"] | first_m
        st["volume"] = st["volume"] | first_m
        st["obj"] = dr.select(first_m, m_id, st["obj"])
        st["z"] = dr.select(first_m, dr.dot(p - cam_o, cam_f), st["z"])
        st["zin"] = dr.select(first_m, dr.dot(p_in - cam_o, cam_f), st["zin"])
        st["zout"] = dr.select(first_m, dr.dot(p_out - cam_o, cam_f), st["zout"])
        st["distance"] = dr.select(first_m, st["dist"] + t_sc, st["distance"])
        st["albedo"] = dr.select(first_m, m_alb, st["albedo"])
        st["normal"] = dr.select(first_m, mi.Vector3f(0.0), st["normal"])
        st["position"] = dr.select(first_m, p, st["position"])
        st["gopen"] = st["gopen"] & ~scatter
        it = dr.zeros(mi.SurfaceInteraction3f, n)
        it.p, it.t = p, mi.Float(0.0)
        phase = 1.0 / (4.0 * math.pi)
        pick = dr.minimum(mi.UInt32(r.u1(SLOT_VOL_PICK) * n_emitters), n_emitters - 1)
        emitter = dr.gather(mi.EmitterPtr, emitters, pick, scatter)
        ds, em_w = emitter.sample_direction(it, r.u2(SLOT_VOL_LIGHT), scatter)
        nee = scatter & (ds.pdf > 0)
        visible = ~scene.ray_test(it.spawn_ray_to(ds.p), nee)
        em_w = dr.select(nee & visible, em_w * n_emitters, 0.0) * _transmittance(mi, dr, media, p, ds.d, ds.dist)
        w_nee = dr.select(ds.delta, 1.0, _mis(ds.pdf / n_emitters, phase))
        light = m_alb * phase * em_w * w_nee
        c_d = dr.select(first_m, light, st["beta_d"] * light)   # split as the first stop's lobes were
        c_s = dr.select(first_m, mi.Color3f(0.0), st["beta_s"] * light)
        st["diffuse"] = dr.select(nee, st["diffuse"] + c_d, st["diffuse"])
        st["specular"] = dr.select(nee, st["specular"] + c_s, st["specular"])
        em_reg = dr.reinterpret_array(mi.UInt32, ds.emitter)
        add_group(st, dr.gather(mi.Int32, grp_t, em_reg, nee), c_d + c_s, nee & (em_reg != 0))
        # isotropic continuation: phase / pdf = 1, so the throughput is multiplied by the albedo; at the first
        # stop all of it is diffuse
        wo = mi.warp.square_to_uniform_sphere(r.u2(SLOT_VOL_DIR))
        st["beta_d"] = dr.select(first_m, m_alb, dr.select(scatter, st["beta_d"] * m_alb, st["beta_d"]))
        st["beta_s"] = dr.select(first_m, mi.Color3f(0.0), dr.select(scatter, st["beta_s"] * m_alb, st["beta_s"]))
        st["ray"] = dr.select(scatter, mi.Ray3f(p, wo), st["ray"])
        st["prev_si"] = dr.select(scatter, it, st["prev_si"])
        st["prev_pdf"] = dr.select(scatter, phase, st["prev_pdf"])
        st["prev_delta"] = dr.select(scatter, mi.Bool(False), st["prev_delta"])

    (st,) = dr.while_loop((state,), lambda st: st["active"], lambda st: (body(st),))
    keep = ("diffuse", "specular", "emission", "group0", "group1", "group2", "hit", "obj", "z", "distance",
            "albedo", "normal", "position") + (("volume", "zin", "zout") if media else ())
    return {k: st[k] for k in keep}
