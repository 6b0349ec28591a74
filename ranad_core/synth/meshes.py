"""Procedural meshes for `ranad synth`: smooth irregular shapes that the analytic primitives cannot make.

A blob is an icosphere displaced radially by a few random waves: star-shaped, so it never intersects itself,
with concave and convex regions at several scales (self-shadowing and interreflection that spheres and cubes
lack). A torus has a hole the camera sees through. Both are written as Wavefront OBJ files (positions, smooth
normals, uvs) into a cache folder, named by a hash of their parameters, so every frame and
every worker process loads the same file and a scene's description stays a small dictionary.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile

import numpy as np

MESH_KINDS = ("blob", "torus")


def icosphere(levels: int) -> tuple[np.ndarray, np.ndarray]:
    """Unit-sphere vertices [V, 3] and triangles [F, 3] of an icosahedron subdivided `levels` times."""
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    verts = [np.asarray(p, float) / np.linalg.norm(p) for p in v]
    faces = f
    for _ in range(levels):
        mid = {}

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = verts[a] + verts[b]
                verts.append(p / np.linalg.norm(p))
                mid[key] = len(verts) - 1
            return mid[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new
    return np.asarray(verts), np.asarray(faces, np.int64)


def vertex_normals(pos: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted averages of the faces' normals around each vertex (unit length)."""
    n = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
    out = np.zeros_like(pos)
    for k in range(3):
        np.add.at(out, faces[:, k], n)
    return out / np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)


def blob(seed: int, waves: int, amplitude: float, levels: int = 4) -> dict:
    """A blob: the unit icosphere with its radius r(d) = 1 + sum of `waves` waves a_k sin(f_k d.w_k + phase_k)
    over random directions w_k and frequencies 1-4, the amplitudes summing to `amplitude` (< 1 keeps r > 0:
    star-shaped, no self-intersection). uvs: longitude and latitude of d, unwrapped across the seam (faces that
    cross it get their own uvs, u + 1, so no face stretches over the whole texture)."""
    if not 0 <= amplitude < 1:
        raise ValueError(f"blob amplitude must be in [0, 1), not {amplitude}")
    rng = np.random.default_rng(seed)
    d, faces = icosphere(levels)
    w = rng.normal(size=(waves, 3))
    w /= np.linalg.norm(w, axis=1, keepdims=True)
    freq = rng.uniform(1.0, 4.0, waves)
    amp = rng.dirichlet(np.ones(waves)) * amplitude
    phase = rng.uniform(0, 2 * np.pi, waves)
    pos = d * (1.0 + (amp * np.sin(d @ w.T * freq + phase)).sum(1))[:, None]
    uv = np.stack([np.arctan2(d[:, 0], -d[:, 2]) / (2 * np.pi) + 0.5, np.arccos(np.clip(d[:, 1], -1, 1)) / np.pi], 1)
    face_uv = faces.copy()
    fu = uv[faces, 0]
    crossing = fu.max(1) - fu.min(1) > 0.5
    extra = []
    for f in np.nonzero(crossing)[0]:
        for k in range(3):
            if fu[f, k] < 0.5:
                extra.append((uv[faces[f, k], 0] + 1.0, uv[faces[f, k], 1]))
                face_uv[f, k] = len(uv) + len(extra) - 1
    uv = np.concatenate([uv, np.asarray(extra).reshape(-1, 2)])
    return dict(pos=pos, normal=vertex_normals(pos, faces), faces=faces, uv=uv, face_uv=face_uv)


def torus(minor: float, rings: int = 48, sides: int = 24) -> dict:
    """A torus of major radius 1 and `minor` radius around the z axis: positions shared across the seams (the
    surface is closed), analytic normals, uvs on a (rings + 1) x (sides + 1) grid so they run 0..1 without a
    jump."""
    if not 0 < minor < 1:
        raise ValueError(f"torus minor radius must be in (0, 1), not {minor}")
    i, j = np.meshgrid(np.arange(rings), np.arange(sides), indexing="ij")
    a, b = i / rings * 2 * np.pi, j / sides * 2 * np.pi
    ring = np.stack([np.cos(a), np.sin(a), np.zeros_like(a)], -1)
    normal = np.cos(b)[..., None] * ring + np.stack([0 * a, 0 * a, np.sin(b)], -1)
    pos = ring + minor * normal
    gi, gj = np.meshgrid(np.arange(rings + 1), np.arange(sides + 1), indexing="ij")
    uv = np.stack([gi / rings, gj / sides], -1).reshape(-1, 2)
    vi = lambda r, c: (r % rings) * sides + (c % sides)  # noqa: E731
    ti = lambda r, c: r * (sides + 1) + c  # noqa: E731
    faces, face_uv = [], []
    for r in range(rings):
        for c in range(sides):
            q = [(r, c), (r + 1, c), (r + 1, c + 1), (r, c + 1)]
            for t in ((0, 1, 2), (0, 2, 3)):
                faces.append([vi(*q[k]) for k in t])
                face_uv.append([ti(*q[k]) for k in t])
    return dict(pos=pos.reshape(-1, 3), normal=normal.reshape(-1, 3), faces=np.asarray(faces, np.int64), uv=uv,
                face_uv=np.asarray(face_uv, np.int64))


def make_mesh(params: dict) -> dict:
    """The mesh a scene's parameters describe ({"kind": "blob", "seed", "waves", "amplitude"} or {"kind":
    "torus", "minor"}): pos, normal [V, 3], faces [F, 3] into them, uv [T, 2] and face_uv [F, 3] into those."""
    if params["kind"] == "blob":
        return blob(int(params["seed"]), int(params["waves"]), float(params["amplitude"]))
    if params["kind"] == "torus":
        return torus(float(params["minor"]))
    raise ValueError(f"unknown mesh kind {params['kind']!r} (one of {', '.join(MESH_KINDS)})")


def cache_folder() -> str:
    return os.environ.get("RANAD_MESH_CACHE") or os.path.join(tempfile.gettempdir(), "ranad-synth-meshes")


def mesh_file(params: dict) -> str:
    """The OBJ file of `params` in the cache folder, written once (atomically: parallel workers may race)."""
    key = hashlib.sha1(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]
    folder = cache_folder()
    path = os.path.join(folder, f"{params['kind']}-{key}.obj")
    if os.path.exists(path):
        return path
    os.makedirs(folder, exist_ok=True)
    m = make_mesh(params)
    lines = [f"v {x:.7g} {y:.7g} {z:.7g}" for x, y, z in m["pos"]]
    lines += [f"vn {x:.7g} {y:.7g} {z:.7g}" for x, y, z in m["normal"]]
    lines += [f"vt {u:.7g} {v:.7g}" for u, v in m["uv"]]
    lines += ["f " + " ".join(f"{v + 1}/{t + 1}/{v + 1}" for v, t in zip(f, ft))
              for f, ft in zip(m["faces"], m["face_uv"])]
    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".obj.part")
    with os.fdopen(fd, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    os.replace(tmp, path)
    return path
