"""Levels of detail for the rasterised passes: coarser versions of each dense mesh, chosen per draw by
how far a level's surface may lie from the mesh's, in pixels of the image (or texels of a shadow map).

A production interior spends most of its triangles on small objects: the breakfast room's chairs,
teapot, cups and spoons hold 80 % of its 262k triangles at 1–20 triangles per covered pixel at
640×360, and a CPU rasteriser pays per triangle (vertex fetch, clipping, set-up and binning), so its
G-buffer costs about as much at 64×36 as at 640×360. A level needs only as many triangles as the
pixels can show.

How a level is made. The mesh is welded (vertices at one position are one, whatever their normals
or uvs) and simplified by quadric error metrics (Garland & Heckbert 1997; the ``fast-simplification``
package) to a sixteenth of its triangles; the prefixes of its collapse sequence down to a half and a
quarter of the triangles are the first two levels, the whole sequence the third. A level's vertex is a vertex of the
mesh moved to where its collapses put it; it keeps that vertex's normal, uv and tangent. At a
vertex that the file splits (a uv seam, a hard edge), a face's corner takes the copy nearest in uv
and normal to the copy it had, so a level keeps the seam; where the seam's vertex collapsed onto one
that the seam does not split, the corner keeps its own copy's attributes at the new position.

A level's error estimates how far the surface moved, both ways (a Hausdorff distance sampled at
vertices): the farthest a vertex of the mesh lies from the level's triangles, or a vertex or face
centre of the level from the mesh's (a nearest-point search over 4 points per triangle bounds each
distance from above, and the largest are refined against every triangle that could be nearer, until
the bound is within 25 % of the exact largest distance). A pass draws each mesh
at the coarsest level whose error, projected at the mesh's nearest point, stays below its bound
(``SceneGL.levels``). Meshes with alpha cut-outs, ray-traced materials or the ground plane keep
their triangles.

Instances (the six chairs of one model) share their simplification: a mesh whose faces equal an
earlier one's and whose vertices are that one's under a rotation and a uniform scale reuses its
levels. The levels of a whole scene are cached on disk (``cache_dir()``) under a digest of its
geometry.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from serenity.io.atomic import atomic_write
from serenity.scene.cache import cache_dir

#: meshes with fewer triangles keep theirs (a draw of a few thousand triangles costs little)
LOD_MIN_TRIANGLES = 2048
#: the fractions of the mesh's triangles the levels aim at, finest first
LOD_FRACTIONS = (1 / 2, 1 / 4, 1 / 16)
#: ... and never below this many triangles
LOD_MIN_LEVEL_TRIANGLES = 96
#: a level is kept only if it has at most this fraction of the triangles of the level before it
LOD_MIN_GAIN = 0.8
#: a corner whose new vertex has no copy within this (squared uv distance + squared normal
#: distance) of the copy it had keeps that copy's attributes (a uv seam or hard edge collapsed away)
LOD_ATTRIBUTE_JUMP = 0.25
#: bump when what a cached level holds changes in a way its key does not see
LOD_CACHE_VERSION = 3


@dataclass
class MeshLevels:
    """The coarser levels of one mesh, finest first (level 0, the mesh itself, is not stored)."""

    positions: list[np.ndarray]
    """Per level: (V_l, 3) float32 world positions of its vertices."""
    vertex_source: list[np.ndarray]
    """Per level: (V_l,) int32, the mesh vertex whose normal, uv and tangent each vertex takes."""
    faces: list[np.ndarray]
    """Per level: (F_l, 3) int32 indices into its own vertices."""
    source: list[np.ndarray]
    """Per level: (F_l,) int32, the mesh face each level face was (its material is that face's)."""
    error: np.ndarray
    """(L,) metres: how far each level's surface may lie from the mesh's."""

    def __len__(self) -> int:
        return len(self.faces)


def _weld(positions: np.ndarray, faces: np.ndarray):
    """Unique positions (W, 3) float32, each vertex's welded index (V,), and the faces in welded
    indices with those that weld to a point or a line dropped (their original indices)."""
    up, inv = np.unique(positions, axis=0, return_inverse=True)
    inv = inv.reshape(-1).astype(np.int64)
    wf = inv[faces]
    ok = (wf[:, 0] != wf[:, 1]) & (wf[:, 1] != wf[:, 2]) & (wf[:, 0] != wf[:, 2])
    return up, inv, wf[ok], np.flatnonzero(ok)


def _point_triangle_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N,) distances from points p to triangles abc (each (N, 3)): to the plane where p projects
    inside the triangle, else to the nearest edge."""
    ab, ac = b - a, c - a
    n = np.cross(ab, ac)
    nn = np.sum(n * n, axis=1)
    ap = p - a
    # barycentrics of p's projection
    d1, d2 = np.sum(ab * ap, axis=1), np.sum(ac * ap, axis=1)
    abab, acac, abac = np.sum(ab * ab, axis=1), np.sum(ac * ac, axis=1), np.sum(ab * ac, axis=1)
    den = np.where(nn > 0, abab * acac - abac * abac, 1.0)
    v = (acac * d1 - abac * d2) / den
    w = (abab * d2 - abac * d1) / den
    inside = (nn > 0) & (v >= 0) & (w >= 0) & (v + w <= 1)
    plane = np.abs(np.sum(ap * n, axis=1)) / np.sqrt(np.where(nn > 0, nn, 1.0))

    def segment(q, e0, e1):
        e = e1 - e0
        t = np.clip(np.sum((q - e0) * e, axis=1) / np.maximum(np.sum(e * e, axis=1), 1e-300), 0.0, 1.0)
        return np.linalg.norm(q - (e0 + t[:, None] * e), axis=1)

    edges = np.minimum(np.minimum(segment(p, a, b), segment(p, b, c)), segment(p, c, a))
    return np.where(inside, plane, edges)


#: barycentric points each triangle is represented by in ``_Surface``'s search
_SAMPLES = np.array([[1 / 3, 1 / 3, 1 / 3], [2 / 3, 1 / 6, 1 / 6], [1 / 6, 2 / 3, 1 / 6], [1 / 6, 1 / 6, 2 / 3]])


def _grid_samples(m: int) -> np.ndarray:
    """Barycentric centres of the m x m upward sub-triangles of a triangle."""
    i, j = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
    keep = i + j <= m - 1
    a, b = (i[keep] + 1 / 3) / m, (j[keep] + 1 / 3) / m
    return np.stack([a, b, 1.0 - a - b], axis=1)


class _Surface:
    """A triangle surface prepared for distance queries: sample points on its triangles in a k-d tree."""

    def __init__(self, points: np.ndarray, faces: np.ndarray):
        from scipy.spatial import cKDTree  # scipy and the simplifier load only for a scene with dense meshes

        self.tri = points[faces].astype(np.float64)                    # (F, 3, 3)
        centre = self.tri.mean(axis=1)
        reach = np.linalg.norm(self.tri - centre[:, None], axis=2).max(axis=1)  # centre to farthest corner
        usual = float(np.quantile(reach, 0.95)) if len(reach) else 0.0  # the usual triangle's reach
        # sample points: 4 per usual triangle, and on a larger one the centres of an m x m
        # subdivision, m its reach in usual reaches (at most 8), so that a point over a large
        # triangle finds it among its nearest samples
        m = np.clip(np.ceil(reach / max(usual, 1e-300)), 1, 8).astype(np.int64)
        samples, owner = [], []
        for k in np.unique(m):
            ts = np.flatnonzero(m == k)
            bary = _SAMPLES if k == 1 else _grid_samples(int(k))
            samples.append(np.einsum("sk,fkd->fsd", bary, self.tri[ts]).reshape(-1, 3))
            owner.append(np.repeat(ts, len(bary)))
        self.owner = np.concatenate(owner)
        self.tree = cKDTree(np.concatenate(samples), balanced_tree=False, compact_nodes=False)
        self.lo, self.hi = self.tri.min(axis=1), self.tri.max(axis=1)  # each triangle's box

    def distance(self, q: np.ndarray, near: int = 3) -> np.ndarray:
        """(N,) distances from the points ``q`` to the surface: to the nearest of the triangles of the
        ``near`` sample points nearest each point, so at least the distance to the surface."""
        k = min(near, self.tree.n)
        _, idx = self.tree.query(q, k=k)
        idx = self.owner[idx.reshape(len(q), k)]
        best = np.full(len(q), np.inf)
        for j in range(k):
            t = self.tri[idx[:, j]]
            best = np.minimum(best, _point_triangle_distance(q, t[:, 0], t[:, 1], t[:, 2]))
        return best

    def exact(self, x: np.ndarray, bound: np.ndarray) -> np.ndarray:
        """(N,) distances from the points ``x`` to the surface, given upper ``bound``s of them: to the
        nearest of the triangles whose boxes lie within each bound."""
        b = bound[:, None, None]
        near = np.all((x[:, None] >= self.lo[None] - b) & (x[:, None] <= self.hi[None] + b), axis=2)  # (N, F)
        point, tri = np.nonzero(near)
        t = self.tri[tri]
        d = _point_triangle_distance(x[point], t[:, 0], t[:, 1], t[:, 2])
        out = np.full(len(x), np.inf)
        np.minimum.at(out, point, d)
        return out

    def farthest(self, q: np.ndarray, slack: float = 1.25, batch: int = 16) -> float:
        """An upper bound, within ``slack`` times, of the largest distance from the points ``q`` to
        the surface: the search's estimates (upper bounds) refined exactly from the largest down, a
        batch at a time, until the largest left is within ``slack`` of the largest exact distance."""
        if not len(q):
            return 0.0
        estimate = self.distance(q)
        order = np.argsort(-estimate)
        best = 0.0
        for start in range(0, len(order), batch):
            idx = order[start:start + batch]
            if estimate[idx[0]] <= slack * best:
                return max(best, float(estimate[idx[0]]))
            best = max(best, float(self.exact(q[idx], estimate[idx]).max()))
        return best


def _copies(inv: np.ndarray, n_welded: int):
    """CSR of the vertices welded into each position: order (V,) and starts (W + 1,)."""
    order = np.argsort(inv, kind="stable")
    starts = np.searchsorted(inv[order], np.arange(n_welded + 1))
    return order, starts


def _level(mesh, up, inv, wf, kept, copies, collapses, surface: _Surface):
    """One level from a prefix of the collapse sequence: (positions, vertex source, faces, face source,
    error), or None when every face collapsed."""
    import fast_simplification

    points, _, mapping = fast_simplification.replay_simplification(up, wf.astype(np.int32), collapses)
    points = np.asarray(points, np.float32)
    mapping = np.asarray(mapping, np.int64)
    # the welded vertex each one ends on: follow "i1 collapsed into i0" to the end of its chain
    root = np.arange(len(up), dtype=np.int64)
    root[collapses[:, 1]] = collapses[:, 0]
    while True:
        nxt = root[root]
        if np.array_equal(nxt, root):
            break
        root = nxt
    target = root[wf]                                     # (F, 3) welded vertex each corner moves to
    ok = (target[:, 0] != target[:, 1]) & (target[:, 1] != target[:, 2]) & (target[:, 0] != target[:, 2])
    target, source = target[ok], kept[ok]
    if not len(target):
        return None
    # a face that collapses onto another's corners is drawn once
    _, first = np.unique(np.sort(target, axis=1), axis=0, return_index=True)
    first.sort()
    target, source = target[first], source[first]
    # each corner: the copy of its new vertex nearest in uv and normal to the copy it had, or where no
    # copy is near (a seam vertex collapsed onto one that the seam does not split), the one it had
    old = mesh.faces[source].astype(np.int64)              # (F, 3) unwelded
    order, starts = copies
    count = starts[target + 1] - starts[target]

    def distance(cand):
        return (np.sum((mesh.uvs[cand] - mesh.uvs[old]) ** 2, axis=-1)
                + np.sum((mesh.normals[cand] - mesh.normals[old]) ** 2, axis=-1))

    best = order[starts[target]]
    best_cost = distance(best)
    for j in range(1, int(count.max())):
        has = count > j
        cand = np.where(has, order[np.minimum(starts[target] + j, len(order) - 1)], 0)
        cost = distance(cand)
        better = has & (cost < best_cost)
        best = np.where(better, cand, best)
        best_cost = np.where(better, cost, best_cost)
    best = np.where(best_cost > LOD_ATTRIBUTE_JUMP, old, best)
    # the level's vertices: one per (copy whose attributes it takes, welded vertex it stands on)
    pairs, faces = np.unique(np.stack([best.reshape(-1), target.reshape(-1)], axis=1), axis=0, return_inverse=True)
    faces = faces.reshape(-1, 3)
    vertex_source = pairs[:, 0]
    positions = points[mapping[pairs[:, 1]]]
    # error: the farther of the mesh's vertices from the level's surface and the level's vertices and
    # face centres from the mesh's surface
    mesh_points = up[np.unique(wf)].astype(np.float64)
    level_points = np.concatenate([positions, positions[faces].mean(axis=1)]).astype(np.float64)
    error = max(_Surface(positions, faces).farthest(mesh_points), surface.farthest(level_points))
    return positions, vertex_source.astype(np.int32), faces.astype(np.int32), source.astype(np.int32), error


def build_levels(mesh) -> MeshLevels | None:
    """The coarser levels of ``mesh`` (a ``Mesh``), or None when it has fewer than ``LOD_MIN_TRIANGLES``
    triangles or no level saves enough (``LOD_MIN_GAIN``)."""
    n = len(mesh.faces)
    if n < LOD_MIN_TRIANGLES:
        return None
    up, inv, wf, kept = _weld(mesh.positions, mesh.faces.astype(np.int64))
    if len(wf) < LOD_MIN_TRIANGLES:
        return None
    import fast_simplification

    last = max(LOD_MIN_LEVEL_TRIANGLES, int(len(wf) * LOD_FRACTIONS[-1]))
    _, tris, collapses = fast_simplification.simplify(up.astype(np.float64), wf, target_count=last,
                                                      return_collapses=True)
    collapses = np.asarray(collapses, np.int64).reshape(-1, 2)
    # a collapse removes about two faces: the prefixes that reach each level's count
    prefixes = [min(len(collapses), max(0, (len(wf) - int(len(wf) * f)) // 2)) for f in LOD_FRACTIONS[:-1]]
    prefixes.append(len(collapses))
    copies = _copies(inv, len(up))
    surface = None  # the mesh's own, for the levels' errors
    out = MeshLevels([], [], [], [], np.zeros(0))
    error = []
    previous = n
    for k in sorted(set(prefixes)):
        if k == 0:
            continue
        if surface is None:
            surface = _Surface(up, wf)
        level = _level(mesh, up, inv, wf, kept, copies, collapses[:k], surface)
        if level is None or len(level[2]) > LOD_MIN_GAIN * previous:
            continue
        for field, value in zip(("positions", "vertex_source", "faces", "source"), level[:4], strict=True):
            getattr(out, field).append(value)
        error.append(max(level[4], error[-1] if error else 0.0))
        previous = len(level[2])
    if not error:
        return None
    out.error = np.asarray(error, np.float64)
    return out


def _similarity(a: np.ndarray, b: np.ndarray):
    """The map x → s (x − ma) R + mb (row vectors; s a uniform scale, R a rotation) that takes the
    points ``a`` onto ``b`` vertex for vertex, as (s, R, ma, mb); None when none fits within 1e-4 of
    the points' spread."""
    ma, mb = a.mean(axis=0, dtype=np.float64), b.mean(axis=0, dtype=np.float64)
    a = a.astype(np.float64) - ma
    b = b.astype(np.float64) - mb
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    if na == 0.0 or nb == 0.0:
        return None
    u, _, vt = np.linalg.svd(a.T @ b)
    r = u @ vt
    if np.linalg.det(r) < 0:
        return None  # a mirror image: its faces wind the other way
    s = nb / na
    if np.max(np.abs(s * a @ r - b)) > 1e-4 * nb / np.sqrt(len(b)):
        return None
    return float(s), r, ma, mb


def _mesh_digest(h, mesh) -> None:
    for a in (mesh.positions, mesh.normals, mesh.uvs, mesh.faces):
        h.update(np.ascontiguousarray(a).tobytes())


def scene_levels(meshes, eligible, cache: bool = True, progress=None) -> list[MeshLevels | None]:
    """The levels of each mesh in ``meshes`` where ``eligible`` (a bool per mesh) allows them, None
    elsewhere; read from or written to the disk cache when ``cache``. ``progress(done, total)`` is
    called after each simplified mesh."""
    eligible = [bool(e) and len(m.faces) >= LOD_MIN_TRIANGLES for m, e in zip(meshes, eligible, strict=True)]
    if not any(eligible):
        return [None] * len(meshes)
    h = hashlib.blake2b(digest_size=16)
    h.update(f"lod{LOD_CACHE_VERSION} {LOD_MIN_TRIANGLES} {LOD_FRACTIONS} "
             f"{LOD_MIN_LEVEL_TRIANGLES} {LOD_MIN_GAIN} {LOD_ATTRIBUTE_JUMP}".encode())
    for m, e in zip(meshes, eligible, strict=True):
        h.update(b"+" if e else b"-")
        if e:
            _mesh_digest(h, m)
    path = cache_dir() / f"lod-{h.hexdigest()}.npz" if cache else None
    if path is not None and path.exists():
        read = _read(path, len(meshes))
        if read is not None:
            return read
    out: list[MeshLevels | None] = [None] * len(meshes)
    shapes: dict[bytes, list[int]] = {}
    todo = [i for i, e in enumerate(eligible) if e]
    for done, i in enumerate(todo, 1):
        m = meshes[i]
        key = hashlib.blake2b(m.faces.tobytes(), digest_size=16).digest() + len(m.positions).to_bytes(8, "little")
        for j in shapes.get(key, []):
            fit = _similarity(meshes[j].positions, m.positions)
            if fit is not None and out[j] is not None:
                s, r, ma, mb = fit
                lv = out[j]
                moved = [(s * (p.astype(np.float64) - ma) @ r + mb).astype(np.float32) for p in lv.positions]
                out[i] = MeshLevels(moved, lv.vertex_source, lv.faces, lv.source, lv.error * s)
                break
        else:
            out[i] = build_levels(m)
            shapes.setdefault(key, []).append(i)
        if progress is not None:
            progress(done, len(todo))
    if path is not None:
        _write(path, out)
    return out


_LEVEL_FIELDS = ("positions", "vertex_source", "faces", "source")


def _write(path, levels) -> None:
    arrays = {}
    for i, lv in enumerate(levels):
        if lv is None:
            continue
        arrays[f"m{i}_error"] = lv.error
        for k in range(len(lv)):
            for field in _LEVEL_FIELDS:
                arrays[f"m{i}_l{k}_{field}"] = getattr(lv, field)[k]

    def write(tmp):
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)

    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write(path, write)
    except OSError:
        pass  # an unwritable cache only costs the next start the simplification


def _read(path, n_meshes: int) -> list[MeshLevels | None] | None:
    try:
        with np.load(path, allow_pickle=False) as z:
            out: list[MeshLevels | None] = [None] * n_meshes
            for i in range(n_meshes):
                if f"m{i}_error" not in z.files:
                    continue
                error = z[f"m{i}_error"]
                out[i] = MeshLevels(*([z[f"m{i}_l{k}_{field}"] for k in range(len(error))]
                                      for field in _LEVEL_FIELDS), error)
            return out
    except (OSError, ValueError, KeyError):
        return None
