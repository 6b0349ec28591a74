"""The synth generator's procedural meshes and textures (pure numpy: no Mitsuba needed)."""

from __future__ import annotations

import numpy as np
import pytest

from ranad_core.synth.meshes import blob, make_mesh, mesh_file, torus
from ranad_core.synth.textures import NOISE_STYLES, noise_texels


def _edges(faces):
    return {tuple(sorted(e)) for f in faces for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0]))}


@pytest.mark.parametrize("mesh,euler", [(blob(3, 6, 0.45), 2), (blob(8, 3, 0.1), 2), (torus(0.3), 0)])
def test_meshes_are_closed_surfaces_with_outward_normals(mesh, euler):
    """Every edge is shared by exactly two faces (closed), V - E + F is the sphere's 2 or the torus's 0, the
    normals point away from the shape's centre line, and no face's uvs stretch over more than a few texels'
    worth of the map except near a blob's poles."""
    pos, faces = mesh["pos"], mesh["faces"]
    count = {}
    for f in faces:
        for e in ((f[0], f[1]), (f[1], f[2]), (f[2], f[0])):
            count[tuple(sorted(e))] = count.get(tuple(sorted(e)), 0) + 1
    assert set(count.values()) == {2}
    assert len(pos) - len(_edges(faces)) + len(faces) == euler
    if euler == 2:   # blob: star-shaped around the origin
        assert (np.linalg.norm(pos, axis=1) > 0.5).all()
        assert ((mesh["normal"] * pos).sum(1) > 0).mean() > 0.97
        polar = np.abs(pos[faces].mean(1)[:, 1]) / np.linalg.norm(pos[faces].mean(1), axis=1) > 0.95
        span = np.ptp(mesh["uv"][mesh["face_uv"]][..., 0], axis=1)
        assert span[~polar].max() < 0.1
    else:            # torus: away from the ring of radius 1
        ring = pos.copy()
        ring[:, 2] = 0
        ring /= np.linalg.norm(ring, axis=1, keepdims=True)
        assert ((mesh["normal"] * (pos - ring)).sum(1) > 0).all()
        assert np.ptp(mesh["uv"][mesh["face_uv"]][..., 0], axis=1).max() < 0.05


def test_mesh_parameters_are_checked_and_files_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("RANAD_MESH_CACHE", str(tmp_path))
    with pytest.raises(ValueError, match="amplitude"):
        blob(1, 4, 1.2)
    with pytest.raises(ValueError, match="unknown mesh kind"):
        make_mesh({"kind": "teapot"})
    params = {"kind": "torus", "minor": 0.25}
    path = mesh_file(params)
    assert path.startswith(str(tmp_path)) and mesh_file(dict(params)) == path
    text = open(path).read()
    assert text.count("\nf ") + text.startswith("f ") == len(torus(0.25)["faces"])
    assert not [p for p in tmp_path.iterdir() if p.suffix == ".part"]


@pytest.mark.parametrize("style", NOISE_STYLES)
def test_noise_textures_tile_and_stay_between_their_colours(style):
    """Each style stays within the box of its two colours, uses both ends of it, is deterministic, and wraps
    around (the jump from the last texel row/column to the first is no larger than the map's typical jumps
    between tiles or stripes)."""
    c0, c1 = [0.05, 0.2, 0.6], [0.9, 0.6, 0.1]
    params = dict(style=style, seed=4, cells=8, colour0=c0, colour1=c1)
    t = noise_texels(params).astype(np.float64)
    lo, hi = np.minimum(c0, c1), np.maximum(c0, c1)
    assert (t >= lo - 1e-6).all() and (t <= hi + 1e-6).all()
    assert np.ptp(t[..., 0]) > 0.3 * (hi[0] - lo[0])
    np.testing.assert_array_equal(t, noise_texels(params))
    for axis in (0, 1):
        steps = np.abs(np.diff(t, axis=axis)).mean(axis=(1 - axis, 2))   # each boundary's mean jump
        wrap = np.abs(np.take(t, 0, axis) - np.take(t, -1, axis)).mean()
        assert wrap <= max(steps.max(), 1e-9) * 1.05
    with pytest.raises(ValueError, match="cells"):
        noise_texels(dict(params, cells=3))
