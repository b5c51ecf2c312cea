"""The kd-tree against exact references: a brute-force loop over all triangles (same triangle test,
so t and the primitive must match exactly), Embree on a big mesh, watertightness on closed meshes,
degenerate input, the disk cache, and CPU vs CUDA."""

import math
import threading

import numpy as np
import pytest
import trimesh

from serenity.device import init_warp
from serenity.errors import SerenityError
from serenity.kernels.kdtree import (
    KEY_LANES,
    PACKET_LANES,
    SORT_COARSE_BITS,
    SORT_DIRECTION_BITS,
    SORT_KEY_BITS,
    SORT_MIN_RAYS,
    SORT_ORIGIN_BITS,
    TRACE_MODULE_OPTIONS,
    KdBuildConfig,
    KdTree,
    intersect_triangle,
    ray_order,
    ray_sort_key,
    setup_ray,
    sort_keys,
    sort_keys_simd,
    sort_scale,
)
from serenity.scene.procedural import lumpy_mesh

wp = init_warp()
wp.set_module_options(TRACE_MODULE_OPTIONS)  # the brute force below uses the kd-tree's arithmetic exactly


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    """Builds in these tests never touch the user's cache."""
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


@wp.kernel
def _brute_force(
    tri_verts: wp.array(dtype=wp.vec3),
    n_tris: int,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    tmax: float,
    out_t: wp.array(dtype=float),
    out_prim: wp.array(dtype=wp.int32),
    out_u: wp.array(dtype=float),
    out_v: wp.array(dtype=float),
):
    i = wp.tid()
    o = origins[i]
    kx, ky, kz, sx, sy, sz = setup_ray(directions[i])
    best = tmax
    prim = int(-1)
    bu = float(0.0)
    bv = float(0.0)
    for f in range(n_tris):
        hit, t, u, v = intersect_triangle(o, kx, ky, kz, sx, sy, sz, tri_verts[3 * f], tri_verts[3 * f + 1],
                                          tri_verts[3 * f + 2], 0.0, best)
        if hit and (t < best or f < prim):
            best = t
            prim = f
            bu = u
            bv = v
    if prim < 0:
        best = float(math.inf)
    out_t[i] = best
    out_prim[i] = prim
    out_u[i] = bu
    out_v[i] = bv


def brute_force(vertices, faces, origins, directions, tmax=math.inf):
    """Closest hits by testing every triangle (the kd-tree's own triangle test)."""
    tv = wp.array(np.ascontiguousarray(vertices[faces].reshape(-1, 3), np.float32), dtype=wp.vec3, device="cpu")
    n = len(origins)
    outs = [wp.zeros(n, dtype=t, device="cpu") for t in (float, wp.int32, float, float)]
    rays = [wp.array(a, dtype=wp.vec3, device="cpu") for a in (origins, directions)]
    wp.launch(_brute_force, n, [tv, len(faces), *rays, float(tmax), *outs], device="cpu")
    return [a.numpy() for a in outs]


def random_soup(rng, n, spread=1.0, size=0.15):
    centres = rng.uniform(-spread, spread, (n, 1, 3))
    v = (centres + rng.normal(size=(n, 3, 3)) * size).reshape(-1, 3).astype(np.float32)
    return v, np.arange(3 * n, dtype=np.int32).reshape(-1, 3)


def random_rays(rng, n, extent=1.5):
    o = rng.uniform(-extent, extent, (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    return o, d


def camera_rays(width, height, position=(0.0, 0.5, 4.0), fov_deg=60.0):
    t = math.tan(math.radians(fov_deg) / 2)
    xs = ((np.arange(width) + 0.5) / width * 2 - 1) * t * width / height
    ys = (1 - (np.arange(height) + 0.5) / height * 2) * t
    d = np.stack(np.broadcast_arrays(xs[None, :], ys[:, None], -1.0), -1).reshape(-1, 3)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    o = np.broadcast_to(np.asarray(position, np.float32), d.shape)
    return np.ascontiguousarray(o, np.float32), d.astype(np.float32)


def assert_same_hits(hits, ref, vertices=None, faces=None, origins=None, directions=None):
    """Same t, same triangle and barycentrics. Where a ray hits a shared edge or vertex exactly, two
    triangles tie at the same t: then the tree's triangle must be hit at that very t (checked
    against the triangle alone when the geometry is given)."""
    t, prim, u, v = ref
    assert np.array_equal(hits.t, t)
    same = hits.prim == prim
    tie = ~same
    if tie.any():
        assert vertices is not None, f"{np.count_nonzero(tie)} rays hit another triangle"
        assert np.all(hits.hit[tie]) and tie.mean() < 0.01
        for i in np.flatnonzero(tie):
            one = brute_force(vertices, faces[hits.prim[i:i + 1]], origins[i:i + 1], directions[i:i + 1])
            assert one[0][0] == t[i], f"ray {i}: triangle {hits.prim[i]} is not hit at t = {t[i]}"
    assert np.array_equal(hits.u[same], u[same]) and np.array_equal(hits.v[same], v[same])


# ---------------------------------------------------------------------------------------------
# exactness


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_matches_brute_force_on_random_soups(device, seed):
    rng = np.random.default_rng(seed)
    v, f = random_soup(rng, 600)
    o, d = random_rays(rng, 20_000)
    tree = KdTree.build(v, f)
    hits = tree.intersect(o, d, device=device)
    assert 0.2 < hits.hit.mean() < 0.9
    assert_same_hits(hits, brute_force(v, f, o, d))


def test_matches_brute_force_on_leaves_of_copies(device):
    """Each triangle 12 times under different indices: leaves of up to ~80 triangles (several of
    the CPU's 8-triangle SIMD leaf tests each) and every hit a tie at equal t, which the lowest
    index wins, as in a test of every triangle in order; the one-ray traversal (``leaf_pick``) and
    packets (``leaf_simd``), closest and any hit."""
    rng = np.random.default_rng(13)
    v, f = random_soup(rng, 100, size=0.4)
    f = rng.permutation(np.repeat(f, 12, axis=0)).astype(np.int32)
    o, d = random_rays(rng, 20_000)
    tree = KdTree.build(v, f)
    ref = brute_force(v, f, o, d)
    for k in (1, PACKET_LANES):
        hits = tree.intersect(o, d, device=device, rays_per_thread=k)
        assert 0.1 < hits.hit.mean() < 0.9
        assert_same_hits(hits, ref)
        for tmax in (math.inf, 0.7):
            assert np.array_equal(tree.occluded(o, d, tmax, device=device, rays_per_thread=k), ref[0] < tmax)


def test_matches_brute_force_on_a_closed_mesh_with_tmax(device):
    rng = np.random.default_rng(3)
    m = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=40, minor_sections=20)
    v, f = m.vertices.astype(np.float32), m.faces.astype(np.int32)
    o, d = random_rays(rng, 20_000)
    tree = KdTree.build(v, f)
    for tmax in (math.inf, 1.0):
        assert_same_hits(tree.intersect(o, d, tmax, device=device), brute_force(v, f, o, d, tmax))


def test_occluded_is_any_hit_before_tmax(device):
    rng = np.random.default_rng(4)
    v, f = random_soup(rng, 400)
    o, d = random_rays(rng, 10_000)
    tree = KdTree.build(v, f)
    closest = tree.intersect(o, d, device=device)
    for tmax in (math.inf, 0.5, np.linspace(0.01, 3.0, len(o)).astype(np.float32)):
        occ = tree.occluded(o, d, tmax, device=device)
        assert occ.dtype == bool
        assert np.array_equal(occ, closest.t < tmax)


def test_non_unit_directions_measure_t_in_direction_lengths(device):
    rng = np.random.default_rng(5)
    v, f = random_soup(rng, 300)
    o, d = random_rays(rng, 5_000)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    tree = KdTree.build(v, f)
    unit = tree.intersect(o, d, device=device)
    long = tree.intersect(o, d * 4.0, device=device)
    assert np.array_equal(unit.prim, long.prim)
    hit = unit.hit
    assert np.allclose(long.t[hit] * 4.0, unit.t[hit], rtol=1e-5)


def _hits_equal(a, b) -> bool:
    return all(np.array_equal(getattr(a, k), getattr(b, k)) for k in ("t", "prim", "u", "v"))


def test_multi_threaded_trace_equals_single_threaded_bit_for_bit():
    """Coherent camera rays (cheap sky above, geometry below: uneven chunks) and random rays: the
    balanced multi-threaded launch (many chunks, handed out dynamically) gives the very same bits."""
    v, f = lumpy_mesh(4)
    tree = KdTree.build(v, f)
    rng = np.random.default_rng(6)
    oc, dc = camera_rays(320, 180, position=(0.0, 0.6, 3.5))
    o2, d2 = random_rays(rng, 40_000, extent=2.0)
    for o, d in ((oc, dc), (o2, d2)):
        one = tree.intersect(o, d, device="cpu", threads=1)
        assert 0.1 < one.hit.mean() < 0.95
        occ = tree.occluded(o, d, 1.5, device="cpu", threads=1)
        for threads in (2, 3, 8):
            assert _hits_equal(tree.intersect(o, d, device="cpu", threads=threads), one), threads
            assert np.array_equal(tree.occluded(o, d, 1.5, device="cpu", threads=threads), occ), threads


def test_reordered_rays_give_the_same_bits_in_the_callers_order():
    """Ray reordering (``sort``) traces the rays in another order and scatters the results back:
    the same bits at the same indices as without it, on one thread and on several. ``sort=None``
    reorders a big batch of random rays and leaves camera rays (already coherent) as they come."""
    v, f = lumpy_mesh(4)
    tree = KdTree.build(v, f)
    data = tree.device_data("cpu")
    rng = np.random.default_rng(7)
    oc, dc = camera_rays(320, 180, position=(0.0, 0.6, 3.5))
    o2, d2 = random_rays(rng, SORT_MIN_RAYS + 1000, extent=2.0)
    for o, d, sorted_by_default in ((oc, dc, False), (o2, d2, True)):
        order = ray_order(data.box_lo, data.box_hi, wp.array(o, dtype=wp.vec3, device="cpu"),
                          wp.array(d, dtype=wp.vec3, device="cpu"), len(o),
                          None, "cpu")
        assert (order.shape[0] == len(o)) == sorted_by_default
        plain = tree.intersect(o, d, device="cpu", threads=1, sort=False)
        occ = tree.occluded(o, d, 1.5, device="cpu", threads=1, sort=False)
        for threads in (1, 3):
            assert _hits_equal(tree.intersect(o, d, device="cpu", threads=threads, sort=True), plain), threads
            assert np.array_equal(tree.occluded(o, d, 1.5, device="cpu", threads=threads, sort=True), occ), threads
    # the order is a permutation, grouped by the origin's coarse cell first, then by the direction's
    # octant, then by the origin's fine cell (Morton order), then by the direction's cell
    order = ray_order(data.box_lo, data.box_hi, wp.array(o2, dtype=wp.vec3, device="cpu"),
                      wp.array(d2, dtype=wp.vec3, device="cpu"), len(o2),
                      True, "cpu").numpy()
    assert np.array_equal(np.sort(order), np.arange(len(o2)))
    lo, hi = np.array(data.box_lo), np.array(data.box_hi)
    fine_cells = 1 << SORT_ORIGIN_BITS
    scale = np.array(sort_scale(data.box_lo, data.box_hi), np.float32)  # cells / extent, as the kernel has it
    assert np.allclose(scale, fine_cells / (hi - lo), rtol=1e-6)
    q_fine = np.clip(np.floor((o2[order] - lo) * scale), 0, fine_cells - 1).astype(np.int64)
    q = q_fine >> (SORT_ORIGIN_BITS - SORT_COARSE_BITS)
    cells = 1 << SORT_COARSE_BITS
    cell = (q[:, 0] * cells + q[:, 1]) * cells + q[:, 2]
    octant = (d2[order] < 0) @ np.array([1, 2, 4])
    runs = np.flatnonzero(np.diff(cell) != 0)  # where the origin's cell changes along the order
    assert len(np.unique(cell[np.r_[0, runs + 1]])) == len(runs) + 1  # each cell is one run
    within = np.ones(len(order) - 1, bool)
    within[runs] = False
    assert np.all(np.diff(octant)[within] >= 0)  # and sorted by octant inside its run

    def morton(c, bits):  # Morton code of (N,3) cells
        out = np.zeros(len(c), np.int64)
        for b in range(bits):
            for a in range(3):
                out |= ((c[:, a] >> b) & 1) << (3 * b + a)
        return out

    fine_bits = SORT_ORIGIN_BITS - SORT_COARSE_BITS
    group = cell * 8 + octant  # (coarse cell, octant) runs
    inside = np.diff(group) == 0
    fine = morton(q_fine & ((1 << fine_bits) - 1), fine_bits)
    assert np.all(np.diff(fine)[inside] >= 0) and np.any(np.diff(fine)[inside] > 0)
    assert SORT_DIRECTION_BITS >= 2




@wp.kernel(enable_backward=False, module="unique", module_options={"cpu_compiler_flags": ""})
def _generic_cpu_keys(box_lo: wp.vec3, scale: wp.vec3, origins: wp.array(dtype=wp.vec3),
                      directions: wp.array(dtype=wp.vec3), keys: wp.array(dtype=wp.uint32)):
    i = wp.tid()
    keys[i] = wp.uint32(ray_sort_key(box_lo, scale, origins[i], directions[i]))


def test_sort_keys_are_the_documented_key_with_and_without_bmi2():
    """The reordering key of every ray (``sort_keys``: Morton spreads by BMI2 ``pdep`` on a CPU that
    has it) is the key the docstring of ``ray_sort_key`` defines, computed here in numpy from the
    same float32 arithmetic, and the same as the key of the portable spreads (shifts and masks: a
    kernel compiled for a generic x86-64 CPU, as CUDA and other CPUs compile it) and as the key of
    the SIMD kernel that computes 16 rays' keys at once (``sort_keys_simd``, which ``ray_order``
    uses on the CPU). Origins inside, on and outside the box, NaN origins, zero, NaN and
    axis-parallel directions."""
    v, f = lumpy_mesh(2)
    data = KdTree.build(v, f).device_data("cpu")
    rng = np.random.default_rng(5)
    n = 5000
    lo = np.array(data.box_lo, np.float32)
    hi = np.array(data.box_hi, np.float32)
    o = (lo + (hi - lo) * rng.uniform(-0.2, 1.2, (n, 3))).astype(np.float32)
    o[:10] = lo
    o[10:20] = hi
    o[20, 1] = np.nan
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[30] = 0.0
    d[31, 2] = np.nan
    d[40:46] = np.repeat(np.eye(3, dtype=np.float32), 2, axis=0) * np.array([1, -1] * 3, np.float32)[:, None]
    scale = sort_scale(data.box_lo, data.box_hi)
    wo, wd = wp.array(o, dtype=wp.vec3, device="cpu"), wp.array(d, dtype=wp.vec3, device="cpu")
    native = wp.empty(n, dtype=wp.uint32, device="cpu")
    wp.launch(sort_keys, dim=n, inputs=[data.box_lo, scale, wo, wd, native, 0], device="cpu")
    generic = wp.empty(n, dtype=wp.uint32, device="cpu")
    wp.launch(_generic_cpu_keys, dim=n, inputs=[data.box_lo, scale, wo, wd, generic], device="cpu")
    simd = wp.zeros(n, dtype=wp.uint32, device="cpu")
    wp.launch(sort_keys_simd, dim=n // KEY_LANES, inputs=[data.box_lo, scale, wo, wd, simd, 0], device="cpu")
    lanes = n // KEY_LANES * KEY_LANES
    assert 0 < lanes < n

    def morton(q, axes, bits):
        out = np.zeros(len(q), np.int64)
        for b in range(bits):
            for a in range(axes):
                out |= ((q[:, a] >> b) & 1) << (axes * b + a)
        return out

    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        cells = np.float32(1 << SORT_ORIGIN_BITS)
        fo = (o - lo) * np.array(scale, np.float32)
        q = np.minimum(np.where(fo >= 0, fo, np.float32(0)), cells - 1).astype(np.int64)
        a = np.abs(d)
        l1 = (a[:, 0] + a[:, 1]) + a[:, 2]
        dir_cells = np.float32(1 << SORT_DIRECTION_BITS)
        ok = (l1 > 0) & (l1 <= np.finfo(np.float32).max)
        s = np.where(ok, dir_cells / np.where(ok, l1, 1), np.float32(0)).astype(np.float32)
        quv = np.minimum(np.where(s[:, None] > 0, a[:, :2] * s[:, None], np.float32(0)), dir_cells - 1)
    quv = quv.astype(np.int64)
    fine_bits = SORT_ORIGIN_BITS - SORT_COARSE_BITS
    origin = morton(q, 3, SORT_ORIGIN_BITS)
    octant = (d < 0) @ np.array([1, 2, 4])
    key = (origin >> (3 * fine_bits)) << 3 | octant
    key = (key << (3 * fine_bits)) | (origin & ((1 << (3 * fine_bits)) - 1))
    key = (key << (2 * SORT_DIRECTION_BITS)) | morton(quv, 2, SORT_DIRECTION_BITS)
    assert key.max() < 1 << SORT_KEY_BITS
    assert np.array_equal(native.numpy().astype(np.int64), key)
    assert np.array_equal(generic.numpy(), native.numpy())
    assert np.array_equal(simd.numpy()[:lanes], native.numpy()[:lanes])
    # ray_order's keys: the SIMD kernel for whole groups of lanes, the one-ray kernel for the rest
    order = ray_order(data.box_lo, data.box_hi, wo, wd, n, True, "cpu")
    assert np.array_equal(order.numpy(), np.argsort(key, kind="stable"))


def test_counting_order_is_numpys_stable_argsort():
    """The CPU's radix sort of the keys by counting (``counting_order``, two digits) gives the order
    numpy's stable argsort gives, on one thread and on several (runs of uneven length, keys at both
    ends of the range and of each digit, many ties, a batch too small to split; nearly every key in
    one bin), into fresh arrays and into reused workspace."""
    from serenity.kernels.kdtree import SORT_DIGIT_BITS, SORT_KEY_BITS, SORT_MIN_KEYS_PER_THREAD, counting_order
    from serenity.kernels.launch import Staging

    rng = np.random.default_rng(3)
    workspace = Staging("cpu")
    top = (1 << SORT_KEY_BITS) - 1
    for n in (1, 1000, 3 * SORT_MIN_KEYS_PER_THREAD + 17):
        keys = rng.integers(0, top + 1, n).astype(np.uint32)
        ends = np.array([0, 7, top, (1 << SORT_DIGIT_BITS) - 1, 1 << SORT_DIGIT_BITS], np.uint32)
        keys[: n // 3] = rng.choice(ends, n // 3)  # ties, both ends, a digit's ends
        expected = np.argsort(keys, kind="stable")
        wk = wp.array(keys, dtype=wp.uint32, device="cpu")
        for threads in (1, 2, 3, 8):
            assert np.array_equal(counting_order(wk, n, threads).numpy(), expected), (n, threads)
            assert np.array_equal(counting_order(wk, n, threads, workspace).numpy(), expected), (n, threads)
    # one bin of the low digit holds every key (or nearly): the second pass's other threads get none
    n = 3 * SORT_MIN_KEYS_PER_THREAD + 5
    for keys in (np.full(n, 5 << SORT_DIGIT_BITS, np.uint32), np.full(n, 77, np.uint32)):
        keys[::1000] = rng.integers(0, top + 1, len(keys[::1000]))
        for threads in (2, 3):
            got = counting_order(wp.array(keys, dtype=wp.uint32, device="cpu"), n, threads, workspace).numpy()
            assert np.array_equal(got, np.argsort(keys, kind="stable")), threads


def test_query_workspace_is_reused_without_aliasing_results():
    """Reordered queries trace into per-thread workspace buffers that grow and are reused
    (``KdTree.workspace``): a later, bigger or smaller batch leaves an earlier call's results as they
    were, each batch's hits equal a fresh tree's, and two threads querying one tree at once each
    get their own batch's hits."""
    v, f = lumpy_mesh(3)
    rng = np.random.default_rng(11)
    batches = [random_rays(rng, n, extent=2.0) for n in (SORT_MIN_RAYS + 5, 2 * SORT_MIN_RAYS + 17, SORT_MIN_RAYS)]
    expected = [KdTree.build(v, f).intersect(o, d, device="cpu", threads=1, sort=True) for o, d in batches]
    tree = KdTree.build(v, f)
    kept = []
    for (o, d), want in zip(batches, expected, strict=True):
        got = tree.intersect(o, d, device="cpu", threads=2, sort=True)
        assert _hits_equal(got, want)
        kept.append((got, {k: np.copy(getattr(got, k)) for k in ("t", "prim", "u", "v")}))
        assert tree.occluded(o, d, 1.0, device="cpu", sort=True).dtype == bool
    for got, copy in kept:  # nothing a later query did wrote into an earlier one's results
        assert all(np.array_equal(getattr(got, k), a) for k, a in copy.items())
    results = [None, None]

    def query(k):
        o, d = batches[k]
        results[k] = [tree.intersect(o, d, device="cpu", threads=1, sort=True) for _ in range(3)]

    workers = [threading.Thread(target=query, args=(k,)) for k in (0, 1)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    for k in (0, 1):
        assert all(_hits_equal(h, expected[k]) for h in results[k]), k

def _edge_case_rays(rng, tree, n):
    """Random rays with the traversal's edge cases mixed in: origins on split planes, rays inside
    them and parallel to the axes, on many planes at once, invalid rays, and per-ray tmax."""
    o, d = random_rays(rng, n, extent=2.0)
    inner = (tree.node_head & 3) != 3
    axes, planes = tree.node_head[inner] & 3, tree.node_split[inner]
    q = n // 8
    pick = rng.integers(0, len(planes), 2 * q)
    rows = np.arange(2 * q)
    o[rows, axes[pick]] = planes[pick]  # origin exactly on a split plane
    d[rows[:q], axes[pick[:q]]] = 0.0  # ... and running inside it
    d[2 * q:3 * q, :2] = 0.0  # along z only
    o[3 * q:4 * q] = np.round(o[3 * q:4 * q] * 4) / 4  # on several planes at once
    d[3 * q:4 * q] = np.round(d[3 * q:4 * q])  # axis-parallel or diagonal (some zero: invalid)
    d[4 * q:4 * q + 8] = np.nan
    o[4 * q + 8:4 * q + 16] = np.inf
    tmax = rng.uniform(0.0, 4.0, n).astype(np.float32)
    tmax[: n // 2] = np.inf
    return o, d, tmax


def test_packet_traversal_gives_the_one_ray_bits(device):
    """The CPU's packets (``PACKET_LANES``), closest and any hit, reordered or not, one thread or
    several, give the one-ray traversal's hits bit for bit, on rays that hit split planes, run inside
    them, are axis-parallel or invalid, on a soup, a closed mesh, a flat grid of coplanar triangles
    and a soup of 12 copies of each triangle (leaves of more triangles than the packets' SIMD leaf
    test takes at once, and every hit a tie that the lower index wins); random rays put every octant
    into one packet (on CUDA ``rays_per_thread`` is accepted and one ray per thread is traced). Any
    other ``rays_per_thread`` is an error."""
    rng = np.random.default_rng(21)
    torus = trimesh.creation.torus(major_radius=1.0, minor_radius=0.3, major_sections=40, minor_sections=20)
    grid = trimesh.creation.box((4.0, 4.0, 4.0)).subdivide().subdivide()
    gv = grid.vertices.astype(np.float32).copy()
    gv[:, 1] = 0.0
    sv, sf = random_soup(rng, 100, size=0.4)
    dup = rng.permutation(np.repeat(sf, 12, axis=0))  # 12 copies of each triangle: leaves of 12 and more, all ties
    scenes = [random_soup(rng, 800), (torus.vertices.astype(np.float32), torus.faces.astype(np.int32)),
              (gv, grid.faces.astype(np.int32)), (sv, dup.astype(np.int32))]
    for v, f in scenes:
        tree = KdTree.build(v, f)
        o, d, tmax = _edge_case_rays(rng, tree, 12_000)
        one = tree.intersect(o, d, tmax, device=device, rays_per_thread=1, sort=False)
        occ = tree.occluded(o, d, tmax, device=device, rays_per_thread=1, sort=False)
        assert 0.05 < one.hit.mean() < 0.95
        for sort, threads in ((False, 1), (True, 1), (True, 3), (False, 3)):
            kw = dict(device=device, rays_per_thread=PACKET_LANES, sort=sort, threads=threads)
            assert _hits_equal(tree.intersect(o, d, tmax, **kw), one), (sort, threads)
            assert np.array_equal(tree.occluded(o, d, tmax, **kw), occ), (sort, threads)
    for k in (2, 4, 5):
        with pytest.raises(SerenityError, match="rays_per_thread"):
            tree.intersect(o, d, device="cpu", rays_per_thread=k)



def test_default_cpu_kernels_trace_reordered_and_coherent_batches_in_packets(monkeypatch):
    """The default CPU query: a reordered (incoherent) batch goes to packets and its results to the
    scatter, camera rays (left in their order, coherent) to packets, with the one-ray kernel's bits,
    and a small batch of random rays (not reordered, not coherent) to one ray per thread."""
    import serenity.kernels.kdtree as K
    from serenity.kernels.kdtree import query, reorder

    v, f = lumpy_mesh(3)
    tree = KdTree.build(v, f)
    launched = []
    original = query.launch
    for module in (query, reorder):
        monkeypatch.setattr(module, "launch",
                            lambda kernel, *a, **kw: (launched.append(kernel), original(kernel, *a, **kw)))
    oc, dc = camera_rays(320, 180, position=(0.0, 0.6, 3.5))
    o2, d2 = random_rays(np.random.default_rng(22), SORT_MIN_RAYS + 1000, extent=2.0)
    packets = tree.intersect(oc, dc, device="cpu")
    assert launched[-1] is K.trace_packets_kernel(False)
    assert _hits_equal(packets, tree.intersect(oc, dc, device="cpu", rays_per_thread=1))
    assert launched[-1] is K.intersect_rays
    occluded = tree.occluded(oc, dc, 2.0, device="cpu")
    assert launched[-1] is K.trace_packets_kernel(True)
    assert np.array_equal(occluded, tree.occluded(oc, dc, 2.0, device="cpu", rays_per_thread=1))
    tree.intersect(o2[:5000], d2[:5000], device="cpu")
    assert launched[-1] is K.intersect_rays
    # a reordered batch is traced in its order, then its results are scattered back in a pass of their own
    hits = tree.intersect(o2, d2, device="cpu")
    assert launched[-2:] == [K.trace_packets_kernel(False), K.scatter_hits]
    assert _hits_equal(hits, tree.intersect(o2, d2, device="cpu", sort=False))
    tree.occluded(o2, d2, device="cpu")
    assert launched[-2:] == [K.trace_packets_kernel(True), K.move_in_order]  # the flags: scatter_in_order
    tree.intersect(o2, d2, device="cpu", rays_per_thread=1)
    assert launched[-2:] == [K.intersect_rays, K.scatter_hits]

def test_build_does_not_depend_on_the_thread_count():
    from serenity.kernels.kdtree_build import build_arrays

    v, f = lumpy_mesh(3)
    a = build_arrays(v, f, KdBuildConfig(), progress=False, threads=1)
    b = build_arrays(v, f, KdBuildConfig(), progress=False, threads=3)
    for k in ("node_head", "node_split", "prims", "box"):
        assert np.array_equal(a[k], b[k]), k
    assert a["stats"] == b["stats"]


@pytest.mark.parametrize("field, value, match", [
    ("traversal_cost", 0.0, "traversal_cost"), ("intersection_cost", float("nan"), "intersection_cost"),
    ("empty_bonus", 1.0, "empty_bonus"), ("bins", 65, "bins"), ("bins", 8.0, "bins"), ("max_depth", 63, "max_depth"),
])
def test_build_config_errors_name_the_field(field, value, match):
    with pytest.raises(SerenityError, match=f"KdBuildConfig.{match}"):
        KdBuildConfig(**{field: value})


def _embree_agreement(v, f, o, d, hits):
    embreex = pytest.importorskip("embreex")  # noqa: F841
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, v, f)
    res = scene.run(o, d, output=1)
    e_prim = res["primID"].astype(np.int32)
    e_t = np.where(e_prim >= 0, res["tfar"], np.inf).astype(np.float32)
    both = (e_prim >= 0) & hits.hit
    close = np.zeros(len(o), bool)
    close[both] = np.abs(hits.t[both] - e_t[both]) <= 1e-5 * e_t[both]
    # the same triangle, or (at a shared edge or vertex) another triangle at the same distance
    agree = ((e_prim == hits.prim) & ((e_prim < 0) | close)) | close
    return agree.mean(), both


def test_agrees_with_embree_on_120k_triangles(device):
    v, f = lumpy_mesh(6)
    assert len(f) > 100_000
    tree = KdTree.build(v, f)
    rng = np.random.default_rng(7)
    o1, d1 = camera_rays(320, 180)
    o2 = rng.uniform(-0.5, 0.5, (60_000, 3)).astype(np.float32)
    d2 = rng.normal(size=(60_000, 3)).astype(np.float32)
    o, d = np.concatenate([o1, o2]), np.concatenate([d1, d2])
    hits = tree.intersect(o, d, device=device)
    agreement, both = _embree_agreement(v, f, o, d, hits)
    assert both.mean() > 0.5
    assert agreement >= 0.9999, agreement


@pytest.mark.slow
def test_agrees_with_embree_on_330k_triangles_1m_rays(device):
    v, f = lumpy_mesh(7)
    tree = KdTree.build(v, f)
    rng = np.random.default_rng(8)
    o1, d1 = camera_rays(1280, 400)
    o2 = rng.uniform(-2, 2, (500_000, 3)).astype(np.float32)
    d2 = rng.normal(size=(500_000, 3)).astype(np.float32)
    o, d = np.concatenate([o1, o2]), np.concatenate([d1, d2])
    hits = tree.intersect(o, d, device=device)
    agreement, _ = _embree_agreement(v, f, o, d, hits)
    assert agreement >= 0.9999, agreement


# ---------------------------------------------------------------------------------------------
# watertightness


def _closed_meshes():
    ico = trimesh.creation.icosphere(subdivisions=4)
    caps = trimesh.creation.capsule(height=1.0, radius=0.4, count=[24, 24])
    box = trimesh.creation.box((1.0, 2.0, 0.5)).subdivide().subdivide()  # axis-aligned faces on split planes
    for m in (ico, caps, box):
        assert m.is_watertight
    return [(name, m.vertices.astype(np.float32), m.faces.astype(np.int32))
            for name, m in (("icosphere", ico), ("capsule", caps), ("box", box))]


def _edge_and_vertex_targets(v, f, rng, per_edge):
    """Every vertex, and points on every edge (midpoints and random fractions), as float32."""
    edges = np.unique(np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1), axis=0)
    a, b = v[edges[:, 0]].astype(np.float64), v[edges[:, 1]].astype(np.float64)
    s = np.concatenate([np.full((len(edges), 1), 0.5), rng.uniform(0, 1, (len(edges), per_edge - 1))], axis=1)
    on_edges = (a[:, None] + s[..., None] * (b - a)[:, None]).reshape(-1, 3)
    return np.concatenate([v.astype(np.float64), on_edges]).astype(np.float32)


def _escapes(tree, v, f, targets, origins, device):
    n = 0
    for c in origins:
        o = np.broadcast_to(np.asarray(c, np.float32), targets.shape).copy()
        d = (targets - o).astype(np.float32)
        hits = tree.intersect(o, d, device=device)
        occ = tree.occluded(o, d, device=device)
        n += int(np.count_nonzero(~hits.hit)) + int(np.count_nonzero(~occ))
    return n


def test_no_ray_escapes_closed_meshes_through_edges_and_vertices(device):
    rng = np.random.default_rng(9)
    total = 0
    for name, v, f in _closed_meshes():
        tree = KdTree.build(v, f)
        targets = _edge_and_vertex_targets(v, f, rng, per_edge=3)
        origins = [(0.0, 0.0, 0.0), (0.05, -0.1, 0.03), (0.1, 0.13, -0.07)]
        assert _escapes(tree, v, f, targets, origins, device) == 0, name
        total += len(targets) * len(origins)
    assert total > 50_000


@pytest.mark.slow
def test_no_ray_escapes_1m_rays(device):
    rng = np.random.default_rng(10)
    total = 0
    for name, v, f in _closed_meshes():
        tree = KdTree.build(v, f)
        targets = _edge_and_vertex_targets(v, f, rng, per_edge=14)
        origins = rng.uniform(-0.15, 0.15, (8, 3))
        assert _escapes(tree, v, f, targets, origins, device) == 0, name
        total += len(targets) * len(origins)
    assert total >= 1_000_000


# ---------------------------------------------------------------------------------------------
# degenerate input


def test_zero_area_triangles_are_never_hit(device):
    rng = np.random.default_rng(11)
    v, f = random_soup(rng, 200)
    # collinear, repeated-vertex and point triangles, placed where rays pass
    deg = np.array([[[0, 0, 0], [1, 1, 1], [2, 2, 2]], [[0.5, 0, 0], [0.5, 0, 0], [0.5, 1, 0]],
                    [[0.2, 0.2, 0.2]] * 3, [[-1, 0, 0], [1, 0, 0], [0, 0, 0]]], np.float32)
    v2 = np.concatenate([v, deg.reshape(-1, 3)])
    f2 = np.concatenate([f, len(v) + np.arange(12).reshape(-1, 3)]).astype(np.int32)
    tree = KdTree.build(v2, f2)
    assert tree.stats.valid_triangles == len(f)
    o, d = random_rays(rng, 10_000)
    d[:100] = (deg[0, 1] - o[:100])  # aimed at the collinear triangle's middle vertex
    hits = tree.intersect(o, d, device=device)
    assert not np.any(hits.prim >= len(f))
    assert_same_hits(hits, brute_force(v, f, o, d))
    only_degenerate = KdTree.build(deg.reshape(-1, 3), np.arange(12).reshape(-1, 3))
    assert not only_degenerate.intersect(o, d, device=device).hit.any()
    assert not only_degenerate.occluded(o, d, device=device).any()


def test_flat_axis_aligned_grid_and_rays_in_its_plane(device):
    g = trimesh.creation.box((4.0, 4.0, 4.0)).subdivide().subdivide().subdivide()
    v = g.vertices.astype(np.float32).copy()
    v[:, 1] = 0.0  # squash the box flat: coplanar overlapping triangles in y = 0
    f = g.faces.astype(np.int32)
    tree = KdTree.build(v, f)
    rng = np.random.default_rng(12)
    o, d = random_rays(rng, 20_000, extent=3.0)
    o[:5000, 1] = 0.0
    d[:5000, 1] = 0.0  # in the plane of every triangle
    o[5000:10000, 1] = 0.0  # starting on the plane
    o[10000:12000] = np.round(o[10000:12000])  # on many split planes at once
    d[10000:11000] = np.round(d[10000:11000])  # axis-parallel
    hits = tree.intersect(o, d, device=device)
    assert_same_hits(hits, brute_force(v, f, o, d), v, f, o, d)
    assert not hits.hit[:5000].any()  # a ray in the triangle's plane is a miss (zero determinant)


def test_rays_on_and_parallel_to_split_planes(device):
    rng = np.random.default_rng(13)
    v, f = random_soup(rng, 800)
    tree = KdTree.build(v, f)
    inner = (tree.node_head & 3) != 3
    axes, planes = tree.node_head[inner] & 3, tree.node_split[inner]
    pick = rng.integers(0, len(planes), 30_000)
    o, d = random_rays(rng, 30_000)
    rows = np.arange(len(o))
    o[rows, axes[pick]] = planes[pick]  # origin exactly on a split plane
    d[:10_000][rows[:10_000], axes[pick[:10_000]]] = 0.0  # ... and running inside it
    d[10_000:20_000, :2] = 0.0  # along z only
    hits = tree.intersect(o, d, device=device)
    assert_same_hits(hits, brute_force(v, f, o, d), v, f, o, d)


def test_invalid_rays_miss(device):
    rng = np.random.default_rng(14)
    v, f = random_soup(rng, 200, spread=0.3)
    tree = KdTree.build(v, f)
    nan, inf = np.nan, np.inf
    o = np.zeros((9, 3), np.float32)
    d = np.array([[0, 0, 0], [nan, 1, 0], [inf, 0, 0], [1e-38, 0, 0], [0, -inf, 1], [1, 0, 0], [1, 0, 0],
                  [0, 1, 0], [0, 0, 1]], np.float32)
    o[5] = nan
    o[6, 2] = -inf
    tmax = np.array([inf] * 7 + [nan, -1.0], np.float32)
    hits = tree.intersect(o, d, tmax, device=device)
    assert not hits.hit.any() and np.all(np.isinf(hits.t)) and np.all(hits.prim == -1)
    assert not tree.occluded(o, d, tmax, device=device).any()
    # a valid ray in the same batch still hits
    h = tree.intersect(np.zeros((1, 3)), np.array([[0.0, 0.0, 1.0]]), device=device)
    b = brute_force(v, f, np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))
    assert h.prim[0] == b[1][0]


def test_empty_and_malformed_meshes_raise():
    with pytest.raises(SerenityError, match="empty"):
        KdTree.build(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    with pytest.raises(SerenityError, match="empty"):
        KdTree.build(np.zeros((3, 3), np.float32), np.zeros((0, 3), np.int32))
    with pytest.raises(SerenityError, match="out of range"):
        KdTree.build(np.zeros((3, 3), np.float32), np.array([[0, 1, 3]]))
    with pytest.raises(SerenityError, match="shape"):
        KdTree.build(np.zeros((3, 2), np.float32), np.array([[0, 1, 2]]))


def test_a_tree_deeper_than_the_traversal_stack_is_refused():
    """The traversal does not test for stack overflow (one entry per level at most): a tree whose
    recorded depth exceeds the stack (a foreign or corrupt cache entry) must not reach a kernel."""
    import dataclasses

    from serenity.kernels.kdtree import STACK_SIZE

    rng = np.random.default_rng(16)
    v, f = random_soup(rng, 50)
    tree = KdTree.build(v, f, cache=False)
    tree.device_data("cpu")  # a real tree is accepted
    deep = KdTree(tree.vertices, tree.faces, {"node_head": tree.node_head, "node_split": tree.node_split,
                                              "prims": tree.prims, "box": tree.box},
                  dataclasses.replace(tree.stats, depth=STACK_SIZE))
    with pytest.raises(SerenityError, match="stack"):
        deep.device_data("cpu")


def test_nan_vertices_leave_their_triangles_out(device):
    rng = np.random.default_rng(15)
    v, f = random_soup(rng, 100)
    v[0] = np.nan
    tree = KdTree.build(v, f)
    assert tree.stats.valid_triangles == 99
    o, d = random_rays(rng, 2000)
    hits = tree.intersect(o, d, device=device)
    assert not np.any(hits.prim == 0)


# ---------------------------------------------------------------------------------------------
# cache, build settings, devices


def test_cache_round_trip(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "c"))
    rng = np.random.default_rng(16)
    v, f = random_soup(rng, 300)
    a = KdTree.build(v, f, cache=True)
    files = list((tmp_path / "c").glob("kdtree-*.npz"))
    assert len(files) == 1 and not a.stats.from_cache
    b = KdTree.build(v, f, cache=True)
    assert b.stats.from_cache
    for k in ("node_head", "node_split", "prims", "box"):
        assert np.array_equal(getattr(a, k), getattr(b, k))
    assert b.stats.nodes == a.stats.nodes and b.stats.references == a.stats.references
    with np.load(files[0], allow_pickle=False) as z:  # plain arrays, no pickled objects
        assert all(z[k].dtype != object for k in z.files)
    o, d = random_rays(rng, 3000)
    assert np.array_equal(a.intersect(o, d, device="cpu").t, b.intersect(o, d, device="cpu").t)
    # other geometry or settings -> another key
    v2 = v.copy()
    v2[0, 0] += 1e-3
    KdTree.build(v2, f, cache=True)
    KdTree.build(v, f, cache=True, config=KdBuildConfig(bins=16))
    assert len(list((tmp_path / "c").glob("kdtree-*.npz"))) == 3
    # a corrupt cache file is rebuilt, not trusted
    files[0].write_bytes(b"not an npz")
    c = KdTree.build(v, f, cache=True)
    assert not c.stats.from_cache and np.array_equal(c.node_head, a.node_head)


def test_tree_is_a_real_sah_tree():
    v, f = lumpy_mesh(4)
    tree = KdTree.build(v, f)
    st = tree.stats
    assert st.depth <= KdBuildConfig().depth_limit(len(f))
    assert st.empty_leaves > 0  # empty space was cut off
    assert st.references < 8 * len(f)
    # every valid triangle is referenced by some leaf
    leaf = (tree.node_head & 3) == 3
    offs = tree.node_head[leaf] >> 2
    referenced = np.zeros(len(f), bool)
    for off in offs[offs > 0]:
        referenced[tree.prims[off + 1: off + 1 + tree.prims[off]]] = True
    assert referenced.all()


def test_cpu_and_cuda_give_identical_hits(cuda_devices):
    if not cuda_devices:
        pytest.skip("no CUDA device")
    v, f = lumpy_mesh(4)
    tree = KdTree.build(v, f)
    rng = np.random.default_rng(17)
    o, d = random_rays(rng, 50_000, extent=2.0)
    ref = tree.intersect(o, d, device="cpu")
    for dev in cuda_devices:
        got = tree.intersect(o, d, device=dev)
        assert np.array_equal(got.prim, ref.prim) and np.array_equal(got.t, ref.t)
        assert np.array_equal(tree.occluded(o, d, 1.0, device=dev), tree.occluded(o, d, 1.0, device="cpu"))


def test_gather_and_scatter_in_order_move_every_element_type():
    """The CPU's prefetching reorder loops (``move_in_order``, several blocks of rays) and the
    one-element kernels give numpy's ``a[order]`` and its inverse, for 4-, 12- and 16-byte elements
    and any other size, and a strided array takes the one-element kernels."""
    from serenity.kernels.kdtree import REORDER_BLOCK, gather_in_order, scatter_in_order

    rng = np.random.default_rng(30)
    n = 2 * REORDER_BLOCK + 77
    order_np = rng.permutation(n).astype(np.int32)
    order = wp.array(order_np, dtype=wp.int32, device="cpu")
    for dtype, shape in ((wp.float32, (n,)), (wp.int32, (n,)), (wp.vec3, (n, 3)), (wp.vec4, (n, 4)),
                         (wp.vec2h, (n, 2))):
        np_dtype = {wp.int32: np.int32, wp.vec2h: np.float16}.get(dtype, np.float32)
        a = (rng.random(shape) * 1000).astype(np_dtype)
        src = wp.array(a, dtype=dtype, device="cpu")
        for threads in (1, 2):
            (got,) = gather_in_order(order, [src], "cpu", threads)
            assert np.array_equal(got.numpy(), a[order_np]), (dtype, threads)
            back = wp.zeros_like(src)
            scatter_in_order(order, [got], [back], "cpu", threads)
            assert np.array_equal(back.numpy(), a), (dtype, threads)
    strided = wp.array(np.arange(2 * n, dtype=np.float32)[::2], dtype=float, device="cpu", copy=False)
    assert not strided.is_contiguous
    (got,) = gather_in_order(order, [strided], "cpu")
    assert np.array_equal(got.numpy(), np.arange(2 * n, dtype=np.float32)[::2][order_np])
