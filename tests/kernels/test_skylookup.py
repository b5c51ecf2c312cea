"""The sky volume's lookup, defined once (``skylookup.lookup_reference``): the Warp lookup the kernels
use and the numpy one the host uses give its answer, plain trilinear and with the traced probes'
visibility, inside the grid, at its edges and beyond them (the fade to the open sky)."""

import numpy as np
import pytest
import warp as wp

from serenity.kernels import sh as S
from serenity.kernels.launch import launch
from serenity.kernels.skylookup import (
    VIS_OCT,
    VIS_TILE,
    interpolate_volume,
    lookup_reference,
    lookup_sky_irradiance,
    probe_grid,
    probe_volume,
)

RES = (4, 3, 5)
ORIGIN = np.array([-1.0, 0.25, -2.0])
CELL = np.array([0.5, 0.75, 0.6])
OFFSET = 0.1


def _volume(seed: int, visibility: bool):
    """Random coefficients (a positive band 0, so that most irradiance is above the clamp), an open sky,
    and with ``visibility`` a random atlas of depth moments (variance ≥ 0) and relocations."""
    rng = np.random.default_rng(seed)
    x, y, z = RES
    coeffs = rng.normal(scale=0.3, size=(z, y, x, 27)).astype(np.float32)
    coeffs[..., :3] += 2.0
    open_sky = rng.normal(scale=0.3, size=(9, 3)) + np.r_[[2.0, 2.0, 2.0], np.zeros(24)].reshape(9, 3)
    vis = None
    if visibility:
        mean = rng.uniform(0.1, 1.5, size=(z * VIS_TILE, y, x * VIS_TILE)).astype(np.float32)
        second = (mean ** 2 + rng.uniform(0.0, 0.2, size=mean.shape)).astype(np.float32)
        offsets = rng.uniform(-0.2, 0.2, size=(x * y * z, 3)).astype(np.float32)
        vis = (np.stack([mean, second], axis=-1), offsets)
    return coeffs, open_sky, vis


def _points(seed: int, n: int):
    rng = np.random.default_rng(seed)
    hi = ORIGIN + (np.array(RES) - 1) * CELL
    p = rng.uniform(ORIGIN - 2.0, hi + 2.0, size=(n, 3))  # inside, at the sides and beyond the fade
    nrm = rng.normal(size=(n, 3))
    return p, nrm / np.linalg.norm(nrm, axis=1, keepdims=True)


@pytest.mark.parametrize("visibility", [False, True], ids=["trilinear", "visibility"])
def test_numpy_lookup_is_the_definition(visibility):
    coeffs, open_sky, vis = _volume(1, visibility)
    p, n = _points(2, 300)
    got = interpolate_volume(coeffs, ORIGIN, CELL, RES, OFFSET, p, n, open_sky, vis)
    want = np.stack([lookup_reference(coeffs, ORIGIN, CELL, RES, OFFSET, p[i], n[i], open_sky, vis)
                     for i in range(len(p))])
    assert np.allclose(got, want, rtol=1e-9, atol=1e-9)
    assert not np.allclose(want, want[:1])  # the points see different probes


@pytest.mark.parametrize("visibility", [False, True], ids=["trilinear", "visibility"])
def test_warp_lookup_is_the_definition(device, visibility):
    coeffs, open_sky, vis = _volume(3, visibility)
    p, n = _points(4, 300)
    dev = device
    if vis is None:
        vis_wp = (wp.zeros((0, 0, 0), dtype=wp.vec2, device=dev), wp.zeros(0, dtype=wp.vec3, device=dev))
    else:
        vis_wp = (wp.array(vis[0], dtype=wp.vec2, device=dev), wp.array(vis[1], dtype=wp.vec3, device=dev))
    vol = probe_volume(probe_grid(ORIGIN, CELL, RES), OFFSET,
                       wp.array(coeffs.reshape(-1, 27), dtype=float, device=dev),
                       wp.array(open_sky.reshape(-1).astype(np.float32), dtype=float, device=dev), *vis_wp)
    out = wp.empty(len(p), dtype=wp.vec3, device=dev)
    launch(lookup_sky_irradiance, len(p), [vol, wp.array(p.astype(np.float32), dtype=wp.vec3, device=dev),
                                           wp.array(n.astype(np.float32), dtype=wp.vec3, device=dev), out], device=dev)
    # the definition in float32's inputs (the points, the grid and the sky as the kernel sees them)
    f32 = [np.asarray(a, np.float32).astype(np.float64) for a in (p, n, ORIGIN, CELL, open_sky)]
    c = np.stack([lookup_reference(coeffs, f32[2], f32[3], RES, np.float32(OFFSET), f32[0][i], f32[1][i], f32[4], vis)
                  for i in range(len(p))])
    want = np.maximum(np.einsum("nk,nkc->nc", S.sh_basis(f32[1]), c), 0.0)
    scale = np.maximum(np.abs(want).max(axis=1, keepdims=True), 1e-3)
    assert np.abs(out.numpy() - want).max(initial=0.0) <= 1e-4 * scale.max()
    assert np.all(np.abs(out.numpy() - want) / scale <= 1e-4)


def test_visibility_atlas_tiles_match_the_lookup():
    """The atlas's tile of probe (x, y, z) is where the lookup reads that probe's moments: a probe whose
    tile says its rays stop short of the point adds next to nothing; with a tile that sees far, it adds
    its trilinear share."""
    coeffs, _, vis = _volume(5, True)
    atlas, offsets = vis[0].copy(), np.zeros_like(vis[1])
    p = ORIGIN + np.array([1.5, 1.0, 2.5]) * CELL  # the middle of a cell
    n = np.array([0.0, 1.0, 0.0])
    atlas[..., 0], atlas[..., 1] = 10.0, 100.0  # every probe sees far
    x0, y0, z0 = 1, 1, 2  # one corner of the cell
    brighter = coeffs.copy()
    brighter[z0, y0, x0] += 10.0

    def change(atlas):
        a, b = (lookup_reference(c, ORIGIN, CELL, RES, 0.0, p, n, None, (atlas, offsets)) for c in (coeffs, brighter))
        return np.abs(b - a).max()

    assert change(atlas) > 0.5  # seen: its share of the 10
    atlas[z0 * VIS_TILE:(z0 + 1) * VIS_TILE, y0, x0 * VIS_TILE:(x0 + 1) * VIS_TILE] = (1e-3, 1e-6)
    assert VIS_OCT + 2 == VIS_TILE and change(atlas) < 1e-3  # hidden: crushed
