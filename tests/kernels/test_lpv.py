"""Light propagation volumes (serenity/kernels/lpv/): transfer, energy, occlusion, lookups,
cascades, early stop and re-injection logic. Numbers quoted in comments were measured on the
2-core CPU; the tests assert bounds, never timings."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from serenity.config import LPVConfig
from serenity.kernels import lpv as L

SQ5 = math.sqrt(5.0)


def unit_grid_volume(device, res=16, iterations=8, early_stop=0.0, geometry_volume=False, threads=None, **kw):
    """One cascade with cell size 1 m and origin (−1, −1, −1): grid cell (i,j,k) = world [i−1, i)…
    (exactly ``iterations`` propagation steps: no scene-crossing extension; no scene-fitted cell size;
    the paper's linear transfer unless ``clamp_faces=True`` is given; no self-illumination damping
    unless ``self_damping`` is given)."""
    kw.setdefault("cross_scene", False)
    kw.setdefault("self_damping", 0.0)
    kw.setdefault("scene_cells", 0.0)
    kw.setdefault("clamp_faces", False)
    cfg = LPVConfig(resolution=res, cascades=1, iterations=iterations, early_stop=early_stop,
                      geometry_volume=geometry_volume, **kw)
    v = L.LightPropagationVolume(cfg, device=device, threads=threads)
    bounds = np.array([[0.0] * 3, [float(res - 2)] * 3])
    v.fit((bounds.mean(axis=0), np.array([0.0, 0.0, 1.0])), bounds)
    assert len(v.fitted) == 1 and v.fitted[0].cell_size == 1.0 and v.fitted[0].origin == (-1.0, -1.0, -1.0)
    v.clear()
    return v


def centre_of(cell):
    """World position of a grid cell's centre in ``unit_grid_volume``."""
    return np.asarray(cell, np.float64) - 0.5


def five_face_transfer(s: np.ndarray, d: np.ndarray, clamped: bool = False) -> np.ndarray:
    """What a cell gathers from a source of SH ``s`` (4,) at −d: the explicit 5-face sum (module doc);
    ``clamped``: each face's flux clamped at 0 (LPVConfig.clamp_faces)."""
    out = np.zeros(4)
    faces = [(d, d, L.W_FRONT)]
    for axis in range(3):
        e = np.zeros(3)
        e[axis] = 1.0
        if abs(d @ e) > 0:
            continue
        for sgn in (1.0, -1.0):
            faces.append(((2 * d + sgn * e) / SQ5, sgn * e, L.W_SIDE))
    for omega, normal, dw in faces:
        intensity = L.SH_C0 * s[0] + L.SH_C1 * (s[1:] @ omega)
        phi = dw * (max(0.0, intensity) if clamped else intensity)
        out += phi * np.array([L.VPL_K0, *(L.VPL_K1 * normal)])
    return out


def test_face_solid_angles_cover_the_sphere():
    front, side = L.face_solid_angles()
    assert front == pytest.approx(4 * math.asin(0.1), rel=1e-12)
    assert 6 * (front + 4 * side) == pytest.approx(4 * math.pi, rel=1e-12)


def test_propagation_matches_explicit_five_face_sum(device):
    v = unit_grid_volume(device, res=8, iterations=1)
    rng = np.random.default_rng(3)
    c = (4, 3, 5)
    normals = rng.normal(size=(5, 3))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    flux = rng.uniform(0.1, 2.0, size=(5, 3))
    pos = np.repeat(centre_of(c)[None], 5, 0) - 0.5 * normals  # the half-cell shift lands them in c
    v.inject(pos, normals, flux)
    v.propagate()
    inj = v.level_grid(0, "inj").astype(np.float64)
    last = v.level_grid(0, "last").astype(np.float64)
    for ch in range(3):
        s = inj[ch, c[2], c[1], c[0]]
        assert s[0] * L.SH_FLUX == pytest.approx(flux[:, ch].sum(), rel=1e-5)
        for axis in range(3):
            for sgn in (1, -1):
                d = np.zeros(3)
                d[axis] = sgn
                x, y, z = np.array(c) + d.astype(int)
                np.testing.assert_allclose(last[ch, z, y, x], five_face_transfer(s, d), rtol=1e-5, atol=1e-7)
    assert np.count_nonzero(np.abs(last[..., 0]) > 0) == 3 * 6


def _border_outflow(wave: np.ndarray) -> np.ndarray:
    """Flux (W, RGB) a wavefront (3, r, r, r, 4) sends across the grid's outer faces in one iteration."""
    t = L.TRANSFER
    lost = np.zeros(3)
    for axis, sl_hi, sl_lo in ((0, np.s_[:, :, :, -1], np.s_[:, :, :, 0]), (1, np.s_[:, :, -1, :], np.s_[:, :, 0, :]),
                               (2, np.s_[:, -1, :, :], np.s_[:, 0, :, :])):
        for sl, sgn in ((sl_hi, 1.0), (sl_lo, -1.0)):
            s = wave[sl].reshape(3, -1, 4)
            lost += L.SH_FLUX * (t["DC_DC"] * s[..., 0] + t["DC_AX"] * sgn * s[..., axis + 1]).sum(axis=1)
    return lost


def test_single_vpl_conserves_flux(device):
    # tolerance: float32 sums over 20³ cells, 1e-5 relative (measured ~3e-7); 8 iterations from the
    # centre stay inside the grid (see the next test for light that leaves it)
    v = unit_grid_volume(device, res=20, iterations=8)
    phi = np.array([[1.0, 2.0, 3.0]])
    v.inject(centre_of((10, 10, 10))[None] - [0, 0.5, 0], np.array([[0.0, 1.0, 0.0]]), phi)
    v.propagate()
    np.testing.assert_allclose(v.flux(0, "last"), phi[0], rtol=1e-5)
    np.testing.assert_allclose(v.flux(0, "accum"), 9 * phi[0], rtol=1e-5)  # injection + 8 wavefronts


def test_flux_leaving_the_grid_is_accounted_for(device):
    # a VPL two cells from the +x face, facing it: light crosses the border from iteration 2 on;
    # what stays in the grid plus what crossed its faces equals what was injected
    v = unit_grid_volume(device, res=8, iterations=1)
    phi = np.array([2.0, 1.0, 0.5])
    v.inject(centre_of((5, 4, 3))[None] - [0.5, 0, 0], np.array([[1.0, 0.0, 0.0]]), phi[None])
    lost = np.zeros(3)
    prev = v.level_grid(0, "inj").astype(np.float64)
    for k in range(1, 7):
        v.propagate(iterations=k)
        lost += _border_outflow(prev)
        prev = v.level_grid(0, "last").astype(np.float64)
        np.testing.assert_allclose(v.flux(0, "last") + lost, phi, rtol=1e-5)
    assert lost.sum() > 0.1 * phi.sum()  # measured: 17 % left within 6 iterations


def _wall_setup(device, geometry_volume, cover=1.0):
    """VPL at x = 3.5 facing +x; a wall of surfels in the plane x = 6 (a cell corner plane), facing
    the light, covering ``cover`` of each cell face. Returns the flux that reached x > 6."""
    v = unit_grid_volume(device, res=16, iterations=12, geometry_volume=geometry_volume)
    phi = np.array([[1.0, 1.0, 1.0]])
    v.inject(np.array([[3.5, 7.0, 7.0]]), np.array([[1.0, 0.0, 0.0]]), phi)
    ys, zs = np.meshgrid(np.arange(-1.0, 15.0, 0.25) + 0.125, np.arange(-1.0, 15.0, 0.25) + 0.125)
    pos = np.stack([np.full(ys.size, 6.0 - 1e-3), ys.ravel(), zs.ravel()], 1)
    nrm = np.tile([-1.0, 0.0, 0.0], (ys.size, 1))
    v.inject_geometry(pos, nrm, np.full(ys.size, 0.0625 * cover))
    v.propagate()
    acc = v.level_grid(0, "accum").astype(np.float64)
    beyond = acc[:, :, :, 8:, 0].sum(axis=(1, 2, 3)) * L.SH_FLUX  # cells 7.. are x > 6
    return beyond.mean()


def test_geometry_volume_wall_blocks_light(device):
    open_ = _wall_setup(device, False)
    half = _wall_setup(device, True, cover=0.5)
    full = _wall_setup(device, True, cover=1.0)
    assert open_ > 0
    # measured: full wall lets ~0 through (faces facing the light block 1), half cover ~50 %
    assert full < 0.02 * open_
    assert 0.3 * open_ < half < 0.7 * open_


def _random_volume(device, **kw):
    cfg = LPVConfig(resolution=12, iterations=4, early_stop=0.0, view_distance=20.0, **kw)
    v = L.LightPropagationVolume(cfg, device=device)
    bounds = np.array([[-8.0, 0.0, -8.0], [8.0, 6.0, 8.0]])
    v.fit((np.array([0.0, 2.0, -2.0]), np.array([0.3, -0.1, 1.0])), bounds)
    v.clear()
    rng = np.random.default_rng(7)
    n = 4000
    p = rng.uniform(bounds[0], bounds[1], (n, 3))
    d = rng.normal(size=(n, 3))
    v.inject(p, d, rng.uniform(0.0, 1.0, (n, 3)))
    v.propagate()
    return v, bounds, rng


def test_lookups_never_negative(device):
    v, bounds, rng = _random_volume(device)
    # random lobes: irradiance behind each lobe is negative before the clamp — the lookups clamp it
    q = rng.uniform(bounds[0] - 2, bounds[1] + 2, (20000, 3))
    n = rng.normal(size=(20000, 3))
    e = v.irradiance(q, n)
    g = v.glossy(q, n, rng.uniform(1, 100, 20000))
    assert np.all(np.isfinite(e)) and np.all(e >= 0) and e.max() > 0
    assert np.all(np.isfinite(g)) and np.all(g >= 0) and g.max() > 0


def test_irradiance_of_a_single_cell_matches_the_formula(device):
    # one VPL, no propagation: at the cell centre, E(n) = max(0, E0·l0 − E1·l·n)/s² exactly
    v = unit_grid_volume(device, res=8, iterations=0, lookup_offset=0.0)
    v.inject(centre_of((4, 4, 4))[None] - [0, 0, 0.5], np.array([[0.0, 0.0, 1.0]]), np.array([[math.pi] * 3]))
    v.propagate()
    n = np.array([[0, 0, -1.0], [0, 0, 1.0], [1.0, 0, 0]])
    e = v.irradiance(np.repeat(centre_of((4, 4, 4))[None], 3, 0), n)[:, 0]
    l0, l1 = math.pi * L.VPL_K0, math.pi * L.VPL_K1  # intensity SH of Φ = π facing +z
    expect = [L.COS_LOBE_0 * l0 + L.COS_LOBE_1 * l1, max(0.0, L.COS_LOBE_0 * l0 - L.COS_LOBE_1 * l1),
              L.COS_LOBE_0 * l0]
    np.testing.assert_allclose(e, expect, rtol=1e-5, atol=1e-7)


def _lit_floor(device, **kw):
    """A floor of exitance 50 W/m² (VPLs every 0.25 m at y = 0.01) under 3 cascades of 16³ around a
    camera at head height; returns the volume."""
    cfg = LPVConfig(resolution=16, early_stop=0.0, view_distance=24.0, geometry_volume=False, **kw)
    v = L.LightPropagationVolume(cfg, device=device)
    bounds = np.array([[-12.0, 0.0, -12.0], [12.0, 6.0, 12.0]])
    v.fit((np.array([0.0, 1.7, 0.0]), np.array([0.0, 0.0, 1.0])), bounds)
    v.clear()
    xs, zs = np.meshgrid(np.arange(-12, 12, 0.25) + 0.125, np.arange(-12, 12, 0.25) + 0.125)
    p = np.stack([xs.ravel(), np.full(xs.size, 0.01), zs.ravel()], 1)
    v.inject(p, np.tile([0.0, 1.0, 0.0], (xs.size, 1)), np.full((xs.size, 3), 0.0625 * 50.0, np.float32))
    v.propagate()
    return v


def _floor_scene(device, blend):
    return _lit_floor(device, iterations=8, blend_cells=blend)


def test_cascade_seam_step_is_small(device):
    """Irradiance 1 m above a uniformly lit floor, facing it, along a line crossing the finest
    cascade's +x border: the hard switch jumps from the fine to the coarse cascade's answer; the
    blend band must spread that jump over its width (smoothstep over 2 cells: max slope 0.75 of
    the jump per cell, 0.015 per 1/50 cell).

    Measured (CPU, 16³): hard step 0.29 of E (0.81 before the hand-over gave the fine cascade
    the coarse ones' far light: fine 39 vs coarse 68 W/m², exact 50), blended max step per 1/50
    cell 0.0024 of E."""
    hard = _floor_scene(device, 0.0)
    soft = _floor_scene(device, 2.0)
    g0 = soft.grids[0]
    x_border = g0.origin[0] + g0.extent
    h = g0.cell_size / 50
    xs = np.arange(x_border - 5 * g0.cell_size, x_border + 2 * g0.cell_size, h)
    pts = np.stack([xs, np.full(xs.size, 1.0), np.full(xs.size, g0.origin[2] + g0.extent / 2)], 1)
    nrm = np.tile([0.0, -1.0, 0.0], (xs.size, 1))
    e_hard = hard.irradiance(pts, nrm, blend=False)[:, 0]
    e_soft = soft.irradiance(pts, nrm)[:, 0]
    ref = float(np.median(e_soft))
    assert ref > 0
    step_hard = np.abs(np.diff(e_hard)).max() / ref
    step_soft = np.abs(np.diff(e_soft)).max() / ref
    print(f"seam: hard step {step_hard:.4f}, blended max step per cell/50 {step_soft:.5f} of E")
    assert step_soft <= 0.02 * step_hard + 1e-4


def _thin_wall(device, geometry_volume, leak_guard, frac):
    """A 5 cm wall (normal ±x) at x0 = 6 + frac (cells of 1 m) lit on its −x side: VPLs on the lit
    face and on a floor in front of it; surfels of both wall faces. Returns (E on the dark face,
    E on the lit face), each facing out of the wall."""
    v = unit_grid_volume(device, res=16, iterations=8, geometry_volume=geometry_volume, leak_guard=leak_guard)
    x0 = 6.0 + frac
    ys, zs = np.meshgrid(np.arange(2.0, 12.0, 0.25) + 0.125, np.arange(2.0, 12.0, 0.25) + 0.125)
    m = ys.size
    lit = np.stack([np.full(m, x0 - 0.025), ys.ravel(), zs.ravel()], 1)
    dark = np.stack([np.full(m, x0 + 0.025), ys.ravel(), zs.ravel()], 1)
    v.inject(lit, np.tile([-1.0, 0, 0], (m, 1)), np.full((m, 3), 0.0625 * 100.0))
    v.inject_geometry(np.concatenate([lit, dark]), np.concatenate([np.tile([-1.0, 0, 0], (m, 1)),
                                                                    np.tile([1.0, 0, 0], (m, 1))]),
                      np.full(2 * m, 0.0625))
    xs, zs2 = np.meshgrid(np.arange(0.0, x0 - 0.1, 0.25) + 0.125, np.arange(2.0, 12.0, 0.25) + 0.125)
    floor = np.stack([xs.ravel(), np.full(xs.size, 2.0), zs2.ravel()], 1)
    v.inject(floor, np.tile([0, 1.0, 0], (xs.size, 1)), np.full((xs.size, 3), 0.0625 * 30.0))
    v.propagate()
    q = np.array([[x0 + 0.025, 5.0, 7.0], [x0 - 0.025, 5.0, 7.0]])
    e = v.irradiance(q, np.array([[1.0, 0, 0], [-1.0, 0, 0]]))[:, 0]
    return float(e[0]), float(e[1])


def test_thin_wall_leak_with_and_without_geometry_volume(device):
    """Light on the dark side of a wall thinner than a cell (the reference there is ~0), as E_dark
    over E_lit of the plain volume, for wall positions within a cell.

    Measured (CPU): plain 0.16–0.74 (worst with the wall in a cell's far half: the trilinear lookup
    reaches the lit cell); geometry volume alone 0.003–0.44 (stops propagated light only); leak
    guard alone 0.05–0.17; geometry volume + leak guard 0.003–0.005 (0.003–0.062 while the guard
    still let cells 1/4 cell behind the surface count)."""
    rows = []
    for frac in (0.1, 0.3, 0.5, 0.7, 0.9):
        _, lit = _thin_wall(device, False, False, frac)
        r = [frac] + [_thin_wall(device, gv, guard, frac)[0] / lit
                      for gv, guard in ((False, False), (True, False), (False, True), (True, True))]
        rows.append(r)
    print("thin wall E_dark/E_lit (frac, plain, GV, guard, GV+guard):",
          [tuple(round(x, 3) for x in r) for r in rows])
    t = np.array(rows)
    plain, both = t[:, 1], t[:, 4]
    assert plain.max() > 0.3  # the classic LPV leak is there to be fixed
    assert both.max() < 0.02
    assert np.all(both <= plain + 1e-6)


def test_early_stop_and_empty_cascade_skip(device):
    # light that leaves the grid quickly: a VPL at the border facing out stops early
    v = unit_grid_volume(device, res=12, iterations=8, early_stop=0.05)
    v.inject(centre_of((11, 6, 6))[None] - [0.5, 0, 0], np.array([[1.0, 0, 0]]), np.array([[1.0, 1.0, 1.0]]))
    runs = v.propagate()
    assert 1 <= runs[0] < 8
    # in the middle of a lossless grid the change ratio is 1/(k+1): a 0.05 threshold stops after 19
    v2 = unit_grid_volume(device, res=48, iterations=30, early_stop=0.05)
    v2.inject(centre_of((24, 24, 24))[None], np.array([[0, 1.0, 0]]), np.array([[1.0, 1.0, 1.0]]))
    assert v2.propagate() == [19]
    v2.clear()
    assert v2.propagate() == [0] and v2.grids == []  # nothing injected: nothing propagated or looked up


def test_empty_fine_cascade_is_skipped_not_black(device):
    cfg = LPVConfig(resolution=16, iterations=4, early_stop=0.0, view_distance=24.0, geometry_volume=False)
    v = L.LightPropagationVolume(cfg, device=device)
    bounds = np.array([[-12.0, 0.0, -12.0], [12.0, 6.0, 12.0]])
    v.fit((np.array([0.0, 1.7, 0.0]), np.array([0.0, 0.0, 1.0])), bounds)
    assert len(v.fitted) >= 2
    fine = v.fitted[0]
    v.clear()
    # VPLs only outside the finest box
    p = np.array([[fine.origin[0] - 1.0, 0.5, fine.origin[2] - 1.0]])
    v.inject(p, np.array([[0, 1.0, 0]]), np.array([[100.0, 100.0, 100.0]]))
    runs = v.propagate()
    assert runs[0] == 0 and all(r > 0 for r in runs[1:])
    assert fine not in v.grids
    inside = np.array([[fine.origin[0] + 0.5, 1.0, fine.origin[2] + 0.5]])
    assert v.irradiance(inside, np.array([[-1.0, -1.0, -1.0]]))[0, 0] > 0


def test_fit_cascades_skips_and_snaps():
    cfg = LPVConfig(resolution=32, view_distance=64.0)
    small = np.array([[0.0, 0.0, 0.0], [5.0, 5.0, 5.0]])
    grids = L.fit_cascades([2.5, 2.5, -4.0], [0, 0, 1], small, cfg)
    assert [g.level for g in grids] == [0, 1]  # cascade 1 already holds the scene: 2 is skipped
    assert grids[-1].extent >= 5.0
    big = np.array([[-200.0, 0.0, -200.0], [200.0, 50.0, 200.0]])
    a = L.fit_cascades([0.0, 2.0, 0.0], [0, 0, 1], big, cfg)
    assert [g.level for g in a] == [0, 1, 2]
    for g in a:
        np.testing.assert_allclose(np.array(g.origin) / g.cell_size, np.round(np.array(g.origin) / g.cell_size),
                                   atol=1e-9)
    b = L.fit_cascades([0.01, 2.0, 0.01], [0, 0, 1], big, cfg)  # moved less than a cell: same grids
    assert a == b
    for inner, outer in zip(a, a[1:], strict=False):
        assert outer.cell_size == pytest.approx(inner.cell_size * cfg.cascade_scale)


def test_update_reinjects_only_when_inputs_or_camera_cell_change(device):
    cfg = LPVConfig(resolution=8, iterations=2, view_distance=16.0)
    v = L.LightPropagationVolume(cfg, device=device)
    bounds = np.array([[-8.0, 0.0, -8.0], [8.0, 4.0, 8.0]])
    rng = np.random.default_rng(0)
    vpls = [(rng.uniform(bounds[0], bounds[1], (100, 3)).astype(np.float32),
             rng.normal(size=(100, 3)).astype(np.float32), rng.uniform(0, 1, (100, 3)).astype(np.float32))]
    cam = (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    assert v.update(cam, bounds, vpls)
    assert not v.update(cam, bounds, vpls)
    cell = v.fitted[0].cell_size
    assert not v.update((cam[0] + [0.01 * cell, 0, 0], cam[1]), bounds, vpls)
    assert v.update((cam[0] + [3 * cell, 0, 0], cam[1]), bounds, vpls)
    changed = [(vpls[0][0], vpls[0][1], vpls[0][2] * 1.5)]
    assert v.update((cam[0] + [3 * cell, 0, 0], cam[1]), bounds, changed)
    assert not v.update((cam[0] + [3 * cell, 0, 0], cam[1]), bounds, changed, key=None)
    assert v.update((cam[0] + [3 * cell, 0, 0], cam[1]), bounds, lambda: changed)  # callables: no hash


def _room_update_inputs(seed=0):
    bounds = np.array([[-8.0, 0.0, -8.0], [8.0, 4.0, 8.0]])
    rng = np.random.default_rng(seed)
    p = rng.uniform(bounds[0], bounds[1], (400, 3)).astype(np.float32)
    n = rng.normal(size=(400, 3)).astype(np.float32)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    vpls = [(p, n, rng.uniform(0, 1, (400, 3)).astype(np.float32))]
    surfels = [(p, n, np.full(400, 0.5, np.float32))]
    return bounds, vpls, surfels


def test_stagger_refreshes_one_cascade_per_update_in_turn_and_converges_to_updating_all(device):
    """``LPVConfig.stagger``: the first update fills every cascade; after that, each update with new
    inputs re-injects and propagates one cascade, the next in turn, so none lags by more than
    ``cascades`` updates; with the inputs and camera then still, ``pending_levels`` counts down and
    the volume ends exactly where updating every cascade at once gets (lookups, hand-over included)."""
    bounds, vpls, surfels = _room_update_inputs()
    cfg = LPVConfig(resolution=8, iterations=4, view_distance=16.0, scene_cells=0.0, cross_scene=False)
    v = L.LightPropagationVolume(dataclasses.replace(cfg, stagger=True), device=device)
    cam = (np.array([0.0, 1.0, 0.0]), np.array([0.0, 0.0, 1.0]))
    assert v.update(cam, bounds, vpls, surfels, key=0)
    levels = [g.level for g in v.fitted]
    assert len(levels) == 3 and v.pending_levels == 0
    cell = v.fitted[-1].cell_size
    turns = []
    for k in range(1, 7):  # new inputs and a moving camera every update
        held = {g.level: g for g in v.fitted}
        moved = (cam[0] + [k * 2.0 * cell, 0, 0], cam[1])
        scaled = [(vpls[0][0], vpls[0][1], vpls[0][2] * (1 + 0.1 * k))]
        assert v.update(moved, bounds, scaled, surfels, key=k)
        assert v.pending_levels == len(levels) - 1
        refreshed = [g.level for g in v.fitted if v._held[g.level][1] == k]
        assert len(refreshed) == 1
        turns.append(refreshed[0])
        # the others still hold the grids their light was propagated in
        assert all(g == held[g.level] for g in v.fitted if g.level != refreshed[0])
    assert turns == [0, 1, 2, 0, 1, 2]
    # still inputs: one more cascade per update until none is pending
    count = 0
    while v.pending_levels:
        assert v.update(moved, bounds, scaled, surfels, key=6)
        count += 1
    assert count == len(levels) - 1 and not v.update(moved, bounds, scaled, surfels, key=6)
    whole = L.LightPropagationVolume(cfg, device=device)
    assert whole.update(moved, bounds, scaled, surfels, key=6)
    assert v.fitted == whole.fitted and v.iterations_run == whole.iterations_run
    for g in v.fitted:
        np.testing.assert_allclose(v.level_grid(g.level), whole.level_grid(g.level), rtol=1e-6, atol=1e-9)
    q = np.random.default_rng(1).uniform(bounds[0], bounds[1], (500, 3))
    nq = np.tile([0.0, 1.0, 0.0], (500, 1))
    np.testing.assert_allclose(v.irradiance(q, nq), whole.irradiance(q, nq), rtol=1e-5, atol=1e-6)


def test_split_injection_matches_single_thread():
    # the CPU scatter writes per-thread private grids; their sum must equal a one-thread injection
    rng = np.random.default_rng(5)
    n = 20000
    p = rng.uniform(0, 14, (n, 3))
    d = rng.normal(size=(n, 3))
    f = rng.uniform(0, 1, (n, 3))
    grids = []
    for threads in (1, 2):
        v = unit_grid_volume("cpu", threads=threads, geometry_volume=True)
        v.inject(p, d, f)
        v.inject(p[:5000], d[:5000], f[:5000])
        v.inject_geometry(p, d, f[:, 0])
        grids.append((v.level_grid(0, "inj").copy(), v.level_grid(0, "gv").copy()))
    np.testing.assert_allclose(grids[0][0], grids[1][0], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(grids[0][1], grids[1][1], rtol=1e-5, atol=1e-6)


def test_cpu_and_cuda_agree(cuda_devices):
    if not cuda_devices:
        pytest.skip("no CUDA device")
    out = []
    for dev in ("cpu", cuda_devices[0]):
        v, bounds, rng = _random_volume(dev, geometry_volume=True)
        q = rng.uniform(bounds[0], bounds[1], (5000, 3))
        n = rng.normal(size=(5000, 3))
        out.append((v.irradiance(q, n), v.glossy(q, n, 20.0), v.iterations_run))
    np.testing.assert_allclose(out[0][0], out[1][0], rtol=1e-4, atol=1e-5 * out[0][0].max())
    np.testing.assert_allclose(out[0][1], out[1][1], rtol=1e-4, atol=1e-5 * out[0][1].max())
    assert out[0][2] == out[1][2]


def test_pixel_areas_sum_to_the_visible_plane():
    # a plane facing the camera at depth D: its visible area is (2·D·tan(fov/2))²·aspect
    h, w, fov, depth = 90, 160, 60.0, 7.0
    t = math.tan(math.radians(fov) / 2)
    ys = (1 - 2 * (np.arange(h) + 0.5) / h) * t
    xs = (2 * (np.arange(w) + 0.5) / w - 1) * t * w / h
    gx, gy = np.meshgrid(xs, ys)
    pos = np.stack([gx * depth, gy * depth, np.full_like(gx, depth)], -1)
    nrm = np.tile([0.0, 0.0, -1.0], (h, w, 1))
    area = L.pixel_areas(pos, nrm, [0, 0, 0], [0, 0, 1], fov, h)
    assert area.sum() == pytest.approx((2 * depth * t) ** 2 * w / h, rel=1e-3)
    # sky VPLs: flux = albedo · E_sky · A, blocks of 4×4 pixels
    albedo = np.full((h, w, 3), 0.5, np.float32)
    e_sky = np.full((h, w, 3), 10.0, np.float32)
    p, n, f = L.sky_vpls_from_gbuffer(pos, nrm, albedo, e_sky, [0, 0, 0], [0, 0, 1], fov, stride=4)
    assert len(p) == math.ceil(h / 4) * (w // 4)
    assert f[:, 0].sum() == pytest.approx(0.5 * 10.0 * area.sum(), rel=0.01)
    sp, sn, sa = L.gbuffer_surfels(pos, nrm, [0, 0, 0], [0, 0, 1], fov, stride=1)
    assert sa.sum() == pytest.approx(area.sum(), rel=1e-5)


def test_hand_over_gives_the_fine_cascade_light_from_beyond_its_reach(device):
    """Irradiance 1.5 m above a uniformly lit floor (exact: 50·R²/(1+R²) → 50 W/m² for an infinite
    floor), looked up in the finest cascade only, with 2 iterations there (reach 2 cells = 1.5 m):
    without hand-over it misses all light from further away; with it, the coarser cascades' far
    light is added. Measured (CPU): 1.7 → 53.6 W/m²."""
    pts = np.array([[0.3, 1.5, 0.3]])
    down = np.array([[0.0, -1.0, 0.0]])
    off = _lit_floor(device, iterations=(2, 8, 8), handover=False, cross_scene=False)
    on = _lit_floor(device, iterations=(2, 8, 8), handover=True, cross_scene=False)
    assert len(on.grids) == 3 and on.grids[0].contains(pts)[0]
    e_off, e_on = off.irradiance(pts, down)[0, 0], on.irradiance(pts, down)[0, 0]
    print(f"E 1.5 m above the floor, finest cascade: no hand-over {e_off:.1f}, hand-over {e_on:.1f} W/m²")
    assert e_on > 3.0 * e_off
    assert 30.0 < e_on < 70.0


def test_coarsest_cascade_runs_enough_iterations_to_cross_the_scene(device):
    v = _lit_floor(device, iterations=4, cross_scene=True)
    g = v.fitted[-1]
    expect = min(g.resolution, math.ceil(24.0 / g.cell_size))
    assert v.iterations_run[:-1] == [4] * (len(v.fitted) - 1)
    assert v.iterations_run[-1] == expect > 4


def test_iterations_per_cascade_are_validated():
    assert LPVConfig(iterations=(2, 4, 8)).iteration_counts == (2, 4, 8)
    with pytest.raises(ValueError, match="iterations"):
        LPVConfig(iterations=(8, 8))
    with pytest.raises(ValueError, match="iterations"):
        LPVConfig(iterations=-1)


def test_self_illumination_of_a_lit_plane(device):
    """The LPV's known bias (module doc): a lit plane lights itself through its VPLs' wide L1 lobes
    (exact answer 0). With the default self-illumination damping (``LPVConfig.self_damping`` = 2.5
    cells) it gets at most 0.1 of its exitance back (measured 0.018-0.054, CPU, 16³, 8 iterations,
    plane at several heights within a cell); without the damping 0.54-0.58, bounded at 0.7 so a
    change that makes it worse is noticed."""
    def ratios(**kw):
        out = []
        for y0 in (3.01, 3.3, 3.6, 3.9):
            v = unit_grid_volume(device, res=16, iterations=8, **kw)
            xs, zs = np.meshgrid(np.arange(0, 14, 0.25) + 0.125, np.arange(0, 14, 0.25) + 0.125)
            p = np.stack([xs.ravel(), np.full(xs.size, y0), zs.ravel()], 1)
            v.inject(p, np.tile([0, 1.0, 0], (xs.size, 1)), np.full((xs.size, 3), 0.0625 * 50.0))
            v.propagate()
            out.append(float(v.irradiance(np.array([[7.0, y0, 7.0]]), np.array([[0, 1.0, 0]]))[0, 0]) / 50.0)
        return out

    damped, undamped = ratios(self_damping=LPVConfig().self_damping), ratios()
    print("self-illumination E/M, default:", [round(r, 3) for r in damped], "undamped:",
          [round(r, 3) for r in undamped])
    assert all(0.0 <= r <= 0.1 for r in damped)
    assert all(0.0 <= r < 0.7 for r in undamped)
    assert max(damped) < 0.5 * min(undamped)


def test_self_illumination_damping_of_a_lit_plane(device):
    """``LPVConfig.self_damping`` (2.5 cells by default; docs/techniques.md, "Light propagation
    volumes"): the lit plane of the test above, with its surfels in the geometry volume and the default
    lookups as in a frame, receives at most 0.1 of its exitance back (measured 0.018–0.047; 0.33–0.42
    without the damping; exact 0)."""
    from serenity.eval.stability import lpv_self_illumination

    ratios = [lpv_self_illumination(y0, device=device, surfels=True, geometry_volume=True, clamp_faces=True,
                                    self_damping=2.5) for y0 in (3.01, 3.3, 3.6, 3.9)]
    print("damped self-illumination E/M:", [round(r, 3) for r in ratios])
    assert all(0.0 <= r <= 0.1 for r in ratios)


def test_self_illumination_damping_keeps_light_from_in_front(device):
    # a lit ceiling 4 cells above a floor: the floor's light comes from in front of it (its DC grows along
    # the normal), so the damping leaves it as it is
    def floor_irradiance(damping):
        v = unit_grid_volume(device, res=16, iterations=8, clamp_faces=True, self_damping=damping)
        xs, zs = np.meshgrid(np.arange(0, 14, 0.25) + 0.125, np.arange(0, 14, 0.25) + 0.125)
        p = np.stack([xs.ravel(), np.full(xs.size, 7.0), zs.ravel()], 1)
        v.inject(p, np.tile([0, -1.0, 0], (xs.size, 1)), np.full((xs.size, 3), 0.0625 * 50.0))
        v.propagate()
        return float(v.irradiance(np.array([[7.0, 3.0, 7.0]]), np.array([[0, 1.0, 0]]))[0, 0])

    plain, damped = floor_irradiance(0.0), floor_irradiance(2.5)
    assert plain > 0.0 and damped == pytest.approx(plain, rel=1e-6)


def test_clamped_propagation_matches_the_clamped_five_face_sum(device):
    # one VPL lobe (negative behind it) propagated one step: every face of the cell behind it sees the
    # lobe's negative tail (cos < −1/2), so it gets nothing, where the linear transfer sends negative DC
    v = unit_grid_volume(device, res=8, iterations=1, clamp_faces=True)
    c = (4, 3, 5)
    n = np.array([[0.0, 1.0, 0.0]])
    v.inject(centre_of(c)[None] - 0.5 * n, n, np.array([[1.0, 2.0, 3.0]]))
    v.propagate()
    inj = v.level_grid(0, "inj").astype(np.float64)
    last = v.level_grid(0, "last").astype(np.float64)
    for ch in range(3):
        s = inj[ch, c[2], c[1], c[0]]
        for axis in range(3):
            for sgn in (1, -1):
                d = np.zeros(3)
                d[axis] = sgn
                x, y, z = np.array(c) + d.astype(int)
                np.testing.assert_allclose(last[ch, z, y, x], five_face_transfer(s, d, clamped=True),
                                           rtol=1e-5, atol=1e-7)
    below = last[:, c[2], c[1] - 1, c[0]]
    np.testing.assert_array_equal(below, 0.0)
    assert five_face_transfer(inj[0, c[2], c[1], c[0]], np.array([0.0, -1.0, 0.0]))[0] < 0.0


def test_clamped_propagation_never_creates_negative_light(device):
    v = unit_grid_volume(device, res=12, iterations=10, clamp_faces=True)
    rng = np.random.default_rng(5)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    v.inject(rng.uniform(1.0, 9.0, (200, 3)), n, rng.uniform(0.1, 1.0, (200, 3)))
    v.propagate()
    acc = v.level_grid(0, "accum")
    assert acc[..., 0].min() >= 0.0  # the linear transfer leaves negative DC behind the lobes


def test_scene_cells_coarsen_the_cascade_that_holds_the_scene():
    room = np.array([[0.0, 0.0, 0.0], [0.56, 0.55, 0.56]])  # a Cornell-box-sized closed room
    plain = L.fit_cascades([0.28, 0.27, -0.8], [0, 0, 1], room, LPVConfig(scene_cells=0.0))
    fitted = L.fit_cascades([0.28, 0.27, -0.8], [0, 0, 1], room, LPVConfig(scene_cells=6.0))
    assert plain[-1].cell_size < 0.56 / 6
    assert fitted[-1].cell_size == pytest.approx(0.56 / 6)
    assert [g.cell_size for g in fitted[:-1]] == [g.cell_size for g in plain[:-1]]  # finer cascades unchanged
    lo, hi = np.array(fitted[-1].origin), np.array(fitted[-1].origin) + fitted[-1].extent
    assert np.all(lo <= room[0]) and np.all(hi >= room[1])  # it still holds the whole scene


def test_lookup_occlusion_drops_cells_across_a_blocking_face(device):
    # a sunlit roof (VPLs facing up above a two-sided slab at y = 5.7, grid 6.7: the geometry volume
    # blocks the face at 7 and the VPLs land in cell 7) and a wall face 5 cm below the slab looking
    # along −z (home cell 6): without the occlusion its lookup reads the roof's cells above the slab.
    # (The slab in a cell's lower half: ``test_lookup_planes_put_a_wall_under_a_ceiling_below_it``.)
    def wall_top_irradiance(occlusion):
        v = unit_grid_volume(device, res=12, iterations=4, geometry_volume=True, lookup_occlusion=occlusion,
                             lookup_planes=False)
        xs, zs = np.meshgrid(np.arange(0, 10, 0.25) + 0.125, np.arange(0, 10, 0.25) + 0.125)
        p = np.stack([xs.ravel(), np.full(xs.size, 5.7), zs.ravel()], 1)
        up = np.tile([0.0, 1.0, 0.0], (xs.size, 1))
        v.inject(p, up, np.full((xs.size, 3), 0.0625 * 50.0))
        v.inject_geometry(p, up, np.full(xs.size, 0.0625))
        v.inject_geometry(p, -up, np.full(xs.size, 0.0625))
        v.propagate()
        return float(v.irradiance(np.array([[5.0, 5.65, 5.0]]), np.array([[0.0, 0.0, -1.0]]))[0, 0])

    with_occ, without = wall_top_irradiance(True), wall_top_irradiance(False)
    assert without > 1.0  # the leak (the roof's exitance is 50 W/m²); measured 3.28 W/m² without, 0.89 with:
    assert with_occ < 0.35 * without  # the rest crossed the two-sided slab (L1 blocks 2/3 of it) in propagation


def roof_over_wall(device, y_slab, planes, points, normals):
    """A sunlit roof: VPLs facing up on a two-sided slab at height y_slab (a 10 m square, exitance 50 W/m²),
    both faces in the geometry volume (as a frame's RSM and G-buffer surfels), 12³ unit cells, 4
    iterations; irradiance at ``points``. The exact answer below the slab is 0."""
    v = unit_grid_volume(device, res=12, iterations=4, geometry_volume=True, lookup_planes=planes, clamp_faces=True)
    xs, zs = np.meshgrid(np.arange(0, 10, 0.25) + 0.125, np.arange(0, 10, 0.25) + 0.125)
    p = np.stack([xs.ravel(), np.full(xs.size, y_slab), zs.ravel()], 1)
    up = np.tile([0.0, 1.0, 0.0], (xs.size, 1))
    v.inject(p, up, np.full((xs.size, 3), 0.0625 * 50.0))
    v.inject_geometry(p, up, np.full(xs.size, 0.0625))
    v.inject_geometry(p, -up, np.full(xs.size, 0.0625))
    v.propagate()
    return v.irradiance(np.asarray(points, np.float64), np.asarray(normals, np.float64))[:, 0]


@pytest.mark.parametrize("y_slab", [5.2, 5.35])
def test_lookup_planes_put_a_wall_under_a_ceiling_below_it(device, y_slab):
    # the slab in the lower half of cell 6 (grid 6.2 / 6.35): the geometry volume blocks the face at 6,
    # below the wall's top rows (grid 6.05..6.3, home cell 6 = the roof's cell). Exact: no roof light
    # below the slab; all the wall may read is the light that crossed the two-sided slab in propagation
    # (L1 blocks 2/3 of it), i.e. what cell 5 under the slab holds: the value at its centre (world
    # y 4.5). Measured (CPU, slab at 5.2): top rows 20.4–21.6 W/m² without the planes, 0.518 with,
    # = the cell below the slab.
    top = [[5.0, y_slab - d, 5.0] for d in (0.02, 0.05, 0.1)]
    below = [[5.0, 4.5, 5.0]]
    side = np.tile([0.0, 0.0, -1.0], (4, 1))
    with_planes = roof_over_wall(device, y_slab, True, top + below, side)
    without = roof_over_wall(device, y_slab, False, top + below, side)
    print("wall under a roof, top rows and the cell below the slab:", with_planes, without)
    assert without[:3].min() > 8.0 * without[3]  # the roof's light reaches the wall's top rows
    assert with_planes[3] > 0.0
    np.testing.assert_allclose(with_planes[:3], with_planes[3], rtol=0.02)  # now only the light below the slab
    assert abs(with_planes[3] - without[3]) < 0.05 * without[3]  # at the cell below nothing changes
    # the roof itself (up-facing, just above the slab) still reads its own cell, planes or not
    roof = [[5.0, y_slab + 0.01, 5.0]]
    up = [[0.0, 1.0, 0.0]]
    assert roof_over_wall(device, y_slab, True, roof, up)[0] == pytest.approx(
        roof_over_wall(device, y_slab, False, roof, up)[0], rel=1e-5)


def test_lookup_planes_locate_the_blocker_in_its_cell(device):
    # Surfels at grid y = 6.3 (world 5.3) facing ±y over the whole grid: the +y face of cell 5 (at 6)
    # holds them, 0.3 cells above the face; a wall at grid x = 4.8 (world 3.8; its face at 5 holds it
    # 0.2 below). openness() packs them in A: q = round((t + 1/2)·254).
    v = unit_grid_volume(device, res=12, iterations=1, geometry_volume=True)
    xs, zs = np.meshgrid(np.arange(0, 10, 0.25) + 0.125, np.arange(0, 10, 0.25) + 0.125)
    p = np.stack([xs.ravel(), np.full(xs.size, 5.3), zs.ravel()], 1)
    up = np.tile([0.0, 1.0, 0.0], (xs.size, 1))
    v.inject_geometry(p, up, np.full(xs.size, 0.0625))
    v.inject_geometry(p, -up, np.full(xs.size, 0.0625))
    pw = np.stack([np.full(xs.size, 3.8), xs.ravel(), zs.ravel()], 1)
    v.inject_geometry(pw, np.tile([1.0, 0.0, 0.0], (xs.size, 1)), np.full(xs.size, 0.0625))
    v.inject(np.array([[5.0, 8.0, 5.0]]), np.array([[0.0, 1.0, 0.0]]), np.ones((1, 3)))
    v.propagate()
    o = v.openness(0)
    a = o[5, 5, 4, 3].astype(np.float64)  # cell (x 4, y 5, z 5): +x face at 5 (the wall), +y face at 6
    q = np.array([a % 256, (a // 256) % 256, a // 65536])
    assert q[1] == round(0.8 * 254) and q[0] == round(0.3 * 254) and q[2] == 127
    assert o[5, 5, 4, 1] == 0.0 and o[5, 5, 4, 0] == 0.0  # both fully covered: closed to lookups


def test_accumulated_grid_without_the_injected_lobes(device):
    v = unit_grid_volume(device, res=10, iterations=3, accumulate_injected=False)
    c = (5, 5, 5)
    n = np.array([[0.0, 1.0, 0.0]])
    v.inject(centre_of(c)[None] - 0.5 * n, n, np.array([[1.0, 1.0, 1.0]]))
    v.propagate()
    acc, inj = v.level_grid(0, "accum"), v.level_grid(0, "inj")
    w = unit_grid_volume(device, res=10, iterations=3)
    w.inject(centre_of(c)[None] - 0.5 * n, n, np.array([[1.0, 1.0, 1.0]]))
    w.propagate()
    np.testing.assert_allclose(acc, w.level_grid(0, "accum") - inj, atol=1e-6)


def test_clamped_propagation_equals_the_linear_one_for_a_non_negative_source(device):
    # a source whose intensity is positive in every direction (two opposite lobes and a weak third):
    # no face is clamped, so the clamped gather takes the linear transfer's shortcut — same result
    grids = []
    for clamp in (False, True):
        v = unit_grid_volume(device, res=8, iterations=1, clamp_faces=clamp)
        c = centre_of((4, 3, 5))
        n = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])
        v.inject(c[None] - 0.1 * n, n, np.array([[1.0, 1.0, 1.0], [1.0, 1.0, 1.0], [0.2, 0.3, 0.4]]))
        v.propagate()
        grids.append(v.level_grid(0, "last").astype(np.float64))
    assert np.abs(grids[0]).max() > 0
    np.testing.assert_allclose(grids[1], grids[0], rtol=1e-5, atol=1e-7)


def test_coverage_blocking_stops_the_thin_wall_leak(device):
    # the stability suite's 5 cm two-sided wall at 5 positions across a 1 m cell (exact dark side: 0).
    # The L1 blocking of a two-sided wall is 2/3, and with clamped faces the worst leak is 0.095 of the
    # lit side; the projected coverage closes the wall's face. Measured (CPU): worst 0.0063.
    from serenity.eval.stability import lpv_thin_wall

    def worst(coverage):
        # undamped: the default self-illumination damping alone takes the worst leak to 0.005
        r = [lpv_thin_wall(f, True, True, device, coverage_blocking=coverage, self_damping=0.0)
             for f in (0.1, 0.3, 0.5, 0.7, 0.9)]
        assert all(lit > 1.0 for _, lit in r)  # the lit side still gets its light
        return max(d / lit for d, lit in r)

    assert worst(False) > 0.05
    assert worst(True) < 0.02


@pytest.mark.parametrize("kw", [{}, {"geometry_volume": True, "early_stop": 0.0},
                                {"geometry_volume": True, "clamp_faces": True, "iterations": (6, 9, 14)}],
                         ids=["early-stop", "geometry-volume", "clamped"])
def test_one_launch_propagation_equals_a_launch_per_iteration(device, kw):
    # propagate(one_launch=True) runs every iteration inside one single-threaded kernel (on the CPU
    # it saves a launch's Python per iteration); the light, the far light handed over, the last
    # wavefront and the iteration counts (early stop included) must be those of the per-iteration path
    rng = np.random.default_rng(11)
    cfg = LPVConfig(resolution=(10, 10, 12), cascades=3, early_stop=kw.pop("early_stop", 0.15), **kw)
    bounds = np.array([[0.0, 0.0, 0.0], [30.0, 12.0, 30.0]])
    p = rng.uniform(bounds[0], bounds[1], (3000, 3))
    n = rng.normal(size=(3000, 3))
    f = rng.uniform(0, 1, (3000, 3))
    v = L.LightPropagationVolume(cfg, device=device)
    v.fit((np.array([5.0, 2.0, 5.0]), np.array([1.0, 0.0, 1.0])), bounds)
    v.clear()
    v.inject(p, n, f)
    v.inject_geometry(p[:1000], n[:1000], f[:1000, 0])
    got = {}
    # the per-iteration launches with the early stop decided on the host (the CPU's way) and on the
    # device (CUDA's: no copy per iteration; lpv/early_stop.py), and the one launch
    for way in ("host", "device", "one"):
        v._device_stop = way == "device"
        runs = v.propagate(one_launch=way == "one")
        got[way] = (runs, [(v.level_grid(k, "accum").copy(), v.level_grid(k, "last").copy())
                           for k in range(3)], v._far.numpy().copy())
    # two cascades fitted; the early stop (0.15) ends them at 5 and 6 of their 8 iterations
    for way in ("device", "one"):
        assert got["host"][0] == got[way][0] and len(got[way][0]) == 2 and min(got[way][0]) >= 1
        for (a, la), (b, lb) in zip(got["host"][1], got[way][1], strict=True):
            np.testing.assert_array_equal(a, b)
            np.testing.assert_array_equal(la, lb)
        np.testing.assert_array_equal(got["host"][2], got[way][2])
