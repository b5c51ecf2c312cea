"""Levels of detail (``serenity.scene.lod``): fewer triangles, indices into the mesh's own vertices,
an error estimate that bounds how far the surface moved, instances simplified once, a disk cache."""

import numpy as np
import pytest
import trimesh

from serenity.scene import lod
from serenity.scene.model import Mesh


def _sphere(radius=1.0, subdivisions=5, seam=True, offset=(0.0, 0.0, 0.0)) -> Mesh:
    """An icosphere (20·4^s triangles) with uvs from longitude/latitude; ``seam``: the vertices on
    one meridian split in two (uv 0 and 1), as a file would store them."""
    s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    p = np.asarray(s.vertices, np.float64)
    f = np.asarray(s.faces, np.int64)
    n = p / np.linalg.norm(p, axis=1, keepdims=True)
    u = (np.arctan2(p[:, 2], p[:, 0]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(n[:, 1], -1, 1)) / np.pi
    uv = np.stack([u, v], axis=1)
    if seam:  # faces that straddle u = 0|1 get copies of their low-u corners at u + 1
        fu = uv[f, 0]
        wrap = fu.max(axis=1) - fu.min(axis=1) > 0.5
        extra = {}
        for i in np.flatnonzero(wrap):
            for k in range(3):
                vi = f[i, k]
                if uv[vi, 0] < 0.5:
                    if vi not in extra:
                        extra[vi] = len(p) + len(extra)
                    f[i, k] = extra[vi]
        src = np.array(sorted(extra, key=extra.get), np.int64)
        p = np.concatenate([p, p[src]])
        n = np.concatenate([n, n[src]])
        uv = np.concatenate([uv, uv[src] + (1.0, 0.0)])
    return Mesh("sphere", p + offset, n, uv, f, np.zeros(len(f), np.int32))


def _surface_samples(positions, faces, per_face=12, seed=0):
    """Points spread over the triangles (uniform barycentric samples and the corners)."""
    rng = np.random.default_rng(seed)
    a, b = rng.random((2, len(faces), per_face))
    flip = a + b > 1
    a, b = np.where(flip, 1 - a, a), np.where(flip, 1 - b, b)
    p = positions[faces].astype(np.float64)
    return (p[:, 0, None] + a[..., None] * (p[:, 1] - p[:, 0])[:, None]
            + b[..., None] * (p[:, 2] - p[:, 0])[:, None]).reshape(-1, 3)


def test_levels_are_coarser_index_lists_whose_error_bounds_the_surface():
    mesh = _sphere()
    levels = lod.build_levels(mesh)
    assert levels is not None and len(levels) == len(lod.LOD_FRACTIONS)
    counts = [len(mesh.faces)] + [len(f) for f in levels.faces]
    for fraction, count in zip(lod.LOD_FRACTIONS, counts[1:], strict=True):
        assert count <= 1.1 * fraction * counts[0]
    assert np.all(np.diff(levels.error) >= 0) and levels.error[0] > 0
    for k, error in enumerate(levels.error):
        pos, vsrc, faces, source = (getattr(levels, f)[k] for f in ("positions", "vertex_source", "faces", "source"))
        assert faces.dtype == np.int32 and faces.min() >= 0 and faces.max() < len(pos) == len(vsrc)
        assert vsrc.min() >= 0 and vsrc.max() < len(mesh.positions)
        assert len(source) == len(faces) and source.max() < len(mesh.faces)
        # the level's surface lies within its error of the sphere (the mesh itself lies within 2e-4) ...
        d = np.abs(np.linalg.norm(_surface_samples(pos, faces), axis=1) - 1.0)
        assert d.max() <= error + 2e-4
        # ... and the estimate is not loose by more than a few times
        assert error < 4 * d.max() + 1e-3
        # no face turned over: outward normals on a sphere
        p = pos[faces].astype(np.float64)
        fn = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
        assert np.all(np.sum(fn * p.mean(axis=1), axis=1) > 0)
        # a vertex keeps the normal of the mesh vertex it came from, which points near where it is
        assert np.all(np.sum(mesh.normals[vsrc] * pos / np.linalg.norm(pos, axis=1, keepdims=True), axis=1) > 0.95)


def test_a_corner_keeps_its_side_of_a_uv_seam():
    mesh = _sphere(seam=True)
    levels = lod.build_levels(mesh)
    assert np.ptp(mesh.uvs[mesh.faces, 0], axis=1).max() <= 0.5  # at the poles
    for vsrc, faces in zip(levels.vertex_source, levels.faces, strict=True):
        u = mesh.uvs[vsrc[faces], 0]
        # no face jumps by ~1 across the seam
        assert np.ptp(u, axis=1).max() < 0.75


def test_small_meshes_keep_their_triangles():
    assert lod.build_levels(_sphere(subdivisions=2)) is None  # 320 triangles


def test_instances_share_one_simplification(monkeypatch):
    a = _sphere()
    r = trimesh.transformations.rotation_matrix(0.7, (0.3, 1.0, 0.2))[:3, :3]
    b = Mesh("copy", a.positions @ r.T * 2.0 + (5.0, 0.0, 0.0), a.normals @ r.T, a.uvs, a.faces, a.face_material)
    calls = []
    real = lod.build_levels
    monkeypatch.setattr(lod, "build_levels", lambda m: calls.append(m.name) or real(m))
    la, lb = lod.scene_levels([a, b], [True, True], cache=False)
    assert calls == ["sphere"]
    assert all(np.array_equal(x, y) for x, y in zip(la.faces, lb.faces, strict=True))
    assert np.allclose(lb.error, 2.0 * la.error)
    # b's levels are a's moved as b is
    for pa, pb in zip(la.positions, lb.positions, strict=True):
        assert np.allclose(pa @ r.T * 2.0 + (5.0, 0.0, 0.0), pb, atol=1e-4)


def test_levels_are_cached_on_disk(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path))
    mesh = _sphere()
    first = lod.scene_levels([mesh], [True])
    assert len(list(tmp_path.glob("lod-*.npz"))) == 1
    monkeypatch.setattr(lod, "build_levels", lambda m: pytest.fail("simplified again"))
    again = lod.scene_levels([mesh], [True])
    assert np.array_equal(again[0].error, first[0].error)
    assert all(np.array_equal(x, y) for x, y in zip(again[0].faces, first[0].faces, strict=True))
    assert lod.scene_levels([mesh], [False]) == [None]
