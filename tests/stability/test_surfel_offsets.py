"""Where the gathered probes' surfels start their shadow rays (``probesurfels.shadow_ray_offsets``,
``shadow_origins``): at one of the surfel's own hits, the one nearest a point of the surfel's square
across its normal, the points spread so that the consecutive surfels of a row (numbered along the
grid's z first) do not start from the same place."""

from __future__ import annotations

import numpy as np

from serenity.kernels.probesurfels import SURFEL_SHADOW_SPREAD, shadow_origins, shadow_ray_offsets


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


def test_a_surfel_at_a_wall_starts_its_ray_at_one_of_its_own_hits():
    """A floor surfel whose hits lie only in the strip beside a wall (x < 0.05 of a 0.4 m cube; the
    wall at x = 0.05): the point of its square may lie beyond the wall's face, inside it, and the ray
    would start in the wall; the origin is the hit nearest that point, on the floor before the wall."""
    rng = np.random.default_rng(1)
    size = 0.4
    hits = np.stack([rng.uniform(0.0, 0.05, 200), np.zeros(200), rng.uniform(0.0, size, 200)], axis=1)
    surfel = np.zeros(200, np.int64)
    means = hits.mean(axis=0, keepdims=True)
    normals = np.array([[0.0, 1.0, 0.0]])
    origin = shadow_origins(hits, surfel, means, normals, size)
    assert origin.shape == (1, 3)
    assert any(np.array_equal(origin[0], h) for h in hits)  # one of its hits: on the floor, before the wall
    target = means[0] + SURFEL_SHADOW_SPREAD * shadow_ray_offsets(normals, size)[0]
    d = np.linalg.norm(hits - target, axis=1)
    assert np.linalg.norm(origin[0] - target) == d.min()  # the nearest to its point
    # surfels keep their own hits apart: a second surfel's hits never serve the first
    two = shadow_origins(np.concatenate([hits, hits + [5.0, 0.0, 0.0]]), np.r_[surfel, surfel + 1],
                         np.concatenate([means, means + [5.0, 0.0, 0.0]]), np.tile(normals, (2, 1)), size)
    assert two[0, 0] < 0.05 and two[1, 0] >= 5.0
