"""The LPV's temporal blend (``LPVConfig.temporal_blend``, ``LightPropagationVolume.update``'s
``blend``): what lookups read moves a fraction of the way to each new propagation, in world space
when a cascade's box moves, and ends exactly on the newest light."""

from __future__ import annotations

import numpy as np

from serenity.config import LPVConfig
from serenity.kernels.lpv import LightPropagationVolume
from serenity.kernels.lpv.volume import blend_updates

BOUNDS = np.array([[-8.0, 0.0, -8.0], [8.0, 4.0, 8.0]])
CFG = LPVConfig(resolution=8, iterations=4, view_distance=16.0, scene_cells=0.0, cross_scene=False)


def _inputs(seed: int, scale: float = 1.0):
    rng = np.random.default_rng(seed)
    p = rng.uniform(BOUNDS[0], BOUNDS[1], (400, 3)).astype(np.float32)
    n = rng.normal(size=(400, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    return [(p, n, rng.uniform(0, 1, (400, 3)).astype(np.float32) * scale)], [(p, n, np.full(400, 0.5, np.float32))]


def _grids(v):
    return {g.level: v.level_grid(g.level).astype(np.float64) for g in v.fitted}


def _exact(cam, vpls, surfels):
    w = LightPropagationVolume(CFG)
    w.update(cam, BOUNDS, vpls, surfels, key=0)
    return w


def test_blend_moves_a_fraction_per_update_and_ends_exactly_on_the_newest_light():
    """First update: the propagation as it is. New inputs: each level's grid at a + α(b − a), then
    α of what is left per update with unchanged inputs (``pending_levels`` > 0, ``stale_levels`` 0,
    ``blend`` steps without inputs), and after ``blend_updates(α)`` updates exactly b; lookups read
    the blended grid."""
    alpha = 0.4
    cam = (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    v = LightPropagationVolume(CFG)
    (va, sa), (vb, sb) = _inputs(0), _inputs(0, 2.0)
    assert v.update(cam, BOUNDS, va, sa, key=0, blend=alpha)
    a = _grids(v)
    for lv, g in _grids(_exact(cam, va, sa)).items():
        np.testing.assert_array_equal(a[lv], g)  # nothing to blend from: shown at once
    assert v.pending_levels == 0
    b = _grids(_exact(cam, vb, sb))
    assert v.update(cam, BOUNDS, vb, sb, key=1, blend=alpha)
    left = 1.0 - alpha
    for lv in a:
        np.testing.assert_allclose(_grids(v)[lv], b[lv] + left * (a[lv] - b[lv]), rtol=1e-5, atol=1e-6)
    assert v.pending_levels == len(a) and v.stale_levels == 0
    q = np.random.default_rng(1).uniform(BOUNDS[0], BOUNDS[1], (200, 3))
    nq = np.tile([0.0, 1.0, 0.0], (200, 1))
    e_mid = v.irradiance(q, nq)
    steps = blend_updates(alpha)
    assert left ** (steps - 1) >= 0.01 > left ** steps
    for k in range(2, steps):
        assert v.blend(alpha) if k % 2 else v.update(cam, BOUNDS, vb, sb, key=1, blend=alpha)
        left *= 1.0 - alpha
        for lv in a:
            np.testing.assert_allclose(_grids(v)[lv], b[lv] + left * (a[lv] - b[lv]), rtol=1e-5, atol=1e-6)
        assert v.pending_levels == len(a)
    assert v.update(cam, BOUNDS, vb, sb, key=1, blend=alpha)  # the last step: exactly the newest
    for lv in a:
        np.testing.assert_array_equal(_grids(v)[lv], b[lv])
    assert v.pending_levels == 0 and not v.update(cam, BOUNDS, vb, sb, key=1, blend=alpha) and not v.blend(alpha)
    e_end, e_a = v.irradiance(q, nq), _exact(cam, va, sa).irradiance(q, nq)
    np.testing.assert_allclose(e_end, _exact(cam, vb, sb).irradiance(q, nq), rtol=1e-6, atol=1e-7)
    assert not np.allclose(e_mid, e_end) and not np.allclose(e_mid, e_a)


def test_blend_follows_a_moving_box_in_world_space():
    """A camera moved by whole cells moves the finest box: each cell of the new box blends from the
    cell of the old box at the same place, and cells the old box did not hold show the newest light."""
    alpha = 0.5
    cam = (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    vpls, surfels = _inputs(3)
    v = LightPropagationVolume(CFG)
    v.update(cam, BOUNDS, vpls, surfels, key=0, blend=alpha)
    before = {g.level: (g, v.level_grid(g.level).astype(np.float64)) for g in v.fitted}
    cell = v.fitted[0].cell_size
    moved = (cam[0] + [2.0 * cell, 0.0, 0.0], cam[1])
    vb, sb = _inputs(3, 1.5)
    v.update(moved, BOUNDS, vb, sb, key=1, blend=alpha)
    target = _exact(moved, vb, sb)
    shifted = 0
    for g in v.fitted:
        old_grid, old = before[g.level]
        new = target.level_grid(g.level).astype(np.float64)
        shift = np.rint((np.asarray(g.origin) - np.asarray(old_grid.origin)) / g.cell_size).astype(int)
        shifted += int(np.any(shift != 0))
        want = new.copy()
        r = g.resolution
        z, y, x = np.meshgrid(np.arange(r), np.arange(r), np.arange(r), indexing="ij")
        ox, oy, oz = x + shift[0], y + shift[1], z + shift[2]
        inside = (ox >= 0) & (oy >= 0) & (oz >= 0) & (ox < r) & (oy < r) & (oz < r)
        prev = old[:, oz.clip(0, r - 1), oy.clip(0, r - 1), ox.clip(0, r - 1)]
        want[:, inside] = prev[:, inside] + alpha * (new[:, inside] - prev[:, inside])
        np.testing.assert_allclose(v.level_grid(g.level), want, rtol=1e-5, atol=1e-6)
    assert shifted >= 1
