"""Where the gathered probes' surfels start their shadow rays (``probegather.shadow_ray_offsets``):
in the surfel's square across its normal, at points spread so that the consecutive surfels of a
row (numbered along the grid's z first) do not start from the same place."""

from __future__ import annotations

import numpy as np

from serenity.kernels.probegather import shadow_ray_offsets


def test_offsets_lie_in_the_square_across_the_normal_and_spread_along_a_row():
    rng = np.random.default_rng(0)
    n = rng.normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    size = 0.4
    off = shadow_ray_offsets(n, size)
    assert off.shape == (500, 3)
    np.testing.assert_allclose(np.sum(off * n, axis=1), 0.0, atol=1e-12)  # in the surfel's plane
    assert np.all(np.linalg.norm(off, axis=1) <= size / np.sqrt(2) + 1e-12)  # within its square
    # a row of ground surfels (normal +y): every 8 consecutive ones cover most of the square on both axes
    up = shadow_ray_offsets(np.tile([0.0, 1.0, 0.0], (64, 1)), size)
    assert np.allclose(up[:, 1], 0.0)
    for k in range(0, 56, 8):
        block = up[k:k + 8]
        for axis in (0, 2):
            gaps = np.diff(np.sort(np.concatenate([block[:, axis], [-size / 2, size / 2]])))
            assert gaps.max() < 0.3 * size, (k, axis)
    assert np.array_equal(shadow_ray_offsets(n, size), off)  # fixed per surfel
