from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from serenity.device import init_warp
from serenity.kernels import launch as launch_module
from serenity.kernels.launch import ScatterGrid, Staging, chunk_ranges, host_array, launch, slot_base

wp = init_warp()


@wp.kernel
def _histogram(values: wp.array(dtype=wp.int32), slot_starts: wp.array(dtype=int), slot_stride: int,
               out: wp.array(dtype=wp.vec4), offset: int):
    i = wp.tid() + offset
    wp.atomic_add(out, slot_base(offset, slot_starts, slot_stride) + values[i], wp.vec4(1.0, float(i % 16), 0.0, 0.0))


@wp.kernel
def _collatz_steps(start: wp.array(dtype=wp.int32), steps: wp.array(dtype=wp.int32), offset: int):
    i = wp.tid() + offset
    n = start[i]
    k = int(0)
    while n != 1 and k < 1000:
        if n % 2 == 0:
            n = n // 2
        else:
            n = 3 * n + 1
        k += 1
    steps[i] = k


@wp.kernel
def _chunk_start(out: wp.array(dtype=wp.int32), offset: int):
    out[wp.tid() + offset] = offset


@wp.kernel
def _worker_and_chunk(out: wp.array(dtype=wp.vec2i), worker: int, offset: int):
    out[wp.tid() + offset] = wp.vec2i(worker, offset)


def test_launch_gives_each_thread_at_least_min_items():
    out = wp.zeros(10_000, dtype=wp.int32, device="cpu")
    launch(_chunk_start, 10_000, [out], device="cpu", threads=4, min_items=2_500)
    assert sorted(set(out.numpy().tolist())) == [0, 2_500, 5_000, 7_500]
    launch(_chunk_start, 10_000, [out], device="cpu", threads=4, min_items=4_000)  # 2 chunks of 5000
    assert sorted(set(out.numpy().tolist())) == [0, 5_000]
    launch(_chunk_start, 10_000, [out], device="cpu", threads=4, min_items=16_384)  # one, on this thread
    assert set(out.numpy().tolist()) == {0}


def test_chunk_ranges_cover_exactly():
    for dim in (1, 7, 255, 256, 1000, 100_003):
        for threads in (1, 2, 3, 16):
            chunks = chunk_ranges(dim, threads, min_items=10)
            assert sum(c for _, c in chunks) == dim
            assert chunks[0][0] == 0
            for (s0, c0), (s1, _) in zip(chunks, chunks[1:], strict=False):
                assert s0 + c0 == s1
            assert len(chunks) <= threads


def test_split_launch_matches_single_launch(device):
    n = 50_001
    start = wp.array(np.arange(1, n + 1, dtype=np.int32), device=device)
    one = wp.zeros(n, dtype=wp.int32, device=device)
    many = wp.zeros(n, dtype=wp.int32, device=device)
    launch(_collatz_steps, n, [start, one], device=device, threads=1)
    launch(_collatz_steps, n, [start, many], device=device, threads=4)
    a, b = one.numpy(), many.numpy()
    assert np.array_equal(a, b)
    assert a[0] == 0 and a[26] == 111  # 27 takes 111 steps


def test_launch_from_a_start_index_covers_exactly_that_range(device):
    n, first, count = 5000, 1234, 3000
    start = wp.array(np.arange(1, n + 1, dtype=np.int32), device=device)
    steps = wp.full(n, -1, dtype=wp.int32, device=device)
    launch(_collatz_steps, count, [start, steps], device=device, threads=3, start=first)
    got = steps.numpy()
    assert np.all(got[:first] == -1) and np.all(got[first + count:] == -1)
    assert np.all(got[first:first + count] >= 0)
    full = wp.zeros(n, dtype=wp.int32, device=device)
    launch(_collatz_steps, n, [start, full], device=device, threads=1)
    np.testing.assert_array_equal(got[first:first + count], full.numpy()[first:first + count])


@pytest.mark.parametrize("threads", [1, 3, 8])
def test_scatter_grid_sums_every_item_once(device, threads):
    """Many items adding into few cells: the CPU's private slots (or CUDA's atomics) lose nothing, and
    a second scatter before the gather adds to the first."""
    n, cells = 140_000, 7  # >= 8 x launch.MIN_CHEAP_ITEMS_PER_THREAD: 8 slots on 8 threads
    values = np.arange(n, dtype=np.int32) % cells
    grid = ScatterGrid(cells, device, threads=threads)
    vals = wp.array(values, dtype=wp.int32, device=device)
    grid.scatter(_histogram, n, [vals])
    grid.scatter(_histogram, n, [vals])
    grid.gather()
    got = grid.array.numpy()
    idx = np.arange(n, dtype=np.float64) % 16  # small integers: float32 sums stay exact
    np.testing.assert_array_equal(got[:, 0], 2 * np.bincount(values, minlength=cells))
    np.testing.assert_array_equal(got[:, 1], 2 * np.bincount(values, weights=idx, minlength=cells))
    grid.zero()
    assert not grid.array.numpy().any()


def test_staging_wraps_or_copies_and_checks_the_device(device):
    st = Staging(device)
    a = st.input(np.arange(12, dtype=np.float64), "p", wp.vec3, 3)
    assert a.shape == (4,) and str(a.device) == device
    np.testing.assert_array_equal(a.numpy(), np.arange(12, dtype=np.float32).reshape(4, 3))
    assert st.buffer("out", 5, wp.vec3).shape == (5,)
    # one name, one buffer per dtype: asking for another dtype never hands back the first
    assert st.buffer("out", 5, wp.float32).dtype == wp.float32 and st.buffer("out", 3, wp.vec3).dtype == wp.vec3
    other = "cpu" if device != "cpu" else None
    if other:
        with pytest.raises(ValueError, match="expected"):
            st.input(wp.zeros(3, dtype=wp.vec3, device=other), "p", wp.vec3, 3)
    assert host_array(wp.zeros(3, dtype=float, device="cpu")).shape == (3,)


def test_balanced_launch_covers_exactly_once_in_any_order():
    """balanced: shrinking chunks handed out to whichever worker is free; every item once."""
    n = 100_003
    start = wp.array(np.arange(1, n + 1, dtype=np.int32), device="cpu")
    one = wp.zeros(n, dtype=wp.int32, device="cpu")
    launch(_collatz_steps, n, [start, one], device="cpu", threads=1)
    for threads, min_chunk in ((2, 4096), (3, 100), (8, 1)):
        out = wp.full(n, -1, dtype=wp.int32, device="cpu")
        launch(_collatz_steps, n, [start, out], device="cpu", threads=threads, balanced=True, min_chunk=min_chunk)
        assert np.array_equal(out.numpy(), one.numpy()), (threads, min_chunk)
    part = wp.full(n, -1, dtype=wp.int32, device="cpu")
    launch(_collatz_steps, 50_000, [start, part], device="cpu", threads=2, start=7, balanced=True)
    got = part.numpy()
    assert np.all(got[:7] == -1) and np.all(got[50_007:] == -1)
    assert np.array_equal(got[7:50_007], one.numpy()[7:50_007])


def test_worker_arg_names_the_worker_thread_of_each_chunk():
    """``worker_arg``: every chunk gets the index of the worker that runs it, below the thread
    count (per-worker workspace memory relies on it), one index per chunk; 0 for a single chunk."""
    n = 200_000
    for threads, k in ((1, False), (2, False), (2, True), (3, True), (8, True)):
        out = wp.full(n, wp.vec2i(-1, -1), dtype=wp.vec2i, device="cpu")
        launch(_worker_and_chunk, n, [out], device="cpu", threads=threads, balanced=k, worker_arg=True)
        got = out.numpy()
        assert got[:, 0].min() >= 0 and got[:, 0].max() < threads, (threads, k)
        for start in np.unique(got[:, 1]):
            assert len(np.unique(got[got[:, 1] == start, 0])) == 1, (threads, k, start)
        if threads == 1:
            assert np.all(got[:, 0] == 0)


def test_balanced_launch_chunks_shrink_to_min_chunk():
    """A balanced launch's chunks (guided scheduling) shrink as the range is used up: each takes
    1 / (2 · workers) of what is left, none is smaller than ``min_chunk`` but the last; one chunk
    for one worker. The launch runs every item in chunks of exactly those sizes."""
    from serenity.kernels.launch import MIN_ITEMS_PER_CHUNK, guided_ranges

    n = 57_600
    assert guided_ranges(n, 1, 256) == [(0, n)]
    for workers, min_chunk in ((2, 256), (2, MIN_ITEMS_PER_CHUNK), (3, 1000)):
        chunks = guided_ranges(n, workers, min_chunk)
        starts = [a for a, _ in chunks]
        counts = [c for _, c in chunks]
        assert starts == list(np.cumsum([0] + counts[:-1])) and sum(counts) == n
        assert counts[0] == n // (2 * workers) and all(a >= b for a, b in zip(counts, counts[1:], strict=False))
        assert min(counts[:-1]) >= min_chunk
    chunks = guided_ranges(n, 2, 256)
    out = wp.full(n, wp.vec2i(-1, -1), dtype=wp.vec2i, device="cpu")
    launch(_worker_and_chunk, n, [out], device="cpu", threads=2, balanced=True, worker_arg=True, min_chunk=256)
    assert sorted(int(x) for x in np.unique(out.numpy()[:, 1])) == [a for a, _ in chunks]


def test_staging_filled_refills_only_when_the_value_or_length_changes():
    """``Staging.filled``: a buffer of one value, filled again only for another value or more
    elements (a query's scalar tmax); a scalar tmax that changes between queries is honoured."""
    st = Staging("cpu")
    a = st.filled("t", 100, float, 2.0)
    assert np.all(a.numpy() == 2.0)
    a.numpy()[:] = -1.0  # not refilled for the same value and length: the marker stays
    assert np.all(st.filled("t", 50, float, 2.0).numpy() == -1.0)
    assert np.all(st.filled("t", 100, float, 3.0).numpy() == 3.0)
    assert np.all(st.filled("t", 1000, float, 3.0).numpy() == 3.0)  # more elements: a new buffer, filled
    assert np.all(st.filled("t", 1000, float, np.inf).numpy() == np.inf)

    from serenity.kernels.kdtree import KdTree
    from serenity.scene.procedural import lumpy_mesh

    v, f = lumpy_mesh(2)
    tree = KdTree.build(v, f, cache=False, progress=False)
    o = np.zeros((64, 3), np.float32)
    d = np.tile(np.array([[0.0, 0.0, 1.0]], np.float32), (64, 1))
    far = tree.intersect(o, d, np.inf, device="cpu")
    assert far.hit.all()
    near = tree.intersect(o, d, 0.5 * float(far.t.min()), device="cpu")
    assert not near.hit.any()
    assert np.array_equal(tree.intersect(o, d, np.inf, device="cpu").t, far.t)


def test_run_chunks_runs_each_chunk_once_and_raises_a_chunks_error():
    """The calling thread works beside the pool (worker 0): every chunk runs once, by some worker
    below the count, and an error in a chunk reaches the caller after the chunks taken are done."""
    import threading
    import time

    from serenity.kernels.launch import _run_chunks

    seen, lock = [], threading.Lock()

    def run(worker, first, count):
        time.sleep(0.001 * (first % 3))
        with lock:
            seen.append((worker, first, count))

    chunks = [(k * 10, 10) for k in range(25)]
    _run_chunks(run, chunks, 3)
    assert sorted((f, c) for _, f, c in seen) == chunks
    assert {w for w, _, _ in seen} <= {0, 1, 2} and 0 in {w for w, _, _ in seen}

    def fail(worker, first, count):
        if first == 50:
            raise ValueError("chunk 5")

    with pytest.raises(ValueError, match="chunk 5"):
        _run_chunks(fail, chunks, 2)


def test_the_launch_pool_grows_safely_while_another_thread_uses_it():
    """Two threads asking for ever larger pools while submitting to what they got: no submit meets a
    pool that was shut down under it (the volume worker and the main thread both launch)."""
    errors = []

    def user(offset):
        try:
            for n in range(1, 40):
                pool = launch_module._executor(n + offset)
                pool.submit(lambda: None).result()
        except RuntimeError as e:  # "cannot schedule new futures after shutdown"
            errors.append(e)

    with ThreadPoolExecutor(2) as ex:
        list(ex.map(user, (0, 1)))
    assert not errors
