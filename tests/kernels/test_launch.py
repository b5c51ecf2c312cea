import numpy as np

from serenity.device import init_warp
from serenity.kernels.launch import chunk_ranges, launch

wp = init_warp()


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
