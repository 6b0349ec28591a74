"""synth/enclosure.py: the room around a scene, checked as geometry (no rendering: see test_synth.py for a render)."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from ranad_core.synth.dataset import scene_seed
from ranad_core.synth.enclosure import enclose
from ranad_core.synth.scene import make_scene

FAMILIES = ("studio", "thin", "textured", "exterior", "organic", "motion", "windows", "easy", "deep-heavy")


def _walls(before, after):
    return after.objects[len(before.objects):]


def _inside(wall, point, margin=0.0):
    """Whether a point is on the lit side of a wall (a rectangle faces along its own +z)."""
    w = np.asarray(wall.transforms[0], float)
    n = w[:3, 2] / np.linalg.norm(w[:3, 2])
    return float((np.asarray(point, float) - w[:3, 3]) @ n) > margin


@pytest.mark.parametrize("family", FAMILIES)
def test_the_room_surrounds_the_scene_and_keeps_its_draws(family):
    """Every object's centre (at every frame) and the camera stand inside every wall; the lights are moved inside;
    the scene's own objects, materials and camera are the ones make_scene drew; the walls are static and opaque."""
    for s in range(4):
        before = make_scene(scene_seed(36, s), family, 32, 3)
        after = copy.deepcopy(before)
        assert enclose(after, 1.0)
        walls = _walls(before, after)
        assert 2 <= len(walls) <= 4 and all(w.kind == "rectangle" and w.radiance is None for w in walls)
        assert all(np.allclose(w.transforms[0], w.transforms[-1]) and w.anim["velocity"] == [0.0] * 3 for w in walls)
        assert not any(w.bsdf["type"] in ("dielectric", "roughdielectric", "thindielectric") for w in walls)
        assert len({o.id for o in after.objects} | {m.id for m in after.media}) == len(after.objects) + len(after.media)
        assert after.camera == before.camera and after.sky == before.sky
        for old, new in zip(before.objects, after.objects):
            assert old.id == new.id and old.bsdf == new.bsdf and old.kind == new.kind
            if old.radiance is None:   # the objects stay where they were; only the lights move
                assert all(np.allclose(a, b) for a, b in zip(old.transforms, new.transforms))
                if old.id != 1:        # not the ground, which runs under the walls
                    for t in new.transforms:
                        assert all(_inside(w, np.asarray(t)[:3, 3], 0.5) for w in walls)
            else:
                assert all(_inside(w, np.asarray(new.transforms[0])[:3, 3], 0.2) for w in walls)
        for origin in after.camera.origin:
            assert all(_inside(w, origin, 0.2) for w in walls)
        if after.sky is not None:      # no ceiling over a sky
            assert not any(np.asarray(w.transforms[0])[1, 2] < -0.9 for w in walls)


def test_the_share_decides_per_scene_and_interiors_are_left_alone():
    """share 0 and the interior family (walls of its own) change nothing; share 0.5 encloses some scenes and not
    others; the same scene is enclosed the same way every time."""
    got = []
    for s in range(16):
        spec = make_scene(scene_seed(7, s), "studio", 32, 1)
        for share, family in ((0.0, "studio"), (1.0, "interior")):
            plain = make_scene(scene_seed(7, s), family, 32, 1)
            kept = copy.deepcopy(plain)
            assert not enclose(kept, share) and len(kept.objects) == len(plain.objects)
        a, b = copy.deepcopy(spec), copy.deepcopy(spec)
        got.append(enclose(a, 0.5))
        assert enclose(b, 0.5) == got[-1]
        assert all(np.allclose(x.transforms[0], y.transforms[0]) and x.bsdf == y.bsdf
                   for x, y in zip(a.objects, b.objects))
    assert 0 < sum(got) < len(got)
