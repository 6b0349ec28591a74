"""A room around a scene: the walls-and-bounce-light axis as an option of any family (`ranad synth --enclosure`).

The held-out `interior` family is the only one built inside walls with its lights aimed at them, so a model trained
on the other families never sees a frame whose background is a lit wall, with every pixel covered and most light
arriving after a bounce, which is what most users' interiors look like. This module adds that axis to any scene
without touching its other draws: a stream of random numbers of its own (seeded by the scene's seed) decides whether
the scene is enclosed and how, and the scene's objects, camera and lights are the ones `make_scene` drew, the lights
moved inside the room and some of them re-aimed at its walls. It differs from `interior`'s room on purpose: the room
is turned by a random angle to the camera, its walls stand at distances fitted to the scene's objects (not one fixed
corner), a ceiling closes it in scenes without a sky, and the walls take the family's own opaque materials and
texture frequencies (plastics, metals, high-frequency checkerboards) rather than interior's matte low-frequency ones.
"""

from __future__ import annotations

import numpy as np

from .scene import PRESET_PARAMS, SceneObject, SceneSpec, draw_material, look_at, rotate, scale, translate

ENCLOSURE_STREAM = 0xE7C            # the enclosure's random stream: np.random.default_rng([scene seed, this])
_TRANSPARENT = ("dielectric", "roughdielectric", "thindielectric")
_MATTE_WALLS = dict(diffuse=2, textured=1)   # the wall materials of the presets without a material mix
MARGIN = 0.8                        # the least distance between a wall and an object's centre or the camera


def _room_coords(yaw_deg: float, points: np.ndarray) -> np.ndarray:
    """World points (N, 3) in the room's frame (the world turned by -yaw about the vertical)."""
    r = rotate([0, 1, 0], -yaw_deg)[:3, :3]
    return points @ r.T


def _wall_material(rng: np.random.Generator, spec: SceneSpec) -> dict:
    """An opaque material from the scene's family mix (glass left out: a wall is opaque), or a matte one."""
    p = PRESET_PARAMS[spec.preset]
    weights = {k: v for k, v in (p.get("materials") or _MATTE_WALLS).items() if k not in _TRANSPARENT}
    return draw_material(rng, weights or _MATTE_WALLS, p.get("tex_freq", (1, 8)))


def enclose(spec: SceneSpec, share: float) -> bool:
    """Puts `share` of the scenes (decided per scene by its own stream) inside a room; returns whether this one was.
    Scenes whose family has walls already (interior) are left alone. Changes `spec` in place: appends the walls
    (static, with new object ids), moves every light inside the room and aims a share of them at its walls."""
    p = PRESET_PARAMS[spec.preset]
    rng = np.random.default_rng([spec.seed, ENCLOSURE_STREAM])
    if share <= 0 or p.get("walls") or rng.random() >= share:
        return False
    yaw = float(rng.uniform(-35, 35))
    lights = [o for o in spec.objects if o.radiance is not None]
    things = [o for o in spec.objects if o.radiance is None and o.id != 1]   # id 1: the ground
    centres = np.array([np.asarray(t)[:3, 3] for o in things for t in o.transforms]).reshape(-1, 3)
    cams = _room_coords(yaw, np.asarray(spec.camera.origin, float))
    pts = _room_coords(yaw, centres) if len(centres) else np.zeros((1, 3))
    back = max(float(-pts[:, 2].min()), 0.0) + MARGIN + float(rng.uniform(0.0, 2.5))
    reach = max(float(np.abs(pts[:, 0]).max()), float(np.abs(cams[:, 0]).max()))
    left = reach + MARGIN + float(rng.uniform(0.0, 2.5))
    right = reach + MARGIN + float(rng.uniform(0.0, 2.5)) if rng.random() < 0.6 else None
    front = float(cams[:, 2].min()) - 0.5           # the side walls and ceiling end beside the camera
    ceiling = float(rng.uniform(4.0, 6.5)) if spec.sky is None and rng.random() < 0.6 else None
    height = ceiling if ceiling is not None else float(rng.uniform(3.5, 6.0))
    depth_mid, depth_half = (front - back) / 2, (front + back) / 2
    span = right if right is not None else left + 3.0   # the open side: the back wall and ceiling reach past it
    turn = rotate([0, 1, 0], yaw)
    walls = [translate([(span - left) / 2, height / 2, -back]) @ scale([(span + left) / 2, height / 2, 1]),
             translate([-left, height / 2, depth_mid]) @ rotate([0, 1, 0], 90) @ scale([depth_half, height / 2, 1])]
    if right is not None:
        walls.append(translate([right, height / 2, depth_mid]) @ rotate([0, 1, 0], -90)
                     @ scale([depth_half, height / 2, 1]))
    if ceiling is not None:
        walls.append(translate([(span - left) / 2, ceiling, depth_mid]) @ rotate([1, 0, 0], 90)
                     @ scale([(span + left) / 2, depth_half, 1]))
    next_id = max([o.id for o in spec.objects] + [m.id for m in spec.media]) + 1
    targets = []   # points on the walls (world), where re-aimed lights point
    for k, w in enumerate(walls):
        world = turn @ w
        spec.objects.append(SceneObject(next_id + k, "rectangle", _wall_material(rng, spec), [world] * spec.frames,
                                        anim={"base": world.tolist(), "velocity": [0.0] * 3, "axis": [0.0, 1.0, 0.0],
                                              "spin": 0.0}))
        targets.append(world)
    bounce = float(rng.uniform(0.3, 1.0))
    top = (ceiling if ceiling is not None else height + 2.0) - 0.3   # the lights' room: 0.3 inside its walls
    x_max = (right if right is not None else np.inf) - 0.3
    for o in lights:
        m = np.asarray(o.transforms[0], float)
        size = float(np.linalg.norm(m[:3, 0]))
        pos = _room_coords(yaw, m[None, :3, 3])[0]
        pos = np.array([min(max(pos[0], 0.3 - left), x_max), min(pos[1], top), max(pos[2], 0.3 - back)])
        world_pos = turn[:3, :3] @ pos
        if rng.random() < bounce:          # at a wall (or the ceiling): bounce light
            w = targets[int(rng.integers(len(targets)))]
            aim = (w @ np.array([*rng.uniform(-0.6, 0.6, 2), 0.0, 1.0]))[:3]
            if np.linalg.norm((aim - world_pos)[[0, 2]]) < 1e-2:   # straight up: look_at needs a horizontal part
                aim = aim + np.array([0.1, 0.0, 0.0])
        else:                              # the way it pointed before: along its own +z
            aim = world_pos + m[:3, 2]
        base = look_at(world_pos, aim) @ scale(size)
        o.transforms = [base] * len(o.transforms)
        if o.anim is not None:
            o.anim["base"] = base.tolist()
    return True
