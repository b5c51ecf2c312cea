"""Two-level ray tracing (``serenity.kernels.dynamic``, ``serenity.kernels.two_level``): rigid objects in
their own BVHs beside a static kd-tree, against a kd-tree built over the posed scene (the static
triangles, then every object's triangles transformed to world space, so the triangle numbers are the
same).

The two cannot agree bit for bit: the reference intersects the posed triangles' float32-rounded world
vertices, the two-level tracer the float32 object-space triangles with the ray carried into object
space. How they may differ:

- t: by ``T_REL`` of t (the tolerance the kd-tree's agreement with Embree uses: float32 t from two
  different watertight tests) plus ``POS_EPS`` (a millionth of the scene's size: a posed vertex's
  float32 rounding is ~6e-8 of its coordinates) seen along the ray, ÷ |d|·cos of the incidence;
- the triangle: only where the ray meets an edge or vertex (within ``EDGE_EPS``, ÷ the cos of the
  incidence): two triangles share it (same t), or the ray grazes a silhouette one of them meets and
  the other passes;
- barycentrics, on the same triangle: the points they name on it by ``BARY_EPS`` (÷ the cos of the
  incidence), a millionth of the scene's size (the thin plate's 2 mm sides turn a posed vertex's
  rounding into barycentrics ~4e-4 apart: a point's distance is the measure that does not depend on
  a triangle's shape).

Seen on these tests' rays (CPU): t within 0.17 of its tolerance, barycentrics within 0.17 of theirs,
0.3-0.5 % of the random and aimed rays on another triangle beyond a tie (a grazed edge), 3-4 % tied
at a shared edge (the rays aimed at vertices and edges).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from serenity.device import init_warp
from serenity.errors import SerenityError
from serenity.kernels.dynamic import MAX_CONDITION, TOP_LEVELS, DynamicGeometry
from serenity.kernels.kdtree import KdTree
from serenity.kernels.two_level import TwoLevelTracer

wp = init_warp()

SCENE = 12.0  # the scene's size (m): the static ground is 12 m across
T_REL = 1e-5
POS_EPS = 1e-6 * SCENE
EDGE_EPS = 1e-5 * SCENE
BARY_EPS = 1e-6 * SCENE


# ---------------------------------------------------------------------------------------------
# scenes


def _mesh(m) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(m.vertices, np.float32), np.asarray(m.faces, np.int32)


def static_scene() -> tuple[np.ndarray, np.ndarray]:
    """A ground quad (12 m), a wall box and a ball: 2 + 12·4 + 320 triangles."""
    ground = (np.array([[-6, 0, -6], [6, 0, -6], [6, 0, 6], [-6, 0, 6]], np.float32),
              np.array([[0, 2, 1], [0, 3, 2]], np.int32))
    wall = trimesh.creation.box((6.0, 3.0, 0.3)).subdivide()
    wall.apply_translation((0.0, 1.5, -4.0))
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.8)
    ball.apply_translation((4.0, 0.8, 3.0))
    parts = [ground, _mesh(wall), _mesh(ball)]
    v = np.concatenate([p[0] for p in parts])
    offs = np.cumsum([0] + [len(p[0]) for p in parts[:-1]])
    f = np.concatenate([p[1] + o for p, o in zip(parts, offs, strict=True)])
    return v, f


def dynamic_objects() -> list[tuple[np.ndarray, np.ndarray]]:
    """A sphere (1280 triangles), a box, a thin plate (2 mm) and a small ball that is posed inside the
    box (an object inside another's bounds)."""
    return [_mesh(trimesh.creation.icosphere(subdivisions=3, radius=0.7)),
            _mesh(trimesh.creation.box((1.4, 1.0, 1.2)).subdivide()),
            _mesh(trimesh.creation.box((1.6, 0.002, 1.1))),
            _mesh(trimesh.creation.icosphere(subdivisions=2, radius=0.2))]


def random_rotation(rng) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q *= np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def random_poses(rng, uneven: bool = False) -> np.ndarray:
    """(4, 4, 4) poses of ``dynamic_objects``: random rotations, translations over the ground, uniform
    scales 0.5-1.8 (``uneven``: a different scale per axis); the small ball inside the box."""
    m = np.tile(np.eye(4), (4, 1, 1))
    for k in range(3):
        s = rng.uniform(0.5, 1.8, 3) if uneven else np.full(3, rng.uniform(0.5, 1.8))
        m[k, :3, :3] = random_rotation(rng) @ np.diag(s)
        m[k, :3, 3] = rng.uniform((-4.0, 0.8, -3.0), (4.0, 3.0, 4.0))
    inner = np.eye(4)
    inner[:3, 3] = rng.uniform(-0.25, 0.25, 3)
    m[3] = m[1] @ inner
    return m


def posed_reference(static, dyn: DynamicGeometry) -> tuple[KdTree, np.ndarray, np.ndarray]:
    """The kd-tree of the posed scene (static triangles first), its vertices and faces."""
    sv, sf = static
    pv, pf = dyn.posed_triangles()
    v = np.concatenate([sv, pv])
    f = np.concatenate([sf, pf + len(sv)])
    return KdTree.build(v, f, cache=False, progress=False), v, f


def make(device, top_level: str = "bvh", objects=None):
    static = static_scene()
    tree = KdTree.build(*static, cache=False, progress=False)
    dyn = DynamicGeometry(device, top_level=top_level)
    for v, f in objects or dynamic_objects():
        dyn.add(v, f)
    return static, tree, dyn, TwoLevelTracer(tree, dyn)


# ---------------------------------------------------------------------------------------------
# rays


def scene_rays(rng, dyn: DynamicGeometry, n: int = 6000) -> tuple[np.ndarray, np.ndarray]:
    """Random rays from anywhere over the ground, rays from inside each object's world box, rays aimed
    at the posed objects' vertices and edges (shared edges: ties), and rays that miss everything."""
    o = [rng.uniform((-6, 0.01, -6), (6, 5, 6), (n, 3))]
    d = [rng.normal(size=(n, 3))]
    pv, pf = dyn.posed_triangles()
    for k, first in enumerate(dyn.first_triangles):
        count = len(dynamic_objects()[k][1])
        used = pv[np.unique(pf[first:first + count])]
        lo, hi = used.min(axis=0), used.max(axis=0)
        o.append(rng.uniform(lo, hi, (n // 4, 3)))
        d.append(rng.normal(size=(n // 4, 3)))
    tri = pv[pf[rng.integers(0, len(pf), n)]].astype(np.float64)
    s = rng.uniform(0, 1, (n, 1))
    targets = np.where(rng.uniform(size=(n, 1)) < 0.3, tri[:, 0], tri[:, 0] + s * (tri[:, 1] - tri[:, 0]))
    src = rng.uniform((-6, 0.2, -6), (6, 5, 6), (n, 3))
    o.append(src)
    d.append(targets - src)
    o.append(rng.uniform((-6, 9, -6), (6, 10, 6), (500, 3)))  # above everything, looking up: misses
    d.append(rng.normal(size=(500, 3)) * (1, 0, 1) + (0, 1, 0))
    return np.concatenate(o).astype(np.float32), np.concatenate(d).astype(np.float32)


def grazing_rays(rng, dyn: DynamicGeometry, n: int = 4000) -> tuple[np.ndarray, np.ndarray]:
    """Rays that graze the posed sphere (object 0: at 1e-4 to 0.1 rad to a face, aimed at a random point
    of it, from outside) and rays in the mid-plane of the thin plate (object 2: its 2 mm sides head on,
    its faces edge on)."""
    pv, pf = dyn.posed_triangles()
    count = len(dynamic_objects()[0][1])
    tri = pv[pf[rng.integers(0, count, n)]].astype(np.float64)
    w = rng.dirichlet((1, 1, 1), n)
    pt = np.einsum("ij,ijk->ik", w, tri)
    nrm = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)  # outward (the icosphere's faces wind outward)
    tan = np.cross(nrm, rng.normal(size=(n, 3)))
    tan /= np.linalg.norm(tan, axis=1, keepdims=True)
    d1 = tan - 10 ** rng.uniform(-4, -1, (n, 1)) * nrm
    o1 = pt - 2.0 * d1
    pl = dyn.transforms[2]
    q = rng.uniform(-1.2, 1.2, (n, 3)) * (1, 0, 1)  # in the plate's mid-plane, in and around it
    u = rng.normal(size=(n, 3)) * (1, 0, 1)
    d2 = u @ pl[:3, :3].T
    o2 = q @ pl[:3, :3].T + pl[:3, 3] - 2.0 * d2
    return np.concatenate([o1, o2]).astype(np.float32), np.concatenate([d1, d2]).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# comparison


def _triangles(v, f, prim):
    return v[f[np.maximum(prim, 0)]].astype(np.float64)


def _edge_distance(p, tri):
    """Distance from points ``p`` (N,3) to the nearest edge of triangles ``tri`` (N,3,3)."""
    best = np.full(len(p), np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):
        e = tri[:, b] - tri[:, a]
        s = np.clip(np.einsum("ij,ij->i", p - tri[:, a], e) / np.maximum(np.einsum("ij,ij->i", e, e), 1e-300), 0, 1)
        best = np.minimum(best, np.linalg.norm(p - (tri[:, a] + s[:, None] * e), axis=1))
    return best


def _incidence(tri, d):
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return np.abs(np.einsum("ij,ij->i", n, d)) / np.linalg.norm(d, axis=1)


def assert_agree(got, ref, v, f, o, d, max_other: float = 0.01, tmin: float = 0.0, tmax=np.inf) -> dict:
    """``got`` (two-level) and ``ref`` (posed kd-tree) agree as the module docstring says (a hit within
    the t tolerance of ``tmin`` or ``tmax`` may be in one and not the other); returns the largest
    differences seen and the shares of rays on another triangle."""
    o64, d64 = o.astype(np.float64), d.astype(np.float64)
    dl = np.linalg.norm(d64, axis=1)
    hit_g, hit_r = got.prim >= 0, ref.prim >= 0
    tri_g, tri_r = _triangles(v, f, got.prim), _triangles(v, f, ref.prim)
    cos_g, cos_r = _incidence(tri_g, d64), _incidence(tri_r, d64)
    p_g = o64 + np.where(hit_g, got.t, 0)[:, None] * d64
    p_r = o64 + np.where(hit_r, ref.t, 0)[:, None] * d64
    edge_g = hit_g & (_edge_distance(p_g, tri_g) <= EDGE_EPS / np.maximum(cos_g, 1e-2))
    edge_r = hit_r & (_edge_distance(p_r, tri_r) <= EDGE_EPS / np.maximum(cos_r, 1e-2))
    # a hit the other misses: a silhouette edge that one meets and the other passes, or a hit at tmin
    # or tmax
    def at_bound(t, cos):
        tol = T_REL * np.where(np.isfinite(t), t, 0) + POS_EPS / (dl * np.maximum(cos, 1e-3))
        finite = np.where(np.isfinite(t), t, -1.0)
        return (np.abs(finite - tmin) <= tol) | (np.abs(finite - tmax) <= tol)

    edge_g |= hit_g & at_bound(got.t, cos_g)
    edge_r |= hit_r & at_bound(ref.t, cos_r)
    only_g, only_r = hit_g & ~hit_r, hit_r & ~hit_g
    assert edge_g[only_g].all(), f"{np.count_nonzero(only_g & ~edge_g)} hits the reference misses, off any edge"
    assert edge_r[only_r].all(), f"{np.count_nonzero(only_r & ~edge_r)} reference hits missed, off any edge"
    both = hit_g & hit_r
    tol = T_REL * np.where(both, ref.t, 0) + POS_EPS / (dl * np.maximum(cos_r, 1e-3))
    dt = np.abs(np.where(both, got.t, 0) - np.where(both, ref.t, 0))
    close = dt <= tol
    same = both & (got.prim == ref.prim)
    assert close[same].all(), f"t off on the same triangle: {np.max((dt / tol)[same]):.3g} × the tolerance"
    # barycentrics: the points they name on the triangle
    w_g = np.stack([1 - got.u - got.v, got.u, got.v], 1).astype(np.float64)
    w_r = np.stack([1 - ref.u - ref.v, ref.u, ref.v], 1).astype(np.float64)
    dp = np.linalg.norm(np.einsum("ij,ijk->ik", w_g - w_r, tri_r), axis=1)[same]
    bary_tol = (BARY_EPS / np.maximum(cos_r, 1e-3))[same]
    assert (dp <= bary_tol).all(), f"barycentrics off: {np.max(dp / bary_tol):.3g} × the tolerance"
    other = both & ~same
    # another triangle: both at one shared edge or vertex (same t), or the nearer one at a grazed edge
    nearer_at_edge = np.where(got.t < ref.t, edge_g, edge_r)
    ok = (close & edge_g & edge_r) | (~close & nearer_at_edge)
    assert ok[other].all(), f"{np.count_nonzero(other & ~ok)} rays on another triangle, not at an edge"
    share = np.count_nonzero((other & ~close) | only_g | only_r) / len(o)  # beyond ties at a shared edge
    assert share <= max_other, share
    assert np.array_equal(np.isinf(got.t), ~hit_g) and np.all(got.prim[~hit_g] == -1)
    return {"t_over_tol": float(np.max((dt / tol)[same], initial=0)),
            "bary_over_tol": float(np.max(dp / bary_tol, initial=0)), "grazed": share,
            "ties": float(np.mean(other & close)), "hits": float(both.mean())}


# ---------------------------------------------------------------------------------------------
# agreement with the posed scene's kd-tree


@pytest.mark.parametrize("top_level", TOP_LEVELS)
def test_closest_and_any_hits_match_a_kdtree_of_the_posed_scene(device, top_level):
    rng = np.random.default_rng(1)
    static, _, dyn, two = make(device, top_level)
    dynamic_hits = 0
    for pose in range(8):
        dyn.set_transforms(random_poses(rng, uneven=pose % 3 == 2))
        ref_tree, v, f = posed_reference(static, dyn)
        o, d = scene_rays(rng, dyn)
        got = two.intersect(o, d)
        ref = ref_tree.intersect(o, d)
        assert_agree(got, ref, v, f, o, d)
        assert np.all(got.prim[-500:] == -1) and np.all(np.isinf(got.t[-500:]))  # the rays into the sky
        dynamic_hits += np.count_nonzero(got.prim >= len(static[1]))
        occ, occ_ref = two.occluded(o, d), ref_tree.occluded(o, d)
        # any hit differs only where a closest hit did (a grazed edge)
        assert np.count_nonzero(occ != occ_ref) <= np.count_nonzero((got.prim >= 0) != (ref.prim >= 0))
        assert np.count_nonzero(occ != (got.prim >= 0)) <= 1e-3 * len(o)
    assert dynamic_hits > 10_000  # the objects are in the rays' way


def test_grazing_rays_match_where_they_are_not_at_an_edge(device):
    rng = np.random.default_rng(2)
    static, _, dyn, two = make(device)
    for _ in range(3):
        dyn.set_transforms(random_poses(rng))
        ref_tree, v, f = posed_reference(static, dyn)
        o, d = grazing_rays(rng, dyn)
        stats = assert_agree(two.intersect(o, d), ref_tree.intersect(o, d), v, f, o, d)
        assert stats["hits"] > 0.2


def test_no_ray_escapes_posed_closed_objects_through_edges_and_vertices(device):
    """The kd-tree's watertightness, kept by the objects: rays from inside closed meshes, posed (rotated,
    scaled, moved, one mirrored), aimed at every vertex and at points on every edge, all hit (closest
    and any hit). Warp's own ``mesh_query_ray`` let 48 of the icosphere's and 102 of the capsule's
    rays through (module docstring of ``serenity.kernels.dynamic``)."""
    rng = np.random.default_rng(12)
    meshes = [trimesh.creation.icosphere(subdivisions=4),
              trimesh.creation.capsule(height=1.0, radius=0.4, count=[24, 24]),
              trimesh.creation.box((1.0, 2.0, 0.5)).subdivide().subdivide()]
    total = 0
    for k, mesh in enumerate(meshes):
        assert mesh.is_watertight
        dyn = DynamicGeometry(device)
        dyn.add(*_mesh(mesh))
        m = np.eye(4)
        m[:3, :3] = random_rotation(rng) @ np.diag([-1.7, 1.7, 1.7] if k == 1 else [1.7, 1.7, 1.7])
        m[:3, 3] = rng.uniform(-5, 5, 3)
        dyn.set_transforms(m[None])
        pv, pf = dyn.posed_triangles()
        edges = np.unique(np.sort(np.concatenate([pf[:, [0, 1]], pf[:, [1, 2]], pf[:, [2, 0]]]), axis=1), axis=0)
        a, b = pv[edges[:, 0]].astype(np.float64), pv[edges[:, 1]].astype(np.float64)
        s = np.concatenate([np.full((len(edges), 1), 0.5), rng.uniform(0, 1, (len(edges), 2))], axis=1)
        targets = np.concatenate([pv, (a[:, None] + s[..., None] * (b - a)[:, None]).reshape(-1, 3)])
        for local in ((0.0, 0.0, 0.0), (0.05, -0.1, 0.03), (0.1, 0.13, -0.07)):
            c = np.asarray(local) @ m[:3, :3].T + m[:3, 3]
            o = np.broadcast_to(c, targets.shape).astype(np.float32)
            d = (targets - o).astype(np.float32)
            assert np.all(dyn.intersect(o, d).prim >= 0) and np.all(dyn.occluded(o, d))
            total += len(o)
    assert total > 50_000


def test_tmin_and_tmax_are_honoured(device):
    rng = np.random.default_rng(3)
    static, _, dyn, two = make(device)
    dyn.set_transforms(random_poses(rng))
    ref_tree, v, f = posed_reference(static, dyn)
    o, d = scene_rays(rng, dyn, 3000)
    full = ref_tree.intersect(o, d)
    n = len(o)
    # windows around the closest hit: tmax just before it, tmin just after it, and random windows
    t = np.where(np.isfinite(full.t), full.t, 10.0)
    tmax = (t * rng.choice([0.999, 1.001, 1.5, 0.3], n)).astype(np.float32)
    for tmin in (0.0, 0.05, 0.7):
        got = two.intersect(o, d, tmax, tmin=tmin)
        ref = ref_tree.intersect(o, d, tmax, tmin=tmin)
        assert_agree(got, ref, v, f, o, d, tmin=tmin, tmax=tmax)
        ok = got.prim >= 0
        assert np.all(got.t[ok] > tmin) and np.all(got.t[ok] < tmax[ok])
        occ, occ_ref = two.occluded(o, d, tmax, tmin=tmin), ref_tree.occluded(o, d, tmax, tmin=tmin)
        assert np.count_nonzero(occ != occ_ref) <= np.count_nonzero((got.prim >= 0) != (ref.prim >= 0))
        assert np.count_nonzero(occ != ok) <= 1e-3 * n
    # rays from 5 m off the sphere's centre, aimed at it: tmax before the centre keeps the near side,
    # tmin past it gives the far side
    sphere = DynamicGeometry(device)
    sphere.add(*dynamic_objects()[0])
    sphere.set_transforms(dyn.transforms[:1])
    c = dyn.transforms[0, :3, 3]
    u = rng.normal(size=(500, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    o, d = (c + 5.0 * u).astype(np.float32), (-u).astype(np.float32)
    near, far = sphere.intersect(o, d, 5.0), sphere.intersect(o, d, tmin=5.0)
    assert np.all(near.prim >= 0) and np.all(far.prim >= 0) and np.all(near.prim != far.prim)
    assert np.all(near.t < 5.0) and np.all(far.t > 5.0)
    assert np.allclose(near.t + far.t, 10.0, atol=0.05)  # a sphere: symmetric about its centre


def test_moving_an_object_gives_the_new_answer_and_keeps_its_bvh(device):
    rng = np.random.default_rng(4)
    static, tree, dyn, two = make(device)
    ids = [m.id for m in dyn._bvhs]
    a = random_poses(rng)
    dyn.set_transforms(a)
    o = np.tile(np.float32([[0.0, 1.5, 8.0]]), (2000, 1))
    target = a[0, :3, 3] + rng.normal(scale=0.2, size=(2000, 3))
    d = (target - o).astype(np.float32)
    first = two.intersect(o, d)
    assert np.mean(first.prim >= len(static[1])) > 0.5
    b = a.copy()
    b[0, :3, 3] += (0.0, 0.0, -30.0)  # the sphere leaves: what was behind it is seen
    dyn.set_transforms(b)
    ref_tree, v, f = posed_reference(static, dyn)
    moved = two.intersect(o, d)
    assert_agree(moved, ref_tree.intersect(o, d), v, f, o, d)
    assert not np.array_equal(moved.prim, first.prim)
    assert [m.id for m in dyn._bvhs] == ids  # the objects' BVHs are the ones built by add()
    dyn.set_transforms(a)
    again = two.intersect(o, d)
    assert np.array_equal(again.prim, first.prim) and np.array_equal(again.t, first.t)


def test_empty_dynamic_geometry_gives_the_kdtrees_bits(device):
    rng = np.random.default_rng(5)
    static = static_scene()
    tree = KdTree.build(*static, cache=False, progress=False)
    two = TwoLevelTracer(tree, DynamicGeometry(device))
    o = rng.uniform((-6, 0.01, -6), (6, 5, 6), (20_000, 3)).astype(np.float32)  # reordered (≥ SORT_MIN_RAYS)
    d = rng.normal(size=(20_000, 3)).astype(np.float32)
    tmax = rng.uniform(0.5, 20, 20_000).astype(np.float32)
    for tm, tmin in ((np.inf, 0.0), (tmax, 0.01), (3.0, 0.5)):
        got, ref = two.intersect(o, d, tm, tmin=tmin), tree.intersect(o, d, tm, device, tmin=tmin)
        for a, b in zip((got.t, got.prim, got.u, got.v), (ref.t, ref.prim, ref.u, ref.v), strict=True):
            assert np.array_equal(a, b)
        assert np.array_equal(two.occluded(o, d, tm, tmin=tmin), tree.occluded(o, d, tm, device, tmin=tmin))
    empty = DynamicGeometry(device).intersect(o[:10], d[:10])
    assert np.all(empty.prim == -1) and np.all(np.isinf(empty.t))


# ---------------------------------------------------------------------------------------------
# the dynamic query on its own: numbering, scale, Warp arrays, devices


def test_dynamic_alone_matches_a_kdtree_of_its_posed_triangles_with_prim_base(device):
    rng = np.random.default_rng(6)
    dyn = DynamicGeometry(device, prim_base=1000)
    for v, f in dynamic_objects():
        dyn.add(v, f)
    dyn.set_transforms(random_poses(rng))
    pv, pf = dyn.posed_triangles()
    ref_tree = KdTree.build(pv, pf, cache=False, progress=False)
    o, d = scene_rays(rng, dyn, 4000)
    got = dyn.intersect(o, d)
    ref = ref_tree.intersect(o, d)
    shifted = type(got)(t=got.t, prim=np.where(got.prim >= 0, got.prim - 1000, -1), u=got.u, v=got.v)
    assert np.all(got.prim[got.prim >= 0] >= 1000)
    stats = assert_agree(shifted, ref, pv, pf, o, d)
    assert stats["hits"] > 0.3
    occ, occ_ref = dyn.occluded(o, d), ref_tree.occluded(o, d)
    assert np.count_nonzero(occ != occ_ref) <= np.count_nonzero((got.prim >= 0) != (ref.prim >= 0))
    assert np.array_equal(occ, got.prim >= 0)


def test_t_is_in_world_units_under_scale(device):
    """Rays aimed at the posed sphere's vertices (exactly on it) from afar: t is the world distance in
    units of |d|, under uniform and non-uniform scale and a mirror."""
    rng = np.random.default_rng(7)
    v, f = dynamic_objects()[0]
    for lin in (np.eye(3) * 3.0, np.diag([0.5, 2.0, 1.25]) @ random_rotation(rng), np.diag([-1.5, 1.5, 1.5])):
        dyn = DynamicGeometry(device)
        dyn.add(v, f)
        m = np.eye(4)
        m[:3, :3] = lin
        m[:3, 3] = (1.0, 2.0, -3.0)
        dyn.set_transforms(m[None])
        pv, _ = dyn.posed_triangles()
        c = m[:3, 3]
        outward = pv.astype(np.float64) - c
        o = (pv + 10.0 * outward / np.linalg.norm(outward, axis=1, keepdims=True)).astype(np.float32)
        for length in (1.0, 0.25):
            d = ((pv - o) / np.linalg.norm(pv - o, axis=1, keepdims=True) * length).astype(np.float32)
            hits = dyn.intersect(o, d)
            expected = np.linalg.norm(pv.astype(np.float64) - o, axis=1) / length
            front = hits.prim >= 0
            assert front.mean() > 0.95  # a few vertices sit behind a neighbouring face's silhouette
            assert np.allclose(hits.t[front], expected[front], rtol=2e-5)


def test_warp_arrays_in_and_out_give_the_numpy_results(device):
    rng = np.random.default_rng(8)
    _, _, dyn, two = make(device)
    dyn.set_transforms(random_poses(rng))
    o, d = scene_rays(rng, dyn, 3000)
    tmax = rng.uniform(1, 15, len(o)).astype(np.float32)
    wo, wd = (wp.array(a, dtype=wp.vec3, device=device) for a in (o, d))
    for tm in (np.inf, tmax):
        wtm = wp.array(tm, dtype=float, device=device) if np.ndim(tm) else tm
        ref = two.intersect(o, d, tm, tmin=0.01)
        got = two.intersect(wo, wd, wtm, tmin=0.01)
        assert got.on_device and str(got.t.device) == device
        g = got.numpy()
        for a, b in zip((g.t, g.prim, g.u, g.v), (ref.t, ref.prim, ref.u, ref.v), strict=True):
            assert np.array_equal(a, b)
        occ = two.occluded(wo, wd, wtm)
        assert isinstance(occ, wp.array) and occ.dtype == wp.int32
        assert np.array_equal(occ.numpy().astype(bool), two.occluded(o, d, tm))
        alone = dyn.intersect(wo, wd, wtm)
        assert alone.on_device and np.array_equal(alone.numpy().prim, dyn.intersect(o, d, tm).prim)


def test_top_levels_and_thread_counts_agree_bit_for_bit(device):
    """37 small objects (a top level of 64 leaves, 27 of them empty) over the static scene: both top
    levels, on 1 and 2 threads, give the same bits, and they agree with the posed scene's kd-tree."""
    rng = np.random.default_rng(9)
    objects = [dynamic_objects()[k % 4] for k in range(37)]
    static = static_scene()
    tree = KdTree.build(*static, cache=False, progress=False)
    tracers = []
    for top in TOP_LEVELS:
        dyn = DynamicGeometry(device, top_level=top)
        for v, f in objects:
            dyn.add(v, f)
        tracers.append(TwoLevelTracer(tree, dyn))
    for _ in range(2):
        m = np.tile(np.eye(4), (37, 1, 1))
        for k in range(37):
            m[k, :3, :3] = random_rotation(rng) * rng.uniform(0.3, 0.7)
            m[k, :3, 3] = rng.uniform((-5, 0.5, -5), (5, 3, 5))
        for two in tracers:
            two.dynamic.set_transforms(m)
        o = rng.uniform((-6, 0.01, -6), (6, 5, 6), (8000, 3)).astype(np.float32)
        d = rng.normal(size=(8000, 3)).astype(np.float32)
        ref = tracers[0].intersect(o, d, threads=1)
        posed, v, f = posed_reference(static, tracers[0].dynamic)
        assert_agree(ref, posed.intersect(o, d), v, f, o, d)
        assert np.mean(ref.prim >= len(static[1])) > 0.04  # ~500 rays end on the objects
        for two in tracers:
            for threads in (1, 2):
                got = two.intersect(o, d, threads=threads)
                for a, b in zip((got.t, got.prim, got.u, got.v), (ref.t, ref.prim, ref.u, ref.v), strict=True):
                    assert np.array_equal(a, b)
            assert np.array_equal(two.occluded(o, d, 5.0), tracers[0].occluded(o, d, 5.0))


def test_invalid_rays_miss(device):
    _, _, dyn, two = make(device)
    dyn.set_transforms(random_poses(np.random.default_rng(10)))
    nan, inf = np.nan, np.inf
    c = dyn.transforms[0, :3, 3].astype(np.float32)
    o = np.tile(c + np.float32([0, 0, 5]), (8, 1))
    d = np.tile(np.float32([[0, 0, -1]]), (8, 1))
    d[0] = 0
    d[1, 0] = nan
    d[2, 1] = inf
    d[3] = (1e-38, 0, 0)
    o[4, 0] = nan
    o[5, 2] = -inf
    tmax = np.float32([inf] * 6 + [nan, -1.0])
    for tracer in (dyn, two):
        hits = tracer.intersect(o, d, tmax)
        assert np.all(hits.prim == -1) and np.all(np.isinf(hits.t))
        assert not tracer.occluded(o, d, tmax).any()
    assert dyn.intersect(o[6:7], d[6:7]).prim[0] >= 0  # the same ray with a valid tmax hits


def test_cpu_and_cuda_give_the_same_hits(cuda_devices):
    if not cuda_devices:
        pytest.skip("no CUDA device")
    rng = np.random.default_rng(11)
    m = random_poses(rng)
    static = static_scene()
    tree = KdTree.build(*static, cache=False, progress=False)
    per_device = {}
    for dev in ["cpu", *cuda_devices]:
        dyn = DynamicGeometry(dev)
        for v, f in dynamic_objects():
            dyn.add(v, f)
        dyn.set_transforms(m)
        per_device[dev] = TwoLevelTracer(tree, dyn)
    o, d = scene_rays(rng, per_device["cpu"].dynamic)
    ref = per_device["cpu"].intersect(o, d)
    for dev in cuda_devices:
        got = per_device[dev].intersect(o, d)
        assert np.mean(got.prim == ref.prim) > 0.999
        same = got.prim == ref.prim
        assert np.allclose(got.t[same & (ref.prim >= 0)], ref.t[same & (ref.prim >= 0)], rtol=1e-6)
        assert np.mean(per_device[dev].occluded(o, d) == per_device["cpu"].occluded(o, d)) > 0.999


# ---------------------------------------------------------------------------------------------
# bad input


@pytest.mark.parametrize("matrices, match", [
    (lambda m: np.where(np.arange(16).reshape(4, 4) == 5, np.nan, m), "not finite"),
    (lambda m: m[:, :3, :], r"\(2, 4, 4\) matrices expected"),
    (lambda m: m[:1], "1 matrices for 2 objects"),
    (lambda m: m * np.where(np.arange(16).reshape(4, 4) == 10, 0.0, 1.0), "degenerate"),
    (lambda m: m @ np.diag([1.0, 1.0, 0.1 / MAX_CONDITION, 1.0]), "degenerate"),
    (lambda m: m + np.where(np.arange(16).reshape(4, 4) == 12, 0.5, 0.0), "not affine"),
    (lambda m: "identity", "not an array of numbers"),
])
def test_bad_transforms_raise_one_line(matrices, match):
    dyn = DynamicGeometry("cpu")
    v, f = dynamic_objects()[2]
    dyn.add(v, f)
    dyn.add(v, f)
    before = dyn.transforms
    with pytest.raises(SerenityError, match=match) as e:
        dyn.set_transforms(matrices(np.tile(np.eye(4), (2, 1, 1))))
    assert "\n" not in str(e.value)
    assert np.array_equal(dyn.transforms, before)  # a refused pose leaves the last one in place


@pytest.mark.parametrize("positions, faces, match", [
    (np.zeros((3, 2)), [[0, 1, 2]], "positions"),
    (np.zeros((3, 3)), [[0, 1, 3]], "out of range"),
    (np.zeros((3, 3)), np.zeros((0, 3), int), "faces"),
    (np.float32([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]]), [[0, 1, 2]], "NaN"),
    (np.zeros((3, 3)), [[0.0, 1.0, 2.0]], "integer"),
])
def test_bad_objects_raise_one_line(positions, faces, match):
    with pytest.raises(SerenityError, match=match) as e:
        DynamicGeometry("cpu").add(positions, faces)
    assert "\n" not in str(e.value)
    with pytest.raises(SerenityError, match="top level"):
        DynamicGeometry("cpu", top_level="octree")


