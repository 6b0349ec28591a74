"""Procedural animated scenes for training data: a plain-Python description, then one Mitsuba scene per frame.

Mitsuba 3 has no animated transforms, so a scene is described here with every object's 4x4 to-world matrix per
frame (the table the motion vectors are computed from) and rebuilt for each frame. Presets stress what makes deep
images hard: semi-transparent panes, alpha-cut "foliage" cards, thin cylinders, objects at close depths, depth
of field, glossy and diffuse materials, several light groups and empty background.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .meshes import mesh_file
from .textures import NOISE_STYLES, noise_texels

CUTOUT_NONE, CUTOUT_LEAF, CUTOUT_FENCE = 0, 1, 2


@dataclass
class SceneObject:
    id: int                      # object id written to the deep-OID `id` channel (1, 2, ...; 0 = nothing)
    kind: str                    # sphere | cube | rectangle | cylinder | mesh
    bsdf: dict                   # Mitsuba BSDF dictionary
    transforms: list             # 4x4 to-world matrix per frame
    opacity: float = 1.0         # < 1: a sample passes through with probability 1 - opacity (semi-transparent)
    cutout: int = CUTOUT_NONE    # alpha-textured card pattern
    radiance: tuple | None = None  # area emitter radiance (an object that is a light)
    light_group: int = -1        # index into SceneSpec.light_groups for emitters
    mesh: dict | None = None     # kind "mesh": the procedural mesh's parameters (meshes.make_mesh)
    anim: dict | None = None     # base, velocity, axis, spin: the motion `transforms` sample (pose_at, any time)


@dataclass
class Camera:
    origin: list                 # per frame, xyz
    target: list                 # per frame, xyz
    fov: float = 40.0
    aperture: float = 0.0        # thin-lens aperture radius (0: pinhole)
    focus: float = 5.0
    velocity: list | None = None  # per frame, xyz (the origin at any time, camera_at); None: as `origin` says


@dataclass
class SceneSpec:
    seed: int
    preset: str
    width: int
    height: int
    frames: int
    camera: Camera
    objects: list = field(default_factory=list)
    light_groups: list = field(default_factory=list)
    sky: "Sky | None" = None      # an environment light (families with `sky`), else none
    media: list = field(default_factory=list)   # participating media (Medium), static
    shutter: float = 0.0          # motion blur: the shutter stays open this fraction of a frame (0: none)

    def object(self, oid: int) -> SceneObject:
        return next(o for o in self.objects if o.id == oid)


@dataclass
class Sky:
    """An environment light: a sky gradient from the horizon to the zenith, a dim ground below the horizon and
    (unless overcast) a sun disc. Paths that leave the scene after a bounce see it; camera rays that miss
    everything stay empty, as deep renders hold no sky bins."""
    zenith: tuple                # RGB radiance straight up
    horizon: tuple               # RGB radiance at the horizon
    ground: tuple                # RGB radiance below the horizon
    sun_dir: tuple | None        # unit vector towards the sun (None: overcast)
    sun_radius_deg: float = 1.0
    sun_irradiance: tuple = (0.0, 0.0, 0.0)   # RGB irradiance of the sun on a surface facing it
    light_group: int = 0


@dataclass
class Medium:
    """A homogeneous participating medium filling an axis-aligned ellipsoid (a fog bank, a smoke puff): light
    scatters in it isotropically, and a sample that scatters there first makes a volume bin (Z < ZBack: where
    its pixel's rays enter and leave the medium). Media do not move."""
    id: int                      # the object id of its bins (deep-OID), unique among the scene's objects
    centre: tuple
    radii: tuple
    sigma_t: float               # extinction per unit length (grey)
    albedo: tuple                # single-scattering albedo, RGB


SKY_WIDTH = 512   # the environment map's width in texels (height half that): 0.7 degrees per texel


def sky_texels(sky: Sky, width: int = SKY_WIDTH) -> np.ndarray:
    """The sky as a latitude-longitude radiance map [width / 2, width, 3] in Mitsuba's `envmap` convention (y up;
    texel (u, v) looks along (sin 2pi u sin pi v, cos pi v, -cos 2pi u sin pi v)). The sun disc is drawn
    antialiased and then scaled so that the map's sun delivers exactly `sun_irradiance`, however few texels it
    covers."""
    h = width // 2
    theta = (np.arange(h) + 0.5) / h * np.pi
    phi = (np.arange(width) + 0.5) / width * 2 * np.pi
    th, ph = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(ph) * np.sin(th), np.cos(th), -np.cos(ph) * np.sin(th)], -1)
    up = np.clip(d[..., 1:2], 0.0, 1.0)
    t = np.sqrt(up)   # the horizon's colour holds low above it, as in a real sky
    sky_rgb = np.asarray(sky.horizon) * (1 - t) + np.asarray(sky.zenith) * t
    out = np.where(d[..., 1:2] >= 0, sky_rgb, np.asarray(sky.ground)).astype(np.float64)
    if sky.sun_dir is not None:
        s = np.asarray(sky.sun_dir, float)
        s = s / np.linalg.norm(s)
        ang = np.arccos(np.clip(d @ s, -1.0, 1.0))
        r, half_texel = math.radians(sky.sun_radius_deg), np.pi / h / 2
        disc = np.clip((r + half_texel - ang) / (2 * half_texel), 0.0, 1.0)
        solid = np.sin(th) * (np.pi / h) * (2 * np.pi / width)   # each texel's solid angle
        flux = float((disc * solid).sum())
        out += disc[..., None] * (np.asarray(sky.sun_irradiance) / max(flux, 1e-12))
    return out.astype(np.float32)


def _draw_sky(rng: np.random.Generator, light_group: int) -> Sky:
    """A random sky: a blue-to-pale gradient at one of many brightnesses, and a sun of a few times the sky's
    irradiance at 8-70 degrees elevation (warmer when low), or an overcast sky (a quarter of the scenes)."""
    level = float(rng.uniform(0.3, 1.2))
    zenith = np.array([0.25, 0.42, 0.9]) * level * rng.uniform(0.85, 1.15, 3)
    horizon = np.array([0.8, 0.85, 0.95]) * level * rng.uniform(0.9, 1.1, 3)
    ground = np.array([0.3, 0.26, 0.2]) * level * rng.uniform(0.1, 0.4)
    if rng.random() < 0.25:   # overcast: a brighter, greyer sky and no sun
        grey = float(horizon.mean()) * 1.5
        return Sky(tuple(float(c) for c in np.full(3, grey) * rng.uniform(0.9, 1.1, 3)),
                   tuple(float(c) for c in np.full(3, grey) * 1.2), tuple(float(c) for c in ground), None,
                   light_group=light_group)
    elev, azim = math.radians(rng.uniform(8, 70)), rng.uniform(0, 2 * math.pi)
    sun_dir = (math.cos(elev) * math.sin(azim), math.sin(elev), -math.cos(elev) * math.cos(azim))
    warm = np.array([1.0, 0.92 - 0.25 * (1 - elev / 1.3), 0.85 - 0.45 * (1 - elev / 1.3)])
    irradiance = warm / warm.mean() * math.pi * level * rng.uniform(2.0, 8.0)
    return Sky(tuple(float(c) for c in zenith), tuple(float(c) for c in horizon), tuple(float(c) for c in ground),
               sun_dir, float(rng.uniform(0.5, 2.5)), tuple(float(c) for c in irradiance), light_group)


# ---- transforms ---------------------------------------------------------------------------------------
def translate(v) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = v
    return m


def scale(s) -> np.ndarray:
    return np.diag([*np.broadcast_to(np.asarray(s, float), (3,)), 1.0])


def rotate(axis, degrees: float) -> np.ndarray:
    a = np.asarray(axis, float)
    a = a / np.linalg.norm(a)
    t = math.radians(degrees)
    c, s = math.cos(t), math.sin(t)
    x, y, z = a
    r = np.array([[c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                  [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                  [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)]])
    m = np.eye(4)
    m[:3, :3] = r
    return m


def look_at(origin, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Camera to-world matrix in Mitsuba's convention (camera looks along +z, x to the left)."""
    o, t, u = (np.asarray(v, float) for v in (origin, target, up))
    d = t - o
    d /= np.linalg.norm(d)
    left = np.cross(u, d)
    left /= np.linalg.norm(left)
    new_up = np.cross(d, left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, new_up, d, o
    return m


# ---- materials ------------------------------------------------------------------------------------------
def _rgb(rng: np.random.Generator, lo=0.1, hi=0.9) -> list:
    return [float(x) for x in rng.uniform(lo, hi, 3)]


def _bsdf(rng: np.random.Generator, glossy_prob: float) -> dict:
    r = rng.random()
    if r < glossy_prob * 0.5:
        return {"type": "roughplastic", "distribution": "ggx", "alpha": float(rng.uniform(0.05, 0.3)),
                "diffuse_reflectance": {"type": "rgb", "value": _rgb(rng)}}
    if r < glossy_prob:
        return {"type": "roughconductor", "material": "none", "alpha": float(rng.uniform(0.08, 0.35)),
                "specular_reflectance": {"type": "rgb", "value": _rgb(rng, 0.4, 0.95)}}
    return {"type": "diffuse", "reflectance": {"type": "rgb", "value": _rgb(rng)}}


def _two_sided(bsdf: dict) -> dict:
    """A card's BSDF seen from both sides: wrapped in `twosided`, except glass (two-sided already, and Mitsuba
    refuses to nest a transmissive BSDF)."""
    if bsdf["type"] in ("dielectric", "roughdielectric", "thindielectric"):
        return bsdf
    return {"type": "twosided", "bsdf": bsdf}


def draw_material(rng: np.random.Generator, weights: dict, tex_freq) -> dict:
    """A BSDF drawn from a family's material weights (MATERIALS)."""
    names = list(weights)
    p = np.asarray([weights[n] for n in names], float)
    kind = names[int(rng.choice(len(names), p=p / p.sum()))]
    if kind == "diffuse":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": _rgb(rng, 0.03, 0.95)}}
    if kind == "noise":   # a procedural albedo map (textures.py), repeated a whole number of times
        tex = {"type": "ranad_noise", "style": str(rng.choice(NOISE_STYLES)), "seed": int(rng.integers(1 << 31)),
               "cells": int(2 ** rng.integers(1, 7)), "colour0": _rgb(rng, 0.02, 0.9), "colour1": _rgb(rng, 0.02, 0.9),
               "to_uv": scale([int(rng.integers(1, 5)), int(rng.integers(1, 5)), 1]).tolist()}
        if rng.random() < 0.3:
            return {"type": "roughplastic", "distribution": "ggx", "alpha": float(rng.uniform(0.1, 0.4)),
                    "diffuse_reflectance": tex}
        return {"type": "diffuse", "reflectance": tex}
    if kind == "textured":
        f = float(np.exp(rng.uniform(np.log(tex_freq[0]), np.log(tex_freq[1]))))
        tex = {"type": "checkerboard", "color0": {"type": "rgb", "value": _rgb(rng, 0.02, 0.9)},
               "color1": {"type": "rgb", "value": _rgb(rng, 0.02, 0.9)}, "to_uv": scale([f, f, 1]).tolist()}
        if rng.random() < 0.3:
            return {"type": "roughplastic", "distribution": "ggx", "alpha": float(rng.uniform(0.1, 0.4)),
                    "diffuse_reflectance": tex}
        return {"type": "diffuse", "reflectance": tex}
    if kind in ("plastic", "roughplastic"):
        d = {"type": kind, "diffuse_reflectance": {"type": "rgb", "value": _rgb(rng, 0.03, 0.9)}}
        if kind == "roughplastic":
            d.update(distribution="ggx", alpha=float(rng.uniform(0.05, 0.4)))
        return d
    if kind in ("conductor", "roughconductor"):
        d = {"type": kind, "material": "none", "specular_reflectance": {"type": "rgb", "value": _rgb(rng, 0.3, 0.98)}}
        if kind == "roughconductor":
            d.update(distribution="ggx", alpha=float(rng.uniform(0.03, 0.5)))
        return d
    if kind == "roughdielectric":
        return {"type": "roughdielectric", "distribution": "ggx", "alpha": float(rng.uniform(0.03, 0.3)),
                "int_ior": float(rng.uniform(1.3, 1.8))}
    if kind == "dielectric":
        return {"type": "dielectric", "int_ior": float(rng.uniform(1.3, 1.8))}
    return {"type": "thindielectric", "int_ior": float(rng.uniform(1.3, 1.6))}


# ---- the generator -------------------------------------------------------------------------------------
PRESET_PARAMS = {
    # objects, panes, cards, thin, glossy share, DOF probability, motion scale
    "easy": dict(objects=(3, 5), panes=(0, 0), cards=(0, 0), thin=(0, 1), veils=(0, 0), glossy=0.2, dof=0.0,
                 motion=0.6),
    "medium": dict(objects=(4, 7), panes=(1, 2), cards=(1, 3), thin=(1, 2), veils=(0, 1), glossy=0.4, dof=0.3,
                   motion=1.0),
    "deep-heavy": dict(objects=(5, 8), panes=(3, 5), cards=(8, 12), thin=(2, 4), veils=(2, 3), glossy=0.5,
                       dof=0.6, motion=1.0),
}

# Scene families for generalization (domain randomisation): each family draws, per scene, from its own ranges
# of materials (`materials`: weights of MATERIALS), geometry (objects, thin wires, panes, foliage cards, fences,
# stacks of semi-transparent layers, thin glass sheets), lighting (`small_lights`: intense small emitters that
# make fireflies and caustics through glass; `exposure`: +- stops applied to every light), camera (`fov`, `dof`)
# and texture frequency. The three presets above keep their original draws (datasets made before the families
# existed render identically); a family's extra axes are drawn after them.
MATERIALS = ("diffuse", "plastic", "roughplastic", "conductor", "roughconductor", "dielectric", "roughdielectric",
             "thindielectric", "textured", "noise")
_NEW = dict(objects=(3, 6), panes=(0, 1), cards=(0, 1), thin=(0, 2), veils=(0, 0), glossy=0.4, dof=0.3,
            motion=1.0, materials=None, small_lights=(0, 0), exposure=2.0, fov=(25, 60), fences=(0, 0),
            stacks=(0, 0), glass_sheets=(0, 0), tex_freq=(2, 32), sky=0.0, meshes=(0, 0), media=(0, 0),
            shutter=(0.0, 0.0))
FAMILY_PARAMS = {
    # polished objects under small intense lights: conductors, plastics and glass (caustics, fireflies)
    "studio": {**_NEW, "objects": (3, 6), "panes": (0, 0), "thin": (0, 1),
               "materials": dict(plastic=2, roughplastic=2, conductor=2, roughconductor=2, dielectric=2,
                                 roughdielectric=1, diffuse=1), "small_lights": (1, 3)},
    # refraction: solid and rough glass objects, thin glass sheets in front of the scene, semi-transparent panes
    "glass": {**_NEW, "objects": (3, 6), "panes": (1, 2), "glass_sheets": (1, 3),
              "materials": dict(dielectric=3, roughdielectric=2, thindielectric=1, diffuse=2, textured=1,
                                conductor=1), "small_lights": (0, 1)},
    # thin geometry: foliage cards, fences, wires and poles at many scales
    "thin": {**_NEW, "objects": (2, 4), "cards": (6, 14), "thin": (4, 10), "fences": (1, 3),
             "materials": dict(diffuse=3, textured=2, roughplastic=1, roughconductor=1)},
    # stacks of 4-8 semi-transparent layers across the view (deep-heavy pixels), textured backgrounds
    "layers": {**_NEW, "objects": (3, 5), "stacks": (1, 1), "panes": (0, 2),
               "materials": dict(diffuse=2, textured=2, plastic=1, roughconductor=1)},
    # textured albedo at many frequencies, many mid-size objects, wide and long lenses
    "textured": {**_NEW, "objects": (5, 9), "thin": (0, 2), "cards": (0, 3), "fov": (15, 70), "dof": 0.5,
                 "materials": dict(textured=5, diffuse=1, roughplastic=1, roughconductor=1)},
    # a room corner lit mostly by bounce light: walls behind and beside the objects, lights aimed at the walls,
    # matte and low-frequency textured materials (indirect, low-frequency noise: what flat denoisers handle best)
    "interior": {**_NEW, "objects": (4, 8), "thin": (0, 1), "walls": True, "bounce": 0.7,
                 "materials": dict(diffuse=4, textured=3, roughplastic=1, roughconductor=1), "tex_freq": (1, 8)},
    # outdoors: objects, foliage and fences on the ground under a sky with a sun (or overcast), the key light
    # group; the other groups are area lights as fill and rim
    "exterior": {**_NEW, "objects": (4, 8), "cards": (0, 4), "fences": (0, 1), "sky": 1.0,
                 "materials": dict(diffuse=3, textured=2, plastic=1, roughplastic=1, conductor=1, roughconductor=1,
                                   dielectric=1)},
    # smooth irregular shapes (blobs, tori: meshes.py) in procedural albedo maps (clouds, marble, stripes, tiles:
    # textures.py), under area lights or, in half the scenes, a sky
    "organic": {**_NEW, "objects": (1, 3), "meshes": (3, 6), "thin": (0, 1), "sky": 0.5,
                "materials": dict(diffuse=2, noise=4, textured=1, plastic=1, roughplastic=2, roughconductor=1,
                                  dielectric=1, roughdielectric=1)},
    # participating media: ground fog banks and smoke puffs among the objects (volume bins), under area lights or,
    # in a third of the scenes, a sky
    "fog": {**_NEW, "objects": (3, 7), "media": (1, 2), "sky": 0.3,
            "materials": dict(diffuse=3, textured=2, roughplastic=1, plastic=1, roughconductor=1, dielectric=1)},
    # motion blur: objects and camera moving four times as fast, the shutter open for 0.25-1 frame (each sample at
    # its own time: streaks, edges of partial coverage), thin wires and foliage among them
    "motion": {**_NEW, "objects": (4, 8), "thin": (1, 3), "cards": (0, 3), "motion": 4.0, "shutter": (0.25, 1.0),
               "materials": dict(diffuse=3, textured=2, noise=1, roughplastic=2, roughconductor=1, dielectric=1)},
    # seen through glass: one or two thin panes (windows, vitrines) between the camera and every scene, glassware
    # (solid and rough dielectrics) among meshes in procedural albedo maps, under a sky or area lights. The
    # refraction a training family shares with the held-out `glass` family, in scenes composed like `organic`'s
    "windows": {**_NEW, "objects": (2, 5), "meshes": (1, 3), "glass_sheets": (1, 2), "cards": (0, 2), "sky": 0.5,
                "small_lights": (0, 1),
                "materials": dict(diffuse=2, noise=2, textured=1, roughplastic=1, conductor=1, roughconductor=1,
                                  dielectric=2, roughdielectric=2, thindielectric=1)},
}
PRESET_PARAMS.update(FAMILY_PARAMS)
PRESETS = ("easy", "medium", "deep-heavy")           # the original presets, used in turn by default
FAMILIES = tuple(PRESET_PARAMS)                      # every named scene family `ranad synth --preset` accepts


def _pose(base: np.ndarray, t: float, velocity, spin_axis, spin_deg: float) -> np.ndarray:
    """The to-world matrix at time t (frames from the shot's centre): base, rotated about its own centre and
    moved by `velocity` per frame."""
    centre = base[:3, 3].copy()
    return translate(centre + np.asarray(velocity) * t) @ rotate(spin_axis, spin_deg * t) @ translate(-centre) @ base


def _animated(base: np.ndarray, frames: int, velocity, spin_axis, spin_deg: float) -> list:
    """Per-frame to-world matrices (_pose at each frame)."""
    return [_pose(base, f - (frames - 1) / 2, velocity, spin_axis, spin_deg) for f in range(frames)]


def pose_at(spec: SceneSpec, o: SceneObject, frame: int, dt: float) -> np.ndarray:
    """An object's to-world matrix `dt` frames after `frame` (inside the shutter; dt = 0: the frame's own)."""
    if dt == 0 or o.anim is None:
        return np.asarray(o.transforms[frame])
    a = o.anim
    return _pose(np.asarray(a["base"]), frame - (spec.frames - 1) / 2 + dt, a["velocity"], a["axis"], a["spin"])


def camera_at(spec: SceneSpec, frame: int, dt: float) -> np.ndarray:
    """The camera's to-world matrix `dt` frames after `frame`."""
    cam = spec.camera
    origin = np.asarray(cam.origin[frame], float)
    if dt and cam.velocity is not None:
        origin = origin + np.asarray(cam.velocity) * dt
    return look_at(origin, cam.target[frame])


def make_scene(seed: int, preset: str = "medium", size: int = 128, frames: int = 3, motion: float = 1.0) -> SceneSpec:
    """A random animated scene, fully determined by (seed, preset, size, frames, motion).

    `motion` scales every per-frame movement (camera, objects, spins) and nothing else: the random draws are the
    same, so `motion=0.5` is the same animation sampled at twice the frame rate (frame offset 2k at 0.5 is frame
    offset k at 1.0), which is how temporal results are compared across frame rates."""
    if motion < 0:
        raise ValueError(f"motion scale must be >= 0, not {motion}")
    if preset not in PRESET_PARAMS:
        raise ValueError(f"unknown preset {preset!r} (one of {', '.join(PRESETS)})")
    p = PRESET_PARAMS[preset]
    family = p.get("materials") is not None
    rng = np.random.default_rng(seed)
    m = p["motion"] * motion
    cam_o = np.array([rng.uniform(-1.0, 1.0), rng.uniform(1.0, 2.2), rng.uniform(6.0, 7.5)])
    cam_t = np.array([rng.uniform(-0.4, 0.4), rng.uniform(0.4, 0.9), 0.0])
    cam_v = rng.normal(0, 0.06 * m, 3)
    camera = Camera(origin=[list(cam_o + cam_v * (f - (frames - 1) / 2)) for f in range(frames)],
                    target=[list(cam_t) for _ in range(frames)], fov=float(rng.uniform(32, 45)),
                    velocity=[float(v) for v in cam_v])
    if family:
        camera.fov = float(rng.uniform(*p["fov"]))
    if rng.random() < p["dof"]:
        camera.aperture = float(rng.uniform(0.03, 0.12))
        camera.focus = float(np.linalg.norm(cam_o - cam_t) + rng.uniform(-1.0, 1.0))
    spec = SceneSpec(seed=seed, preset=preset, width=size, height=size, frames=frames, camera=camera,
                     light_groups=["key", "fill", "rim"][: int(rng.integers(2, 4))])
    next_id = iter(range(1, 1000))
    if family:  # the family's material mix replaces the presets' diffuse/glossy choice
        def _bsdf(rng, glossy):  # noqa: F811 (shadows the module-level sampler on purpose)
            return draw_material(rng, p["materials"], p["tex_freq"])
    else:
        _bsdf = globals()["_bsdf"]

    def add(kind, bsdf, base, *, vel=None, spin=0.0, **kw):
        vel = rng.normal(0, 0.12 * m, 3) if vel is None else vel
        axis = rng.normal(size=3)
        anim = {"base": np.asarray(base).tolist(), "velocity": [float(v) for v in vel],
                "axis": [float(v) for v in axis], "spin": float(spin)}
        spec.objects.append(SceneObject(next(next_id), kind, bsdf,
                                        _animated(base, frames, vel, axis, spin), anim=anim, **kw))

    # ground (static), kept below everything; some presets leave background pixels empty above the horizon
    add("rectangle", _bsdf(rng, 0.1), translate([0, 0, 0]) @ rotate([1, 0, 0], -90) @ scale(8), vel=np.zeros(3))
    for _ in range(int(rng.integers(*p["objects"], endpoint=True))):
        kind = str(rng.choice(["sphere", "cube", "sphere", "cylinder"]))
        s = rng.uniform(0.25, 0.6)
        pos = [rng.uniform(-2.2, 2.2), s, rng.uniform(-2.0, 2.0)]
        base = translate(pos) @ rotate(rng.normal(size=3), rng.uniform(0, 180)) @ scale([s, s, s * (3 if kind == "cylinder" else 1)])
        add(kind, _bsdf(rng, p["glossy"]), base, spin=float(rng.uniform(-15, 15) * m))
    for _ in range(int(rng.integers(*p["thin"], endpoint=True))):  # thin poles
        r = rng.uniform(0.015, 0.04)
        pos = [rng.uniform(-2.5, 2.5), 0.0, rng.uniform(-1.5, 2.5)]
        base = translate(pos) @ rotate([1, 0, 0], -90 + rng.uniform(-20, 20)) @ scale([r, r, rng.uniform(1.2, 2.5)])
        add("cylinder", _bsdf(rng, 0.3), base)
    for _ in range(int(rng.integers(*p["panes"], endpoint=True))):  # semi-transparent panes
        pos = [rng.uniform(-1.8, 1.8), rng.uniform(0.5, 1.3), rng.uniform(-0.5, 3.0)]
        base = translate(pos) @ rotate([0, 1, 0], rng.uniform(-50, 50)) @ scale([rng.uniform(0.5, 1.1), rng.uniform(0.4, 0.9), 1])
        add("rectangle", _two_sided(_bsdf(rng, 0.3)), base, opacity=float(rng.uniform(0.2, 0.6)))
    for k in range(int(rng.integers(*p["veils"], endpoint=True))):  # large faint panes across the view: layers
        depth = 0.35 + 0.2 * k + rng.uniform(-0.05, 0.05)
        pos = cam_o + (cam_t - cam_o) * depth
        base = look_at(pos, cam_o) @ scale([rng.uniform(1.0, 1.8), rng.uniform(0.8, 1.4), 1])
        add("rectangle", _two_sided(_bsdf(rng, 0.2)), base, opacity=float(rng.uniform(0.12, 0.35)),
            spin=float(rng.uniform(-6, 6) * m))
    for _ in range(int(rng.integers(*p["cards"], endpoint=True))):  # alpha-cut foliage cards, often overlapping
        pos = [rng.uniform(-2.0, 2.0), rng.uniform(0.3, 1.6), rng.uniform(-1.0, 3.5)]
        base = translate(pos) @ rotate(rng.normal(size=3), rng.uniform(0, 60)) @ scale(rng.uniform(0.2, 0.45))
        leaf = {"type": "twosided", "bsdf": {"type": "diffuse",
                                             "reflectance": {"type": "rgb", "value": _rgb(rng, 0.05, 0.5)}}}
        add("rectangle", leaf, base, cutout=CUTOUT_LEAF, spin=float(rng.uniform(-25, 25) * m))
    if family:
        _family_extras(spec, p, rng, add, cam_o, cam_t, m)
        # a sky (always at sky 1, else in that share of the scenes) is the key light group; the other groups keep
        # their area lights
        if p["sky"] >= 1 or (p["sky"] > 0 and rng.random() < p["sky"]):
            spec.sky = _draw_sky(rng, 0)
            spec.light_groups[0] = "sky"
    if family and p["media"][1] > 0:
        for _ in range(int(rng.integers(*p["media"], endpoint=True))):
            spec.media.append(_draw_medium(rng, next(next_id)))
    # area lights, one light group each (several lights may share a group)
    for g, _name in enumerate(spec.light_groups):
        for _ in range(1 if g else (0 if spec.sky else int(rng.integers(1, 3)))):
            pos = [rng.uniform(-4, 4), rng.uniform(3.0, 5.0), rng.uniform(-3, 4)]
            aim = [0, 0.5, 0]
            if p.get("walls"):   # inside the room
                pos = [min(max(pos[0], 0.3 - WALL), WALL - 0.3), pos[1], max(pos[2], 0.3 - WALL)]
            if p.get("bounce") and rng.random() < p["bounce"]:   # at the back or left wall: bounce light
                aim = [rng.uniform(-3, 3), rng.uniform(1, 4), -WALL] if rng.random() < 0.6 else \
                    [-WALL, rng.uniform(1, 4), rng.uniform(-3, 3)]
            base = look_at(pos, aim) @ scale(rng.uniform(0.3, 0.8))
            power = rng.uniform(4, 14) if g == 0 else rng.uniform(1.5, 6)
            col = np.clip(rng.normal(1.0, 0.15, 3), 0.6, 1.4) * power
            add("rectangle", {"type": "diffuse"}, base, vel=np.zeros(3),
                radiance=tuple(float(c) for c in col), light_group=g)
    if family:
        for _ in range(int(rng.integers(*p["small_lights"], endpoint=True))):  # small, intense: fireflies
            pos = [rng.uniform(-3, 3), rng.uniform(0.8, 4.0), rng.uniform(-2.5, 4)]
            size = rng.uniform(0.03, 0.12)
            base = look_at(pos, [rng.uniform(-1, 1), 0.4, rng.uniform(-1, 1)]) @ scale(size)
            col = np.clip(rng.normal(1.0, 0.2, 3), 0.5, 1.5) * rng.uniform(1.0, 4.0) / size ** 2
            add("rectangle", {"type": "diffuse"}, base, vel=np.zeros(3),
                radiance=tuple(float(c) for c in col), light_group=int(rng.integers(0, len(spec.light_groups))))
        gain = 2.0 ** rng.uniform(-p["exposure"], p["exposure"])   # the scene's exposure, +- stops
        for o in spec.objects:
            if o.radiance is not None:
                o.radiance = tuple(float(c * gain) for c in o.radiance)
        if spec.sky is not None:
            k = spec.sky
            k.zenith, k.horizon, k.ground, k.sun_irradiance = (tuple(float(c * gain) for c in v) for v in
                                                                (k.zenith, k.horizon, k.ground, k.sun_irradiance))
        if p["shutter"][1] > 0:
            spec.shutter = float(rng.uniform(*p["shutter"]))
    return spec


def _draw_medium(rng: np.random.Generator, oid: int) -> Medium:
    """A fog bank lying on the ground (wide and low) or a smoke puff among the objects, with an optical depth
    through its thinnest axis of 0.3-4 (from a veil to nearly opaque) and a pale, slightly tinted albedo."""
    if rng.random() < 0.5:
        radii = (rng.uniform(2.5, 5.0), rng.uniform(0.3, 0.9), rng.uniform(1.5, 3.5))
        centre = (rng.uniform(-1.0, 1.0), rng.uniform(0.0, 0.3), rng.uniform(-1.0, 2.0))
    else:
        r = rng.uniform(0.4, 1.2)
        radii = tuple(r * rng.uniform(0.8, 1.25, 3))
        centre = (rng.uniform(-2.0, 2.0), rng.uniform(0.4, 1.6), rng.uniform(-1.5, 3.0))
    depth = float(np.exp(rng.uniform(np.log(0.3), np.log(4.0))))
    albedo = np.clip(rng.uniform(0.7, 0.99) * rng.uniform(0.9, 1.1, 3), 0.0, 0.995)
    return Medium(oid, tuple(float(c) for c in centre), tuple(float(c) for c in radii),
                  float(depth / (2 * min(radii))), tuple(float(c) for c in albedo))


WALL = 3.5   # the interior family's walls: the back wall at z = -WALL, the side walls at x = -+WALL


def _family_extras(spec: SceneSpec, p: dict, rng: np.random.Generator, add, cam_o, cam_t, m: float) -> None:
    """The geometry axes only families draw: fences, stacks of semi-transparent layers, thin glass sheets, walls,
    blob and torus meshes (families without walls or meshes draw nothing for them, so their scenes are as
    before)."""
    for _ in range(int(rng.integers(*p["fences"], endpoint=True))):  # fences: a grid of bars cut out of a card
        pos = [rng.uniform(-2.0, 2.0), rng.uniform(0.4, 1.0), rng.uniform(-1.0, 3.0)]
        base = translate(pos) @ rotate([0, 1, 0], rng.uniform(-60, 60)) @ scale([rng.uniform(0.6, 1.6),
                                                                                  rng.uniform(0.4, 0.9), 1])
        add("rectangle", {"type": "twosided", "bsdf": draw_material(rng, dict(diffuse=2, roughconductor=1), (2, 8))},
            base, cutout=CUTOUT_FENCE, vel=np.zeros(3) if rng.random() < 0.5 else None)
    for _ in range(int(rng.integers(*p["stacks"], endpoint=True))):  # 4-8 parallel semi-transparent layers
        layers = int(rng.integers(4, 9))
        start, step = rng.uniform(0.15, 0.35), rng.uniform(0.04, 0.1)
        shift = rng.normal(0, 0.3, 3)
        for k in range(layers):
            pos = cam_o + (cam_t - cam_o) * (start + step * k) + shift * (1 + 0.2 * k)
            base = look_at(pos, cam_o) @ rotate([0, 0, 1], rng.uniform(-20, 20)) @ \
                scale([rng.uniform(0.3, 0.9), rng.uniform(0.25, 0.7), 1])
            mat = draw_material(rng, dict(diffuse=2, textured=1, roughplastic=1), (2, 16))
            add("rectangle", {"type": "twosided", "bsdf": mat}, base, opacity=float(rng.uniform(0.1, 0.45)),
                spin=float(rng.uniform(-4, 4) * m))
    for _ in range(int(rng.integers(*p["glass_sheets"], endpoint=True))):  # thin glass in front of the scene
        pos = cam_o + (cam_t - cam_o) * rng.uniform(0.3, 0.7) + rng.normal(0, 0.4, 3)
        base = look_at(pos, cam_o) @ rotate([0, 1, 0], rng.uniform(-30, 30)) @ \
            scale([rng.uniform(0.3, 0.8), rng.uniform(0.3, 0.7), 1])
        add("rectangle", {"type": "thindielectric", "int_ior": float(rng.uniform(1.3, 1.6))}, base)
    if p.get("walls"):   # static walls: back, left, and the right one in half the scenes
        walls = [translate([0, 0, -WALL]) @ scale(8), translate([-WALL, 0, 0]) @ rotate([0, 1, 0], 90) @ scale(8)]
        if rng.random() < 0.5:
            walls.append(translate([WALL, 0, 0]) @ rotate([0, 1, 0], -90) @ scale(8))
        for base in walls:
            add("rectangle", draw_material(rng, dict(diffuse=2, textured=1), (1, 4)), base, vel=np.zeros(3))
    if p["meshes"][1] > 0:   # blobs and tori standing on the ground
        for _ in range(int(rng.integers(*p["meshes"], endpoint=True))):
            size = rng.uniform(0.3, 0.7)
            if rng.random() < 0.7:
                mesh = {"kind": "blob", "seed": int(rng.integers(1 << 31)), "waves": int(rng.integers(3, 9)),
                        "amplitude": float(rng.uniform(0.1, 0.45))}
                lift, shape = size * (1 + mesh["amplitude"]), scale(size)
            else:
                mesh = {"kind": "torus", "minor": float(rng.uniform(0.2, 0.5))}
                shape = rotate(rng.normal(size=3), rng.uniform(0, 180)) @ scale(size)
                lift = size * (1 + mesh["minor"])
            base = translate([rng.uniform(-2.2, 2.2), lift, rng.uniform(-2.0, 2.0)]) @ shape
            add("mesh", draw_material(rng, p["materials"], p["tex_freq"]), base, spin=float(rng.uniform(-15, 15) * m),
                mesh=mesh)


def mitsuba_dict(spec: SceneSpec, frame: int, dt: float = 0.0) -> dict:
    """The Mitsuba scene dictionary of one frame, or of the instant `dt` frames after it inside the shutter (no
    integrator: ranad traces its own paths)."""
    cam = spec.camera
    to_world = camera_at(spec, frame, dt)
    sensor = {"type": "thinlens" if cam.aperture > 0 else "perspective", "fov": cam.fov,
              "to_world": to_world.tolist(),
              "film": {"type": "hdrfilm", "width": spec.width, "height": spec.height, "rfilter": {"type": "box"}}}
    if cam.aperture > 0:
        sensor["aperture_radius"] = cam.aperture
        sensor["focus_distance"] = cam.focus
    d = {"type": "scene", "sensor": sensor}
    for o in spec.objects:
        shape = {"type": o.kind, "to_world": pose_at(spec, o, frame, dt).tolist(), "bsdf": _realised(o.bsdf)}
        if o.kind == "mesh":
            shape.update(type="obj", filename=mesh_file(o.mesh))
        if o.radiance is not None:
            shape["emitter"] = {"type": "area", "radiance": {"type": "rgb", "value": list(o.radiance)}}
        d[f"obj{o.id}"] = shape
    if spec.sky is not None:
        d["sky"] = {"type": "envmap", "bitmap": sky_texels(spec.sky)}
    return d


def _realised(bsdf: dict) -> dict:
    """`bsdf` with its procedural textures made into Mitsuba bitmap textures (texels as numpy arrays, which
    convert_transforms hands to Mitsuba)."""
    if bsdf.get("type") == "ranad_noise":
        params = {k: v for k, v in bsdf.items() if k not in ("type", "to_uv")}
        return {"type": "bitmap", "bitmap": noise_texels(params), "raw": True, "to_uv": bsdf["to_uv"]}
    return {k: _realised(v) if isinstance(v, dict) else v for k, v in bsdf.items()}


def convert_transforms(d: dict) -> dict:
    """Replaces the nested-list matrices of mitsuba_dict by Mitsuba transforms (needs the variant loaded)."""
    from .mitsuba_env import mitsuba

    mi = mitsuba()
    out = {}
    for key, val in d.items():
        if isinstance(val, dict):
            val = convert_transforms(val)
        if key in ("to_world", "to_uv"):
            val = mi.ScalarTransform4f(np.asarray(val, dtype=np.float64).tolist())
        if key == "bitmap":
            val = mi.Bitmap(np.ascontiguousarray(val, dtype=np.float32))
        out[key] = val
    return out
