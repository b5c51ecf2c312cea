"""Queries with Warp arrays in and out: the kd-tree's rays given on the query's device and its hits left
there give the numpy path's hits bit for bit, on every device (the CPU always, CUDA where there is
one), for every traversal, order and form of tmax, through an alpha test too; a GPU query of device
arrays copies nothing to or from the host; bad arrays are one-line errors. And the LPV's propagation,
with the stop decided on the device (CUDA's way), reads nothing back per iteration."""

from __future__ import annotations

import numpy as np
import pytest

from serenity.config import LPVConfig
from serenity.device import init_warp
from serenity.errors import SerenityError
from serenity.kernels import lpv as L
from serenity.kernels.kdtree import PACKET_LANES, SORT_MIN_RAYS, KdTree
from serenity.scene.procedural import lumpy_mesh

wp = init_warp()


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    """Builds in these tests never touch the user's cache."""
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


@pytest.fixture(scope="module")
def mesh():
    return lumpy_mesh(3)


@pytest.fixture(scope="module")
def tree(mesh):
    return KdTree.build(*mesh, cache=False, progress=False)


def _rays(n: int, coherent: bool, seed: int = 3):
    """n rays at the lumpy mesh: ``coherent`` from one eye over a grid of directions (camera rays),
    else from random points in random directions; a few degenerate ones (zero or NaN direction), and
    per-ray tmax from 0.5 to 8 (some rays end before their hit)."""
    rng = np.random.default_rng(seed)
    if coherent:
        side = int(np.ceil(np.sqrt(n)))
        u, v = np.meshgrid(np.linspace(-0.6, 0.6, side), np.linspace(-0.4, 0.4, side))
        d = np.stack([u.ravel(), v.ravel(), -np.ones(side * side)], axis=1)[:n]
        o = np.tile([0.1, 0.3, 3.5], (n, 1))
    else:
        o = rng.uniform(-1.5, 1.5, (n, 3))
        d = rng.normal(size=(n, 3))
    d[::997] = 0.0
    d[5::1009] = np.nan
    tm = rng.uniform(0.5, 8.0, n)
    return o.astype(np.float32), d.astype(np.float32), tm.astype(np.float32)


def _assert_same_hits(got, ref):
    h = got.numpy()
    for name in ("t", "prim", "u", "v"):
        np.testing.assert_array_equal(getattr(h, name), getattr(ref, name), err_msg=name)


def _on(device: str, *arrays) -> bool:
    return all(isinstance(a, wp.array) and str(a.device) == device for a in arrays)


QUERIES = [
    {"sort": False},
    {"sort": False, "rays_per_thread": 1},
    {"sort": False, "rays_per_thread": PACKET_LANES},
    {"sort": True},
    {"sort": True, "rays_per_thread": 1},
    {"sort": None},
]


@pytest.mark.parametrize("coherent", [False, True], ids=["incoherent", "coherent"])
@pytest.mark.parametrize("tmax_form", ["scalar", "warp", "numpy"])
@pytest.mark.parametrize("query", QUERIES, ids=lambda q: ",".join(f"{k}={v}" for k, v in q.items()))
def test_warp_rays_give_the_numpy_hits_as_warp_arrays(device, tree, query, tmax_form, coherent):
    """Big enough a batch that ``sort=None`` reorders the incoherent rays and leaves the coherent ones
    in their order (packets on the CPU); every path's hits equal the numpy query's."""
    o, d, tm = _rays(SORT_MIN_RAYS + 1000, coherent)
    tmax = {"scalar": np.float32(4.0), "warp": tm, "numpy": tm}[tmax_form]
    ref = tree.intersect(o, d, tmax, device, **query)
    wo = wp.array(o, dtype=wp.vec3, device=device)
    wd = wp.array(d, dtype=wp.vec3, device=device)
    wtm = wp.array(tm, dtype=float, device=device) if tmax_form == "warp" else tmax
    got = tree.intersect(wo, wd, wtm, **query)  # the device: the rays'
    assert got.on_device and _on(device, got.t, got.prim, got.u, got.v)
    assert got.t.shape == (len(o),)
    _assert_same_hits(got, ref)
    assert ref.hit.sum() > len(o) // 4 and (~ref.hit).sum() > len(o) // 20  # hits and misses both
    occ = tree.occluded(wo, wd, wtm, **query)
    assert _on(device, occ) and occ.dtype == wp.int32
    np.testing.assert_array_equal(occ.numpy().astype(bool), tree.occluded(o, d, tmax, device, **query))


def test_strided_warp_rays_and_small_batches(device, tree):
    """Rays that are every other element of bigger arrays (not contiguous: packets fall back to one
    ray per kernel thread), a batch under a packet, and an empty one."""
    o, d, tm = _rays(2 * SORT_MIN_RAYS + 64, False, seed=5)
    wo = wp.array(o, dtype=wp.vec3, device=device)[::2]
    wd = wp.array(d, dtype=wp.vec3, device=device)[::2]
    assert not wo.is_contiguous
    for sort in (None, True, False):
        ref = tree.intersect(o[::2], d[::2], 6.0, device, sort=sort)
        _assert_same_hits(tree.intersect(wo, wd, 6.0, sort=sort), ref)
    few = tree.intersect(wp.array(o[:7], dtype=wp.vec3, device=device), wp.array(d[:7], dtype=wp.vec3, device=device))
    _assert_same_hits(few, tree.intersect(o[:7], d[:7], device=device))
    none = tree.intersect(wp.empty(0, dtype=wp.vec3, device=device), wp.empty(0, dtype=wp.vec3, device=device))
    assert none.on_device and _on(device, none.t, none.prim) and none.t.shape == (0,)
    assert tree.occluded(wp.empty(0, dtype=wp.vec3, device=device),
                         wp.empty(0, dtype=wp.vec3, device=device)).shape == (0,)


def test_each_query_gives_arrays_of_its_own(device, tree):
    """The hits are new arrays, not the tree's workspace buffers: a second query leaves the first's
    hits as they were."""
    o, d, _ = _rays(SORT_MIN_RAYS + 10, False, seed=7)
    wo, wd = wp.array(o, dtype=wp.vec3, device=device), wp.array(d, dtype=wp.vec3, device=device)
    first = tree.intersect(wo, wd, sort=True)
    kept = first.numpy()
    kept = {k: np.array(getattr(kept, k)) for k in ("t", "prim", "u", "v")}
    tree.intersect(wp.array(o[::-1].copy(), dtype=wp.vec3, device=device), wd, sort=True)
    after = first.numpy()
    for k, v in kept.items():
        np.testing.assert_array_equal(getattr(after, k), v)


def test_alpha_test_with_warp_rays(device, mesh):
    """A tree with cut-outs: the alpha test (on the host) rejects hits on some triangles, and the Warp
    rays' hits and occlusion are the numpy query's, left in the Warp arrays."""
    v, f = mesh
    tree = KdTree.build(v, f, cache=False, progress=False)
    masked = np.zeros(len(f), bool)
    masked[::3] = True
    tree.set_alpha_test(masked, lambda prim, u, w: u + 0.3 * w < 0.45)
    o, d, tm = _rays(SORT_MIN_RAYS + 500, False, seed=11)
    wo, wd = wp.array(o, dtype=wp.vec3, device=device), wp.array(d, dtype=wp.vec3, device=device)
    for sort in (True, False):
        ref = tree.intersect(o, d, tm, device, sort=sort)
        got = tree.intersect(wo, wd, wp.array(tm, dtype=float, device=device), sort=sort)
        assert got.on_device and _on(device, got.t, got.prim, got.u, got.v)
        _assert_same_hits(got, ref)
        occ = tree.occluded(wo, wd, tm, sort=sort)
        assert _on(device, occ)
        np.testing.assert_array_equal(occ.numpy().astype(bool), tree.occluded(o, d, tm, device, sort=sort))
    # the test did reject hits: without it the same rays hit those triangles
    plain = KdTree.build(v, f, cache=False, progress=False).intersect(o, d, tm, device)
    through = tree.intersect(o, d, tm, device)
    assert np.count_nonzero(plain.prim != through.prim) > 100


def test_bad_warp_rays_are_one_line_errors(device, tree):
    o, d, tm = _rays(10, False)
    wo, wd = wp.array(o, dtype=wp.vec3, device=device), wp.array(d, dtype=wp.vec3, device=device)
    bad = [
        ((wo, d), "both Warp arrays or neither"),
        ((wp.array(o.ravel(), dtype=float, device=device), wd), "wp.vec3"),
        ((wo, wd[:9]), "10 ray origins but 9 directions"),
        ((wo, wd, wp.array(tm[:9], dtype=float, device=device)), "tmax"),
        ((wo, wd, wp.array(tm.astype(np.int32), dtype=wp.int32, device=device)), "tmax"),
    ]
    for args, text in bad:
        for query in (tree.intersect, tree.occluded):
            with pytest.raises(SerenityError, match=text) as e:
                query(*args)
            assert "\n" not in str(e.value)


def test_warp_rays_on_another_device_than_the_query_s(cuda_devices, tree):
    if not cuda_devices:
        pytest.skip("no CUDA device")
    o, d, _ = _rays(10, False)
    wo, wd = wp.array(o, dtype=wp.vec3, device="cpu"), wp.array(d, dtype=wp.vec3, device="cpu")
    with pytest.raises(SerenityError, match="rays on cpu but the query's device is cuda"):
        tree.intersect(wo, wd, device=cuda_devices[0])
    with pytest.raises(SerenityError, match="origins on cpu but directions on cuda"):
        tree.intersect(wo, wp.array(d, dtype=wp.vec3, device=cuda_devices[0]))


@pytest.mark.parametrize("sort", [None, True, False])
def test_a_gpu_query_of_warp_arrays_copies_nothing_between_host_and_device(cuda_devices, tree, monkeypatch, sort):
    """Rays in, hits out, all on the GPU: no host-to-device or device-to-host copy during the queries
    (the tree itself is uploaded by the first query, before the count starts)."""
    if not cuda_devices:
        pytest.skip("no CUDA device")
    from warp._src.context import runtime

    dev = cuda_devices[0]
    o, d, tm = _rays(SORT_MIN_RAYS + 1000, False)
    wo, wd = wp.array(o, dtype=wp.vec3, device=dev), wp.array(d, dtype=wp.vec3, device=dev)
    wtm = wp.array(tm, dtype=float, device=dev)
    ref = tree.intersect(o, d, tm, dev)  # uploads the tree; compiles the kernels
    tree.intersect(wo, wd, wtm, sort=sort)
    copies = []
    with monkeypatch.context() as m:
        for name in ("wp_memcpy_h2d", "wp_memcpy_d2h"):
            real = getattr(runtime.core, name)
            m.setattr(runtime.core, name, lambda *a, _real=real, _name=name: (copies.append(_name), _real(*a))[1])
        hits = tree.intersect(wo, wd, wtm, sort=sort)
        occ = tree.occluded(wo, wd, 3.0, sort=sort)
        wp.synchronize_device(dev)
    assert copies == []
    _assert_same_hits(hits, ref)
    np.testing.assert_array_equal(occ.numpy().astype(bool), tree.occluded(o, d, 3.0, dev))


def test_device_decided_lpv_propagation_reads_nothing_back_per_iteration(device, monkeypatch):
    """With the stop decided on the device (every CUDA propagation's way, chosen here on the CPU too),
    the iterations' launches bring nothing to the host: the reads of one propagation are as many for 2
    iterations as for 9 (the sums that say which cascades are lit, and the counts at the end), where
    the early stop decided on the host reads the cells' sums after every iteration."""
    rng = np.random.default_rng(4)
    bounds = np.array([[0.0, 0.0, 0.0], [30.0, 12.0, 30.0]])
    p = rng.uniform(bounds[0], bounds[1], (2000, 3))
    # an early stop that never ends a cascade here, but is tested after every iteration (the host's
    # way reads the cells' sums back each time: 5 reads for 2 iterations, 19 for 9)
    cfg = LPVConfig(resolution=(10, 10, 12), cascades=3, early_stop=1e-7)
    vol = L.LightPropagationVolume(cfg, device=device)
    vol.fit((np.array([5.0, 2.0, 5.0]), np.array([1.0, 0.0, 1.0])), bounds)
    vol.clear()
    vol.inject(p, rng.normal(size=(2000, 3)), rng.uniform(0, 1, (2000, 3)))
    vol.inject_geometry(p[:500], rng.normal(size=(500, 3)), rng.uniform(0, 1, 500))
    vol._device_stop = True
    real = wp.array.numpy
    reads = {}
    for iterations in (2, 9):
        calls = []
        with monkeypatch.context() as m:
            m.setattr(wp.array, "numpy", lambda self, *a, _calls=calls, **k: (_calls.append(1), real(self, *a, **k))[1])
            runs = vol.propagate(iterations=iterations, one_launch=False)
        assert len(runs) >= 2 and all(r == iterations for r in runs)
        reads[iterations] = len(calls)
    assert reads[2] == reads[9] <= 3, reads
