"""Single-scattering atmosphere: the sky map, the sun's colour, and a numerical reference (paper §5, §6).

Physics (clear sky, single scattering, no ground reflection, no ozone), as O'Neil's real-time model
(GPU Gems 2 ch. 16, the paper's refs [8][9]) after Nishita et al. 1993, with the standard Earth
parameters of Nishita 1993 / Bruneton & Neyret 2008 (all lengths in **km** inside the model):

    ground radius R = 6360, top of the atmosphere R_top = 6420 (60 km thick), observer at h = 0;
    Rayleigh: β_R = (5.8, 13.5, 33.1)·10⁻³ km⁻¹ (RGB ≈ 680/550/440 nm, ∝ λ⁻⁴), scale height 8 km,
              phase 3/(16π)·(1 + cos²θ);
    Mie:      β_M = 21·10⁻³ km⁻¹ scattering, β_M/0.9 extinction, scale height 1.2 km,
              Cornette–Shanks phase 3/(8π)·(1−g²)(1+cos²θ)/((2+g²)(1+g²−2g cosθ)^{3/2}), g = 0.76.

    L(v) = E₀ ∫₀^T Σ_k β_k ρ_k(h(s)) P_k(v·l) · exp(−τ(O→s) − τ(s→sun)) ds,
    τ = β_R^ext·∫ρ_R + β_M^ext·∫ρ_M,  ρ_k(h) = exp(−h/H_k),

v the view direction, l the unit direction towards the sun, T the distance to the top of the
atmosphere. A sample whose sun ray hits the ground is in the Earth's shadow (T_sun = 0). Radiance in
W·m⁻²·sr⁻¹ per RGB channel (the scene model's units, :mod:`serenity.scene.model`).

**Fast model** (the sky-map kernel): O'Neil's structure — a short march along the view ray, the
view optical depth accumulated along it, and the optical depth towards the sun from a closed-form
fit instead of a nested march. O'Neil fitted a polynomial "scale" function to his own scaled
atmosphere; we use the asymptotic Chapman function (Chapman 1931; the large-x expansion, e.g.
Schüler 2012, GPU Pro 3 "An approximation to the Chapman grazing-incidence function"), which
holds for any scale height:

    ∫₀^∞ ρ(h(s)) ds ≈ H·e^{−h/H}·Ch(x, μ),  x = r/H,
    Ch(x, μ ≥ 0) = √(πx/2)·erfcx(√(x/2)·μ),
    Ch(x, μ < 0) = 2·e^{x−x_t}·√(πx_t/2) − Ch(x, −μ),  x_t = x√(1−μ²) (through the tangent point),

erfcx(y) = e^{y²}erfc(y) by Abramowitz & Stegun 7.1.26 (y < 2) and an 8-term continued fraction
(y ≥ 2); the fit is within 0.1% of the exact integral for both scale heights at every altitude
and angle. The view march takes ``steps`` midpoint samples in x ∈ [0,1] with s = T·x² (denser
near the observer, where the density is, which matters towards the horizon).

**Files**: this module holds the Warp model (funcs, kernels, the sky-map bake) and the sky-map
cache; ``atmosphere_ref`` holds the physical constants, the float64 reference model, the sun and
the numpy twins of the sky-map mapping (no Warp), all re-exported here.

**Reference model** (:func:`sky_radiance_reference`, numpy float64, ``atmosphere_ref``): the same integral with
uniform midpoint steps (512 along the view ray, 256 along each sun ray by default) and the exact
geometry for both optical depths. The tests and ``benchmarks/bench_sky.py`` measure the fast model
against it.

**Sun** (paper §6): :func:`sun_irradiance` = E₀·exp(−τ(ground → sun)) on a surface facing the sun
(× the fraction of its disc above the geometric horizon: it fades over ±0.27° and is 0 once all
of it is below; no refraction), :func:`sun_radiance` = that over the
disc's solid angle, :func:`make_sun` a :class:`serenity.scene.model.Sun` with it.
E₀ = ``SOLAR_IRRADIANCE`` = 1100 W·m⁻² per channel (white): the solar constant is 1361 W·m⁻² over
the whole spectrum; in the renderer's radiometric RGB the sun at zenith then delivers
≈ (1021, 960, 821) W·m⁻² at the ground — the order of the scene model's default Sun irradiance
(1000, 960, 900), whose green channel it matches.

**Night**: a sun below the horizon still lights the upper atmosphere (twilight falls off
smoothly through the Earth's shadow); once it is deep below, the sky tends to
``NIGHT_SKY_RADIANCE`` ≈ 3·10⁻⁷ W·m⁻²·sr⁻¹, the moonless night sky (airglow + starlight,
≈ 2·10⁻⁴ cd/m², over 683 lm/W), added above the horizon in both models: dark, finite, positive.
Directions below the horizon (v.y < 0) get 0 (the observer stands on the ground).

**Sky map** (paper §5, Fig. 3): a ``size``×``size`` (256) paraboloid map of the upper hemisphere,
(size, size, 3) float32, array row i, column j. Texel centre (u, v) = ((j+½)/size, (i+½)/size),
(s, t) = (2u − 1, 2v − 1), and with r² = s² + t²:

    direction(s, t) = (2s, 1 − r², 2t) / (1 + r²)      (upper hemisphere; r = 1 is the horizon)
    (s, t) = (d.x, d.z) / (1 + d.y)                     (inverse)

so column j runs west → east (+x), row i north → south (+z), the zenith is the centre. Texels
outside the unit circle hold the horizon radiance of their radial direction (clamped (s, t)), so
bilinear filtering at the horizon never reads undefined texels. The solid angle of a texel is
4/(1 + r²)²·(2/size)². Lookups (:func:`sample_sky_map`, ``sky.glsl``'s ``sky_map_radiance``)
clamp d.y to ≥ 0 first (a direction below the horizon gets the horizon) and filter bilinearly
with clamp-to-edge, as GL_LINEAR + GL_CLAMP_TO_EDGE does.

**Equirect export** (:func:`equirect_sky`, for Mitsuba's ``envmap``): (H, W, 3) float32, row 0 the
zenith, pixel (i, j) centre u = (j+½)/W, v = (i+½)/H ↔ azimuth φ = 2πu from north (−z) towards
east (+x), zenith angle θ = πv: d = (sinθ sinφ, cosθ, −sinθ cosφ) — Mitsuba 3's default envmap
orientation (u = atan2(x, −z)/2π, v = acos(y)/π). Sky only, no sun disc (the reference renders the
sun as its own emitter); below the horizon 0.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from serenity.config import SKY_MAP_SIZE, SKY_VIEW_TABLE_MIN
from serenity.device import resolve_device
from serenity.kernels.atmosphere_ref import (
    ATMOSPHERE_TOP_KM,
    DEFAULT_STEPS,
    EARTH_RADIUS_KM,
    MIE_EXTINCTION,
    MIE_G,
    MIE_SCALE_HEIGHT_KM,
    MIE_SCATTERING,
    NIGHT_SKY_RADIANCE,
    OBSERVER_ALTITUDE_KM,
    RAYLEIGH_SCALE_HEIGHT_KM,
    RAYLEIGH_SCATTERING,
    SOLAR_IRRADIANCE,
    SUN_ANGULAR_DIAMETER_DEG,
    _unit,
    angle_between_deg,
    direction_to_paraboloid,
    equirect_directions,
    horizontal_irradiance,
    make_sun,
    paraboloid_direction,
    sample_sky_map_np,
    sampling_operator,
    scene_sun_irradiance,
    sky_map_directions,
    sky_map_solid_angles,
    sky_radiance_reference,
    sun_disc_fraction,
    sun_irradiance,
    sun_radiance,
    sun_transmittance,
)
from serenity.kernels.launch import launch

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants (the physical values are in ``atmosphere_ref``)


_R = wp.constant(EARTH_RADIUS_KM)
_R_TOP = wp.constant(ATMOSPHERE_TOP_KM)
_R_OBS = wp.constant(EARTH_RADIUS_KM + OBSERVER_ALTITUDE_KM)
_H_OBS = wp.constant(OBSERVER_ALTITUDE_KM)
_BETA_R = wp.constant(wp.vec3(*RAYLEIGH_SCATTERING))
_H_R = wp.constant(RAYLEIGH_SCALE_HEIGHT_KM)
_BETA_M = wp.constant(MIE_SCATTERING)
_BETA_M_EXT = wp.constant(MIE_EXTINCTION)
_H_M = wp.constant(MIE_SCALE_HEIGHT_KM)
_G = wp.constant(MIE_G)
_E0 = wp.constant(wp.vec3(*SOLAR_IRRADIANCE))
_NIGHT = wp.constant(wp.vec3(*NIGHT_SKY_RADIANCE))
_PI = wp.constant(math.pi)
_INV_SQRT_PI = wp.constant(1.0 / math.sqrt(math.pi))
_BLOCKED = wp.constant(1.0e9)  # optical depth (km) of a ray that hits the ground


# ---------------------------------------------------------------------------------------------
# funcs


@wp.func
def erfcx_approx(y: float) -> float:
    """exp(y²)·erfc(y) for y ≥ 0: A&S 7.1.26 below 2, a continued fraction above (rel. err < 2e-5)."""
    if y < 2.0:
        t = 1.0 / (1.0 + 0.3275911 * y)
        return t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))))
    f = y
    for k in range(8):
        f = y + (float(8 - k) * 0.5) / f
    return _INV_SQRT_PI / f


@wp.func
def chapman_up(x: float, mu: float) -> float:
    """Chapman function Ch(x, μ) for μ ≥ 0 (asymptotic form, x = r/H ≫ 1)."""
    return wp.sqrt(0.5 * _PI * x) * erfcx_approx(wp.sqrt(0.5 * x) * mu)


@wp.func
def eval_optical_depth(r: float, h: float, mu: float, scale_height: float) -> float:
    """∫ρ ds (km) from radius r (altitude h) along cos-zenith μ to infinity; _BLOCKED if it hits the ground."""
    if mu >= 0.0:
        return scale_height * wp.exp(-h / scale_height) * chapman_up(r / scale_height, mu)
    # through the tangent point: r_t = r·sqrt(1 − μ²), h_t = r_t − R computed without cancellation
    s2 = wp.max(1.0 - mu * mu, 0.0)
    rt = r * wp.sqrt(s2)
    ht = (h * (2.0 * _R + h) - r * r * mu * mu) / (rt + _R)
    if ht < 0.0:
        return _BLOCKED
    down = 2.0 * scale_height * wp.exp(-ht / scale_height) * wp.sqrt(0.5 * _PI * rt / scale_height)
    return down - scale_height * wp.exp(-h / scale_height) * chapman_up(r / scale_height, -mu)


@wp.func
def eval_extinction(tau_r: float, tau_m: float) -> wp.vec3:
    """exp(−β_R·τ_R − β_M^ext·τ_M) per channel."""
    m = _BETA_M_EXT * tau_m
    return wp.vec3(wp.exp(-_BETA_R[0] * tau_r - m), wp.exp(-_BETA_R[1] * tau_r - m), wp.exp(-_BETA_R[2] * tau_r - m))


@wp.func
def phase_rayleigh(c: float) -> float:
    return 3.0 / (16.0 * _PI) * (1.0 + c * c)


@wp.func
def phase_mie(c: float) -> float:
    g2 = _G * _G
    d = wp.max(1.0 + g2 - 2.0 * _G * c, 1.0e-6)
    return 3.0 / (8.0 * _PI) * (1.0 - g2) * (1.0 + c * c) / ((2.0 + g2) * d * wp.sqrt(d))


@wp.func
def eval_sky_inscatter(v: wp.vec3, sun: wp.vec3, steps: int):
    """The view march of :func:`eval_sky` without the phase functions and E₀: (β_R ⊙ S_R, β_M·S_M),
    per channel, for unit ``v`` with v.y ≥ 0. Radiance = E₀ ⊙ (P_R(v·l)·first + P_M(v·l)·second)."""
    mu = v[1]
    r0 = _R_OBS
    t_end = -r0 * mu + wp.sqrt((_R_TOP - r0) * (_R_TOP + r0) + r0 * r0 * mu * mu)
    inv_n = 1.0 / float(steps)
    tau_vr = float(0.0)
    tau_vm = float(0.0)
    sum_r = wp.vec3(0.0, 0.0, 0.0)
    sum_m = wp.vec3(0.0, 0.0, 0.0)
    for k in range(steps):
        x = (float(k) + 0.5) * inv_n
        s = t_end * x * x
        ds = 2.0 * t_end * x * inv_n
        # altitude without cancellation: r² − R² = h0(2R + h0) + s² + 2 r0 s μ
        p = wp.vec3(s * v[0], r0 + s * v[1], s * v[2])
        r = wp.length(p)
        h = (_H_OBS * (2.0 * _R + _H_OBS) + s * s + 2.0 * r0 * s * mu) / (r + _R)
        rho_r = wp.exp(-h / _H_R)
        rho_m = wp.exp(-h / _H_M)
        mu_s = wp.dot(p, sun) / r
        tsr = eval_optical_depth(r, h, mu_s, _H_R)
        tsm = eval_optical_depth(r, h, mu_s, _H_M)
        t = eval_extinction(tau_vr + 0.5 * rho_r * ds + tsr, tau_vm + 0.5 * rho_m * ds + tsm)
        sum_r += t * (rho_r * ds)
        sum_m += t * (rho_m * ds)
        tau_vr += rho_r * ds
        tau_vm += rho_m * ds
    return wp.cw_mul(_BETA_R, sum_r), sum_m * _BETA_M


@wp.func
def eval_phased(rayleigh: wp.vec3, mie: wp.vec3, c: float) -> wp.vec3:
    """Sky radiance from :func:`eval_sky_inscatter`'s two terms at cos(view, sun) = ``c``."""
    return wp.cw_mul(_E0, rayleigh * phase_rayleigh(c) + mie * phase_mie(c)) + _NIGHT


@wp.func
def eval_sky(v: wp.vec3, sun: wp.vec3, steps: int) -> wp.vec3:
    """Fast single-scattering sky radiance (no sun disc) seen from the ground along unit ``v``."""
    if v[1] < 0.0:
        return wp.vec3(0.0, 0.0, 0.0)
    rayleigh, mie = eval_sky_inscatter(v, sun, steps)
    return eval_phased(rayleigh, mie, wp.dot(v, sun))


@wp.func
def eval_paraboloid_direction(u: float, v: float) -> wp.vec3:
    """Unit direction of sky-map coordinates (u, v) ∈ [0,1]² (outside the disc: its horizon)."""
    s = 2.0 * u - 1.0
    t = 2.0 * v - 1.0
    r2 = s * s + t * t
    if r2 > 1.0:
        inv = 1.0 / wp.sqrt(r2)
        s = s * inv
        t = t * inv
        r2 = 1.0
    k = 1.0 / (1.0 + r2)
    return wp.vec3(2.0 * s * k, (1.0 - r2) * k, 2.0 * t * k)


@wp.func
def eval_texel_direction(i: int, size: int):
    """(row, column, unit direction) of the ``i``-th texel, row-major, of a ``size``² sky map."""
    row = i // size
    col = i - row * size
    return row, col, eval_paraboloid_direction((float(col) + 0.5) / float(size), (float(row) + 0.5) / float(size))


@wp.func
def eval_paraboloid_uv(d: wp.vec3) -> wp.vec2:
    """Sky-map (u, v) of a unit direction; d.y is clamped to ≥ 0 (below the horizon → the horizon)."""
    y = wp.max(d[1], 0.0)
    hx = d[0]
    hz = d[2]
    n = wp.sqrt(hx * hx + y * y + hz * hz)
    if n < 1.0e-12:
        hx = 1.0
        n = 1.0
    k = 1.0 / (n + y)
    return wp.vec2(0.5 * hx * k + 0.5, 0.5 * hz * k + 0.5)


@wp.func
def sample_sky_map(sky_map: wp.array2d(dtype=wp.vec3), d: wp.vec3) -> wp.vec3:
    """Bilinear, clamp-to-edge lookup of the paraboloid sky map (= GL_LINEAR + GL_CLAMP_TO_EDGE)."""
    size = sky_map.shape[0]
    uv = eval_paraboloid_uv(d)
    fx = uv[0] * float(size) - 0.5
    fy = uv[1] * float(size) - 0.5
    x0f = wp.floor(fx)
    y0f = wp.floor(fy)
    ax = fx - x0f
    ay = fy - y0f
    x0 = wp.clamp(int(x0f), 0, size - 1)
    x1 = wp.clamp(int(x0f) + 1, 0, size - 1)
    y0 = wp.clamp(int(y0f), 0, size - 1)
    y1 = wp.clamp(int(y0f) + 1, 0, size - 1)
    top = sky_map[y0, x0] * (1.0 - ax) + sky_map[y0, x1] * ax
    bot = sky_map[y1, x0] * (1.0 - ax) + sky_map[y1, x1] * ax
    return top * (1.0 - ay) + bot * ay


# ---------------------------------------------------------------------------------------------
# kernels


@wp.kernel
def bake_sky_map_texels(
    # inputs
    size: int,
    sun: wp.vec3,
    steps: int,
    # outputs
    sky_map: wp.array2d(dtype=wp.vec3),
    offset: int,
):
    row, col, d = eval_texel_direction(wp.tid() + offset, size)
    sky_map[row, col] = eval_sky(d, sun, steps)


@wp.kernel
def bake_sky_view_table(
    # inputs
    sun: wp.vec3,
    towards: wp.vec3,
    side: wp.vec3,
    steps: int,
    # outputs
    rayleigh: wp.array2d(dtype=wp.vec3),
    mie: wp.array2d(dtype=wp.vec3),
    offset: int,
):
    """One node of the sky-view table: row i ↔ cos-zenith μ = (i/(rows−1))², column j ↔ azimuth
    φ = π·j/(cols−1) from the sun's (``towards``: the horizontal unit towards the sun, ``side``
    perpendicular to it)."""
    i = wp.tid() + offset
    cols = rayleigh.shape[1]
    row = i // cols
    col = i - row * cols
    u = float(row) / float(rayleigh.shape[0] - 1)
    mu = u * u
    phi = _PI * float(col) / float(cols - 1)
    sn = wp.sqrt(wp.max(1.0 - mu * mu, 0.0))
    v = towards * (sn * wp.cos(phi)) + side * (sn * wp.sin(phi)) + wp.vec3(0.0, mu, 0.0)
    r, m = eval_sky_inscatter(v, sun, steps)
    rayleigh[row, col] = r
    mie[row, col] = m


@wp.func
def table_bilinear(table: wp.array2d(dtype=wp.vec3), fy: float, fx: float) -> wp.vec3:
    """Bilinear lookup at node coordinates (fy, fx), clamped to the table."""
    y0 = wp.clamp(int(wp.floor(fy)), 0, table.shape[0] - 2)
    x0 = wp.clamp(int(wp.floor(fx)), 0, table.shape[1] - 2)
    ay = wp.clamp(fy - float(y0), 0.0, 1.0)
    ax = wp.clamp(fx - float(x0), 0.0, 1.0)
    top = table[y0, x0] * (1.0 - ax) + table[y0, x0 + 1] * ax
    bot = table[y0 + 1, x0] * (1.0 - ax) + table[y0 + 1, x0 + 1] * ax
    return top * (1.0 - ay) + bot * ay


@wp.kernel
def bake_sky_map_from_table(
    # inputs
    size: int,
    sun: wp.vec3,
    towards: wp.vec3,
    side: wp.vec3,
    rayleigh: wp.array2d(dtype=wp.vec3),
    mie: wp.array2d(dtype=wp.vec3),
    # outputs
    sky_map: wp.array2d(dtype=wp.vec3),
    offset: int,
):
    row, col, d = eval_texel_direction(wp.tid() + offset, size)
    fy = wp.sqrt(wp.max(d[1], 0.0)) * float(rayleigh.shape[0] - 1)
    phi = wp.atan2(wp.abs(wp.dot(d, side)), wp.dot(d, towards))  # 0..π: the sky is symmetric about the sun's plane
    fx = phi / _PI * float(rayleigh.shape[1] - 1)
    sky_map[row, col] = eval_phased(table_bilinear(rayleigh, fy, fx), table_bilinear(mie, fy, fx), wp.dot(d, sun))


@wp.kernel
def eval_sky_directions(
    # inputs
    directions: wp.array(dtype=wp.vec3),
    sun: wp.vec3,
    steps: int,
    # outputs
    radiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    i = wp.tid() + offset
    radiance[i] = eval_sky(wp.normalize(directions[i]), sun, steps)


@wp.kernel
def lookup_sky_map(
    # inputs
    sky_map: wp.array2d(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    # outputs
    radiance: wp.array(dtype=wp.vec3),
    offset: int,
):
    i = wp.tid() + offset
    radiance[i] = sample_sky_map(sky_map, wp.normalize(directions[i]))


# ---------------------------------------------------------------------------------------------
# host


def sky_radiance(directions, sun_direction, device: str | None = None, steps: int = DEFAULT_STEPS) -> np.ndarray:
    """(N,3) float32 sky radiance (W·m⁻²·sr⁻¹, no sun disc) along (N,3) directions, fast model."""
    device = resolve_device(device)
    d = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
    sun = _unit(sun_direction)
    dirs = wp.array(d, dtype=wp.vec3, device=device)
    out = wp.zeros(len(d), dtype=wp.vec3, device=device)
    launch(eval_sky_directions, len(d), [dirs, wp.vec3(*sun), int(steps), out], device)
    return out.numpy()


SKY_VIEW_TABLE_MIN_ELEVATION_DEG = 1.0
"""Below this sun elevation (degrees) the sky map is marched per texel, not through the table."""


def _sun_frame(sun: np.ndarray) -> tuple[wp.vec3, wp.vec3]:
    """(towards, side): the horizontal unit towards the sun's azimuth (any, for a sun at the zenith)
    and the horizontal unit perpendicular to it."""
    h = np.array([sun[0], 0.0, sun[2]])
    n = float(np.linalg.norm(h))
    towards = h / n if n > 1e-9 else np.array([1.0, 0.0, 0.0])
    side = np.array([-towards[2], 0.0, towards[0]])
    return wp.vec3(*towards.astype(np.float32)), wp.vec3(*side.astype(np.float32))


def sky_view_table_size(map_size: int, table: int | None = None) -> int:
    """Nodes per side of the sky-view table for a ``map_size`` sky map: ``table`` if given, else a
    quarter of the map's rows, at least ``SKY_VIEW_TABLE_MIN`` (at 2° of sun elevation a 32² table
    under a 256² map was 3.1 % off the reference at its worst texel, 64² 0.92 %, the same as
    marching every texel)."""
    return int(table) if table is not None else max(SKY_VIEW_TABLE_MIN, int(map_size) // 4)


def bake_sky_map_wp(sun_direction, size: int = SKY_MAP_SIZE, device: str | None = None,
                    steps: int = DEFAULT_STEPS, table: int | None = None):
    """The sky map as a Warp ``array2d(vec3)`` (size, size) on ``device`` (no host copy).

    ``table`` (default :func:`sky_view_table_size`) > 0: march ``table``×``table`` view directions
    (the sky-view table: cos-zenith rows dense towards the horizon × azimuth from the sun, both
    halves of the sky being mirror images) and interpolate every texel from it, with the phase
    functions applied per texel — the march without them varies slowly, so the Mie glow around the
    sun stays sharp (after Hillaire 2020's
    sky-view LUT and Bruneton & Neyret 2008's separated phase functions). 0: march every texel.
    With the sun lower than ``SKY_VIEW_TABLE_MIN_ELEVATION_DEG`` every texel is marched: the Earth's
    shadow then crosses the sky as an edge a 32-row table cannot follow (96² map: at 0° the table's
    worst texel is 14 % off, at −4° the dim ones by multiples, against 3 % at 1°, < 1 % from 5° up).
    ``tests/kernels/test_atmosphere.py`` bounds the table's error against the per-texel march."""
    device = resolve_device(device)
    sun = _unit(sun_direction)
    out = wp.zeros((size, size), dtype=wp.vec3, device=device)
    table = sky_view_table_size(size, table)
    if table <= 0 or sun[1] < math.sin(math.radians(SKY_VIEW_TABLE_MIN_ELEVATION_DEG)):
        launch(bake_sky_map_texels, size * size, [int(size), wp.vec3(*sun), int(steps), out], device)
        return out
    if table < 2:
        raise ValueError(f"the sky-view table needs at least 2×2 nodes, got {table}")
    towards, side = _sun_frame(sun)
    rayleigh = wp.empty((table, table), dtype=wp.vec3, device=device)
    mie = wp.empty((table, table), dtype=wp.vec3, device=device)
    launch(bake_sky_view_table, table * table, [wp.vec3(*sun), towards, side, int(steps), rayleigh, mie], device)
    launch(bake_sky_map_from_table, size * size, [int(size), wp.vec3(*sun), towards, side, rayleigh, mie, out],
           device)
    return out


def bake_sky_map(sun_direction, size: int = SKY_MAP_SIZE, device: str | None = None,
                 steps: int = DEFAULT_STEPS, table: int | None = None) -> np.ndarray:
    """(size, size, 3) float32 paraboloid sky map (see the module docstring for the mapping)."""
    return bake_sky_map_wp(sun_direction, size, device, steps, table).numpy().reshape(size, size, 3)


def sample_sky_map_wp(sky_map: np.ndarray, directions, device: str | None = None) -> np.ndarray:
    """(N,3) bilinear lookups of a sky map by the Warp function the sky volume uses."""
    device = resolve_device(device)
    m = np.ascontiguousarray(sky_map, np.float32)
    d = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
    out = wp.zeros(len(d), dtype=wp.vec3, device=device)
    launch(lookup_sky_map, len(d), [wp.array(m, dtype=wp.vec3, device=device),
                                     wp.array(d, dtype=wp.vec3, device=device), out], device)
    return out.numpy()


def equirect_sky(sun_direction, width: int, height: int, device: str | None = None,
                 steps: int = DEFAULT_STEPS) -> np.ndarray:
    """(H, W, 3) float32 equirect sky (Mitsuba envmap orientation, no sun disc, 0 below the horizon)."""
    d = equirect_directions(width, height).reshape(-1, 3)
    return sky_radiance(d, sun_direction, device=device, steps=steps).reshape(height, width, 3)


# ---------------------------------------------------------------------------------------------
# cache


class SkyMapCache:
    """Owns the baked sky map; rebakes only when the sun moved more than ``rebuild_angle_deg``.

    ``get(sun_direction)`` returns the current Warp map and whether it was rebaked; ``version``
    counts bakes (consumers such as the sky volume compare it to know their data is stale).
    ``sky_map`` is the (size, size, 3) numpy copy (for GL upload), ``sun_direction`` the direction
    it was baked for.
    """

    def __init__(self, size: int = SKY_MAP_SIZE, rebuild_angle_deg: float = 0.5, device: str | None = None,
                 steps: int = DEFAULT_STEPS, table: int | None = None):
        if size < 2:
            raise ValueError(f"sky map size must be >= 2, got {size}")
        if not rebuild_angle_deg >= 0.0:
            raise ValueError(f"rebuild_angle_deg must be >= 0, got {rebuild_angle_deg}")
        self.size = int(size)
        self.rebuild_angle_deg = float(rebuild_angle_deg)
        self.device = resolve_device(device)
        self.steps = int(steps)
        self.table = table
        self.version = 0
        self.sun_direction: np.ndarray | None = None
        self.sky_map_wp = None
        self._host: np.ndarray | None = None

    def needs_rebuild(self, sun_direction) -> bool:
        if self.sun_direction is None:
            return True
        return angle_between_deg(self.sun_direction, sun_direction) > self.rebuild_angle_deg

    def get(self, sun_direction, force: bool = False):
        """(Warp sky map, rebaked?) for ``sun_direction``."""
        if force or self.needs_rebuild(sun_direction):
            self.sun_direction = _unit(sun_direction)
            self.sky_map_wp = bake_sky_map_wp(self.sun_direction, self.size, self.device, self.steps, self.table)
            self._host = None
            self.version += 1
            return self.sky_map_wp, True
        return self.sky_map_wp, False

    @property
    def sky_map(self) -> np.ndarray:
        if self.sky_map_wp is None:
            raise RuntimeError("SkyMapCache.get(sun_direction) has not been called yet")
        if self._host is None:
            self._host = self.sky_map_wp.numpy().reshape(self.size, self.size, 3)
        return self._host


__all__ = [
    # numpy model and sun (``atmosphere_ref``), re-exported: one import for the whole atmosphere
    "ATMOSPHERE_TOP_KM", "DEFAULT_STEPS", "EARTH_RADIUS_KM", "MIE_EXTINCTION", "MIE_G", "MIE_SCALE_HEIGHT_KM",
    "MIE_SCATTERING", "NIGHT_SKY_RADIANCE", "OBSERVER_ALTITUDE_KM", "RAYLEIGH_SCALE_HEIGHT_KM",
    "RAYLEIGH_SCATTERING", "SOLAR_IRRADIANCE", "SUN_ANGULAR_DIAMETER_DEG", "SKY_MAP_SIZE", "angle_between_deg",
    "direction_to_paraboloid", "equirect_directions", "horizontal_irradiance", "make_sun", "paraboloid_direction",
    "sample_sky_map_np", "sampling_operator", "scene_sun_irradiance", "sky_map_directions", "sky_map_solid_angles",
    "sky_radiance_reference", "sun_disc_fraction", "sun_irradiance", "sun_radiance", "sun_transmittance",
    # the Warp model
    "SKY_VIEW_TABLE_MIN_ELEVATION_DEG", "SkyMapCache", "bake_sky_map", "bake_sky_map_wp",
    "equirect_sky", "sample_sky_map", "sample_sky_map_wp",
    "sky_radiance", "sky_view_table_size",
]
