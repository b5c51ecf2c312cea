"""Where the light propagation volume fails: a wall thinner than a cell, a lit plane lighting itself,
a small light near a floor; each against its exact answer, mitigation off and on.
"""

from __future__ import annotations

import math
import time

import numpy as np

from serenity.config import LPVConfig
from serenity.eval.stability.harness import UP, Case, timed
from serenity.kernels.lpv import LightPropagationVolume


def _unit_lpv(res: int, cell: float, iterations: int, device=None, **kw):
    """One cascade of ``res``³ cells of ``cell`` m with its origin at (−cell, −cell, −cell) (the cell
    size as given: no scene-fitted coarsening)."""
    kw.setdefault("cross_scene", False)
    kw.setdefault("scene_cells", 0.0)
    cfg = LPVConfig(resolution=res, cascades=1, iterations=iterations, early_stop=0.0, **kw)
    v = LightPropagationVolume(cfg, device=device)
    bounds = np.array([[0.0] * 3, [(res - 2) * cell] * 3])
    v.fit((bounds.mean(axis=0), np.array([0.0, 0.0, 1.0])), bounds)
    v.clear()
    return v


def lpv_thin_wall(frac: float, geometry_volume: bool, leak_guard: bool, device=None,
                  **lpv) -> tuple[float, float]:
    """A 5 cm wall (a twentieth of a 1 m cell) at x = 6 + ``frac`` lit on its −x face (VPLs of
    100 W/m² exitance on the lit face, a lit floor in front), surfels on both faces. Returns
    (E on the dark face, E on the lit face), W/m², each facing out of the wall. Exact dark face: 0
    (nothing lies on its side). ``lpv``: other LPVConfig fields."""
    v = _unit_lpv(16, 1.0, 8, device, geometry_volume=geometry_volume, leak_guard=leak_guard, **lpv)
    x0 = 6.0 + frac
    ys, zs = np.meshgrid(np.arange(2.0, 12.0, 0.25) + 0.125, np.arange(2.0, 12.0, 0.25) + 0.125)
    m = ys.size
    lit = np.stack([np.full(m, x0 - 0.025), ys.ravel(), zs.ravel()], 1)
    dark = np.stack([np.full(m, x0 + 0.025), ys.ravel(), zs.ravel()], 1)
    west, east = np.tile([-1.0, 0, 0], (m, 1)), np.tile([1.0, 0, 0], (m, 1))
    v.inject(lit, west, np.full((m, 3), 0.0625 * 100.0))
    v.inject_geometry(np.concatenate([lit, dark]), np.concatenate([west, east]), np.full(2 * m, 0.0625))
    xs, zs2 = np.meshgrid(np.arange(0.0, x0 - 0.1, 0.25) + 0.125, np.arange(2.0, 12.0, 0.25) + 0.125)
    floor = np.stack([xs.ravel(), np.full(xs.size, 2.0), zs2.ravel()], 1)
    v.inject(floor, np.tile(UP, (xs.size, 1)), np.full((xs.size, 3), 0.0625 * 30.0))
    v.propagate()
    q = np.array([[x0 + 0.025, 5.0, 7.0], [x0 - 0.025, 5.0, 7.0]])
    e = v.irradiance(q, np.array([[1.0, 0, 0], [-1.0, 0, 0]]))[:, 0]
    return float(e[0]), float(e[1])


def lpv_thin_wall_case(fracs=(0.1, 0.3, 0.5, 0.7, 0.9), device=None) -> Case:
    """Light leaking through a wall thinner than a cell, for wall positions across a cell: worst
    E_dark/E_lit (exact 0) of the plain volume (no geometry volume, leak guard or self-illumination
    damping) vs the default mitigations (geometry volume + leak guard + damping). Image:
    E_dark/E_lit per wall position (columns), plain (top) vs mitigated (bottom)."""
    plain, both, t_plain, t_both = [], [], 0.0, 0.0
    lpv_thin_wall(fracs[0], False, False, device, self_damping=0.0)  # compile both variants outside the timing
    lpv_thin_wall(fracs[0], True, True, device)
    for f in fracs:
        (d0, l0), ms0 = timed(lpv_thin_wall, f, False, False, device, self_damping=0.0)
        (d1, l1), ms1 = timed(lpv_thin_wall, f, True, True, device)
        plain.append(d0 / l0)
        both.append(d1 / l1)
        t_plain += ms0
        t_both += ms1
    img = np.array([plain, both])
    return Case("LPV thin wall (5 cm, 1 m cells)", "lpv", "max E_dark/E_lit over wall positions in a cell",
                "geometry volume + leak guard + damping", max(plain), max(both), t_plain / len(fracs),
                t_both / len(fracs),
                exact=0.0, images={"exact": np.zeros_like(img), "without": img[:1], "with": img[1:],
                                   "error": img},
                extra={"wall_position_in_cell": list(fracs), "ratio_plain": plain, "ratio_mitigated": both})


def lpv_self_illumination(y0: float, leak_guard: bool = True, device=None, surfels: bool = False,
                          **lpv) -> float:
    """A plane of exitance M = 50 W/m² at height ``y0`` (1 m cells, 8 iterations); returns the
    irradiance it receives from its own VPLs over M. Exact: 0 (a plane cannot see itself).
    ``surfels``: the plane's surfels go into the geometry volume too; ``lpv``: other LPVConfig fields."""
    v = _unit_lpv(16, 1.0, 8, device, leak_guard=leak_guard, **lpv)
    xs, zs = np.meshgrid(np.arange(0, 14, 0.25) + 0.125, np.arange(0, 14, 0.25) + 0.125)
    p = np.stack([xs.ravel(), np.full(xs.size, y0), zs.ravel()], 1)
    nrm = np.tile(UP, (xs.size, 1))
    v.inject(p, nrm, np.full((xs.size, 3), 0.0625 * 50.0))
    if surfels:
        v.inject_geometry(p, nrm, np.full(xs.size, 0.0625))
    v.propagate()
    return float(v.irradiance(np.array([[7.0, y0, 7.0]]), UP[None])[0, 0]) / 50.0


def lpv_self_illumination_case(heights=(3.01, 3.3, 3.6, 3.9), device=None) -> Case:
    """The LPV's known bias: a lit plane lights itself through its VPLs' wide L1 lobes. Worst E/M
    over plane heights within a cell, with its surfels in the geometry volume as in a frame, without
    and with the self-illumination damping (``LPVConfig.self_damping``, on by default)."""
    lpv_self_illumination(heights[0], True, device, surfels=True, self_damping=0.0)  # compile outside the timing
    lpv_self_illumination(heights[0], True, device, surfels=True)
    off, t_off = zip(*[timed(lpv_self_illumination, y, True, device, surfels=True, self_damping=0.0)
                       for y in heights], strict=True)
    on, t_on = zip(*[timed(lpv_self_illumination, y, True, device, surfels=True) for y in heights], strict=True)
    img = np.array([off, on])
    return Case("LPV self-illumination of a lit plane", "lpv", "max E_self/M over plane heights in a cell",
                "self-illumination damping (2.5 cells)", max(off), max(on), float(np.mean(t_off)),
                float(np.mean(t_on)), exact=0.0,
                images={"exact": np.zeros_like(img), "without": img[:1], "with": img[1:], "error": img},
                extra={"plane_height_m": list(heights), "ratio_undamped": list(off), "ratio_damped": list(on)})


NEAR_FIELD_HALF = 4.0
"""Half-width (m) of the floor square over which the near-field error is integrated."""


def near_field_exact(x, z, h, phi):
    """Irradiance (W/m²) on the floor at (x, z) from a downward-facing Lambertian point emitter of
    flux ``phi`` W at height ``h`` above the origin: E = Φ·h²/(π·(r² + h²)²)."""
    r2 = x * x + z * z + h * h
    return phi * h * h / (math.pi * r2 * r2)


def lpv_near_field(h: float, cell: float = 1.0, step: float = 0.05, device=None):
    """A bright small light (one VPL, Φ = 100 W, facing down) ``h`` m above a floor (surfels
    included), in a single cascade of ``cell``-metre cells (16 m across, 16 iterations: the whole
    floor square is in reach). Returns (relative L1 error ∫|E − E_exact| dA / ∫E_exact dA over
    the floor square of half-width NEAR_FIELD_HALF, the LPV's captured flux over the exact one,
    E map, exact map, ms of inject + propagate). The exact map averages 4×4 sub-samples per sample
    square (its peak, Φ/(π h²), is narrower than a sample at small h)."""
    res = int(round(16.0 / cell))
    v = _unit_lpv(res, cell, 16, device)
    c = np.array([7.0, 3.0, 7.0])
    phi = 100.0
    t0 = time.perf_counter()
    v.inject((c + [0.0, h, 0.0])[None], -UP[None], np.array([[phi] * 3]))
    gx, gz = np.meshgrid(np.arange(0, 14, 0.25) + 0.125, np.arange(0, 14, 0.25) + 0.125)
    v.inject_geometry(np.stack([gx.ravel(), np.full(gx.size, c[1]), gz.ravel()], 1), np.tile(UP, (gx.size, 1)),
                      np.full(gx.size, 0.0625))
    v.propagate()
    ms = (time.perf_counter() - t0) * 1e3
    s = np.arange(-NEAR_FIELD_HALF, NEAR_FIELD_HALF, step) + step / 2
    x, z = np.meshgrid(s, s)
    pts = np.stack([x.ravel() + c[0], np.full(x.size, c[1]), z.ravel() + c[2]], 1)
    e = v.irradiance(pts, np.tile(UP, (len(pts), 1)))[:, 0].reshape(x.shape).astype(np.float64)
    sub = (np.arange(4) + 0.5) / 4 * step - step / 2
    ex = np.mean([near_field_exact(x + a, z + b, h, phi) for a in sub for b in sub], axis=0)
    l1 = float(np.abs(e - ex).sum() / ex.sum())
    return l1, float(e.sum() / ex.sum()), e, ex, ms


def lpv_near_field_case(h: float = 0.25, step: float = 0.05, device=None) -> Case:
    """Near-field over-lighting: a small light ``h`` m above a floor; 1 m cells (the default
    cascade's scale) vs 0.5 m cells (the mitigation: a finer cascade, 8× the cells)."""
    lpv_near_field(h, 1.0, step, device)  # compile outside the timing
    lpv_near_field(h, 0.5, step, device)
    a = lpv_near_field(h, 1.0, step, device)
    b = lpv_near_field(h, 0.5, step, device)
    return Case(f"LPV near field (light {h} m above a floor)", "lpv",
                "relative L1 error of floor irradiance", "finer cells (0.5 m instead of 1 m)", a[0], b[0], a[4], b[4],
                exact=0.0, images={"exact": a[3], "without": a[2], "with": b[2], "error": np.abs(b[2] - b[3])},
                extra={"height_m": h, "flux_ratio_1m": a[1], "flux_ratio_half_m": b[1]})
