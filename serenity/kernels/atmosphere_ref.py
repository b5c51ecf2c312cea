"""The atmosphere in numpy (float64, no Warp): the physical constants, the numerical reference model,
the sun's transmitted irradiance, and the numpy twins of the sky-map mapping. The physics, the fast
Warp model and the sky-map layout are described in ``serenity/kernels/atmosphere.py``'s docstring.

**Reference model** (:func:`sky_radiance_reference`): the single-scattering integral with uniform
midpoint steps (512 along the view ray, 256 along each sun ray by default) and the exact geometry
for both optical depths. The tests and ``benchmarks/bench_sky.py`` measure the fast model against
it. **Sun** (paper §6): :func:`sun_irradiance` = E₀·exp(−τ(ground → sun)) × the fraction of its disc
above the geometric horizon (:func:`sun_disc_fraction`: it fades over ±0.27° instead of popping),
:func:`sun_radiance`,
:func:`make_sun`, :func:`scene_sun_irradiance` (what the renderer and the Mitsuba reference light with).
"""

from __future__ import annotations

import functools
import math

import numpy as np

from serenity.config import SKY_MAP_SIZE
from serenity.scene.model import Sun

# ---------------------------------------------------------------------------------------------
# constants

EARTH_RADIUS_KM = 6360.0
ATMOSPHERE_TOP_KM = 6420.0
OBSERVER_ALTITUDE_KM = 0.0
RAYLEIGH_SCATTERING = (5.8e-3, 13.5e-3, 33.1e-3)  # km⁻¹ per RGB channel
RAYLEIGH_SCALE_HEIGHT_KM = 8.0
MIE_SCATTERING = 21.0e-3  # km⁻¹
MIE_EXTINCTION = MIE_SCATTERING / 0.9
MIE_SCALE_HEIGHT_KM = 1.2
MIE_G = 0.76
#: top-of-atmosphere solar irradiance per channel, W·m⁻² (see the module docstring)
SOLAR_IRRADIANCE = (1100.0, 1100.0, 1100.0)
#: moonless night sky, W·m⁻²·sr⁻¹ per channel (added above the horizon)
NIGHT_SKY_RADIANCE = (2.5e-7, 3.0e-7, 4.0e-7)
#: default view-march steps of the fast model (see benchmarks/bench_sky.py for error vs steps)
DEFAULT_STEPS = 24
SUN_ANGULAR_DIAMETER_DEG = 0.53


def _unit(v) -> np.ndarray:
    a = np.asarray(v, np.float64).reshape(3)
    n = float(np.linalg.norm(a))
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"sun direction must be a finite non-zero 3-vector, got {v!r}")
    return a / n


# -- numpy twins of the mapping


def paraboloid_direction(u, v) -> np.ndarray:
    """(..., 3) unit directions of sky-map coordinates u, v (arrays, [0,1]); twin of the Warp func."""
    s = 2.0 * np.asarray(u, np.float64) - 1.0
    t = 2.0 * np.asarray(v, np.float64) - 1.0
    r2 = s * s + t * t
    inv = np.where(r2 > 1.0, 1.0 / np.sqrt(np.maximum(r2, 1e-300)), 1.0)
    s, t = s * inv, t * inv
    r2 = np.minimum(r2, 1.0)
    k = 1.0 / (1.0 + r2)
    return np.stack([2.0 * s * k, (1.0 - r2) * k, 2.0 * t * k], axis=-1)


def direction_to_paraboloid(d) -> np.ndarray:
    """(..., 2) sky-map (u, v) of directions (d.y clamped to ≥ 0); twin of the Warp func."""
    d = np.asarray(d, np.float64)
    x, y, z = d[..., 0], np.maximum(d[..., 1], 0.0), d[..., 2]
    n = np.sqrt(x * x + y * y + z * z)
    bad = n < 1e-12
    x = np.where(bad, 1.0, x)
    n = np.where(bad, 1.0, n)
    k = 1.0 / (n + y)
    return np.stack([0.5 * x * k + 0.5, 0.5 * z * k + 0.5], axis=-1)


def sky_map_directions(size: int = SKY_MAP_SIZE) -> np.ndarray:
    """(size, size, 3) float64 direction of every sky-map texel centre (outside the disc: horizon)."""
    c = (np.arange(size) + 0.5) / size
    return paraboloid_direction(c[None, :], c[:, None])


def sky_map_solid_angles(size: int = SKY_MAP_SIZE) -> np.ndarray:
    """(size, size) float64 solid angle (sr) of each texel inside the unit disc, 0 outside; sums to ≈ 2π."""
    c = 2.0 * (np.arange(size) + 0.5) / size - 1.0
    r2 = c[None, :] ** 2 + c[:, None] ** 2
    return np.where(r2 <= 1.0, 4.0 / (1.0 + r2) ** 2 * (2.0 / size) ** 2, 0.0)


def bilinear_texels(size: int, directions):
    """The bilinear clamp-to-edge taps of :func:`sample_sky_map` in a size² map: columns xa, xb and
    rows ya, yb (N,) int64, and the fractions ax, ay (N, 1) float64."""
    uv = direction_to_paraboloid(np.asarray(directions, np.float64).reshape(-1, 3))
    fx, fy = uv[:, 0] * size - 0.5, uv[:, 1] * size - 0.5
    x0, y0 = np.floor(fx), np.floor(fy)
    ax, ay = (fx - x0)[:, None], (fy - y0)[:, None]
    x0, y0 = x0.astype(np.int64), y0.astype(np.int64)
    xa, xb = np.clip(x0, 0, size - 1), np.clip(x0 + 1, 0, size - 1)
    ya, yb = np.clip(y0, 0, size - 1), np.clip(y0 + 1, 0, size - 1)
    return xa, xb, ya, yb, ax, ay


def sample_sky_map_np(sky_map: np.ndarray, directions) -> np.ndarray:
    """(N,3) float64 bilinear clamp-to-edge lookup (twin of :func:`sample_sky_map`)."""
    m = np.asarray(sky_map, np.float64)
    xa, xb, ya, yb, ax, ay = bilinear_texels(m.shape[0], directions)
    top = m[ya, xa] * (1 - ax) + m[ya, xb] * ax
    bot = m[yb, xa] * (1 - ax) + m[yb, xb] * ax
    return top * (1 - ay) + bot * ay


def sampling_operator(size: int, directions, basis: np.ndarray) -> np.ndarray:
    """(K, size²) float64 M with M @ map.reshape(-1, C) = basisᵀ @ sample_sky_map_np(map, directions)
    for every size² map (the lookup at fixed directions is linear in the map): ``basis`` (N, K) the
    functions the samples are projected on (e.g. SH at the directions). Build it once, apply it for
    each map: K·size² multiply-adds instead of N bilinear lookups and an N×K product."""
    xa, xb, ya, yb, ax, ay = bilinear_texels(size, directions)
    b = np.asarray(basis, np.float64)
    out = np.zeros((size * size, b.shape[1]))
    for row, col, w in ((ya, xa, (1 - ax) * (1 - ay)), (ya, xb, ax * (1 - ay)), (yb, xa, (1 - ax) * ay),
                        (yb, xb, ax * ay)):
        np.add.at(out, row * size + col, b * w)
    return out.T


@functools.lru_cache(maxsize=8)
def _horizontal_weights(size: int) -> np.ndarray:
    """(size², ) float64 solid angle × cosθ of every texel (read-only; cached per size)."""
    w = (sky_map_solid_angles(size) * np.maximum(sky_map_directions(size)[..., 1], 0.0)).reshape(-1)
    w.setflags(write=False)
    return w


def horizontal_irradiance(sky_map: np.ndarray) -> np.ndarray:
    """(3,) W·m⁻² the sky map delivers to an upward-facing horizontal surface (∫ L cosθ dω)."""
    size = sky_map.shape[0]
    return _horizontal_weights(size) @ np.asarray(sky_map, np.float64).reshape(-1, 3)



# -- reference model and the sun (numpy, float64)

_BETA_R_NP = np.array(RAYLEIGH_SCATTERING)
_E0_NP = np.array(SOLAR_IRRADIANCE)
_NIGHT_NP = np.array(NIGHT_SKY_RADIANCE)


def _altitude(p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(r, h) of points p (…,3) in km relative to the Earth's centre at (0, −R, 0) + observer (0, h0, 0)."""
    r0 = EARTH_RADIUS_KM + OBSERVER_ALTITUDE_KM
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    r2_minus_R2 = (OBSERVER_ALTITUDE_KM * (2 * EARTH_RADIUS_KM + OBSERVER_ALTITUDE_KM)
                   + x * x + z * z + y * y + 2.0 * r0 * y)
    r = np.sqrt(EARTH_RADIUS_KM**2 + r2_minus_R2)
    return r, r2_minus_R2 / (r + EARTH_RADIUS_KM)


def _distance_to_top(r: np.ndarray, mu: np.ndarray) -> np.ndarray:
    return -r * mu + np.sqrt((ATMOSPHERE_TOP_KM - r) * (ATMOSPHERE_TOP_KM + r) + r * r * mu * mu)


def _phase_rayleigh_np(c):
    return 3.0 / (16.0 * math.pi) * (1.0 + c * c)


def _phase_mie_np(c):
    g = MIE_G
    d = np.maximum(1.0 + g * g - 2.0 * g * c, 1e-6)
    return 3.0 / (8.0 * math.pi) * (1.0 - g * g) * (1.0 + c * c) / ((2.0 + g * g) * d ** 1.5)


def _sun_optical_depths_exact(p: np.ndarray, sun: np.ndarray, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(τ_R, τ_M, blocked) along the sun ray from points p (…,3), uniform midpoint steps."""
    r, h = _altitude(p)
    centre_up = p + np.array([0.0, EARTH_RADIUS_KM + OBSERVER_ALTITUDE_KM, 0.0])
    mu = (centre_up @ sun) / r
    blocked = (mu < 0.0) & (r * r * (1.0 - mu * mu) < EARTH_RADIUS_KM**2)
    length = _distance_to_top(r, mu)
    x = (np.arange(steps) + 0.5) / steps
    q = p[..., None, :] + (length[..., None, None] * x[:, None]) * sun
    _, hq = _altitude(q)
    ds = length / steps
    tau_r = np.exp(-hq / RAYLEIGH_SCALE_HEIGHT_KM).sum(-1) * ds
    tau_m = np.exp(-hq / MIE_SCALE_HEIGHT_KM).sum(-1) * ds
    return tau_r, tau_m, blocked


def sky_radiance_reference(directions, sun_direction, device: str | None = None, view_steps: int = 512,
                           sun_steps: int = 256, chunk: int = 16) -> np.ndarray:
    """(N,3) float32 reference sky radiance: the same physics as :func:`sky_radiance`, integrated
    numerically (uniform midpoint steps, exact optical depths). numpy float64; ``device`` is
    accepted for signature parity and ignored. Cost ∝ N·view_steps·sun_steps."""
    del device
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    sun = _unit(sun_direction)
    out = np.zeros((len(d), 3))
    x = (np.arange(view_steps) + 0.5) / view_steps
    r0 = EARTH_RADIUS_KM + OBSERVER_ALTITUDE_KM
    for a in range(0, len(d), chunk):
        v = d[a:a + chunk]
        up = v[:, 1] >= 0.0
        t_end = _distance_to_top(np.full(len(v), r0), v[:, 1])
        ds = t_end / view_steps
        p = (t_end[:, None, None] * x[None, :, None]) * v[:, None, :]
        _, h = _altitude(p)
        rho_r, rho_m = np.exp(-h / RAYLEIGH_SCALE_HEIGHT_KM), np.exp(-h / MIE_SCALE_HEIGHT_KM)
        tv_r = (np.cumsum(rho_r, axis=1) - 0.5 * rho_r) * ds[:, None]
        tv_m = (np.cumsum(rho_m, axis=1) - 0.5 * rho_m) * ds[:, None]
        ts_r, ts_m, blocked = _sun_optical_depths_exact(p, sun, sun_steps)
        tau = (_BETA_R_NP * (tv_r + ts_r)[..., None]) + (MIE_EXTINCTION * (tv_m + ts_m))[..., None]
        t = np.where(blocked[..., None], 0.0, np.exp(-tau))
        s_r = (t * rho_r[..., None]).sum(1) * ds[:, None]
        s_m = (t * rho_m[..., None]).sum(1) * ds[:, None]
        c = v @ sun
        rad = _BETA_R_NP * s_r * _phase_rayleigh_np(c)[:, None] + MIE_SCATTERING * s_m * _phase_mie_np(c)[:, None]
        out[a:a + chunk] = np.where(up[:, None], _E0_NP * rad + _NIGHT_NP, 0.0)
    return out.astype(np.float32)


def sun_transmittance(sun_direction, steps: int = 4096) -> np.ndarray:
    """(3,) transmittance from the ground to the top of the atmosphere towards the sun (exact,
    numerically integrated in float64; 0 below the geometric horizon)."""
    sun = _unit(sun_direction)
    if sun[1] < 0.0:
        return np.zeros(3)
    tr, tm, _ = _sun_optical_depths_exact(np.zeros((1, 3)), sun, steps)
    return np.exp(-(_BETA_R_NP * tr[0] + MIE_EXTINCTION * tm[0]))


def sun_disc_fraction(sun_direction, angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG) -> float:
    """Fraction of the sun's disc above the geometric horizon: 1 when its centre is more than the
    disc's angular radius r above it, 0 when more than r below, the circular segment's share of
    the disc in between (x = elevation/r: 1 − (acos x − x·√(1 − x²))/π; ½ at sunset)."""
    sun = _unit(sun_direction)
    r = math.radians(angular_diameter_deg) / 2.0
    x = min(max(math.asin(min(max(sun[1], -1.0), 1.0)) / r, -1.0), 1.0)
    return 1.0 - (math.acos(x) - x * math.sqrt(1.0 - x * x)) / math.pi


def sun_irradiance(sun_direction, angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG) -> np.ndarray:
    """(3,) float64 W·m⁻² of the sun on a surface facing it at the ground: E₀ × transmittance ×
    :func:`sun_disc_fraction`. While the disc sets (centre within its radius of the horizon) the
    transmittance is the horizon's, so the sun fades over ±0.27° instead of popping from the
    horizon's ~17 W/m² (red) to 0 as its centre crosses it."""
    sun = _unit(sun_direction)
    f = sun_disc_fraction(sun, angular_diameter_deg)
    if f <= 0.0:
        return np.zeros(3)
    if sun[1] < 0.0:  # the visible sliver: the horizon's transmittance
        h = math.hypot(sun[0], sun[2])
        sun = np.array([sun[0] / h, 0.0, sun[2] / h]) if h > 0 else np.array([1.0, 0.0, 0.0])
    return _E0_NP * sun_transmittance(sun) * f


def sun_radiance(sun_direction, angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG) -> np.ndarray:
    """(3,) float64 W·m⁻²·sr⁻¹ of the (uniform) sun disc: :func:`sun_irradiance` / disc solid angle."""
    omega = 2.0 * math.pi * (1.0 - math.cos(math.radians(angular_diameter_deg) / 2.0))
    return sun_irradiance(sun_direction, angular_diameter_deg) / omega


def make_sun(sun_direction, angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG):
    """A :class:`serenity.scene.model.Sun` towards ``sun_direction`` with the atmosphere's irradiance."""
    return Sun(direction=_unit(sun_direction), irradiance=sun_irradiance(sun_direction),
               angular_diameter_deg=angular_diameter_deg)


def equirect_directions(width: int, height: int) -> np.ndarray:
    """(H, W, 3) float64 pixel-centre directions of the Mitsuba envmap layout (``atmosphere`` docstring)."""
    phi = 2.0 * math.pi * (np.arange(width) + 0.5) / width
    theta = math.pi * (np.arange(height) + 0.5) / height
    st = np.sin(theta)[:, None]
    return np.stack([st * np.sin(phi)[None, :], np.broadcast_to(np.cos(theta)[:, None], (height, width)),
                     -st * np.cos(phi)[None, :]], axis=-1)



def angle_between_deg(a, b) -> float:
    a, b = _unit(a), _unit(b)
    return math.degrees(math.atan2(float(np.linalg.norm(np.cross(a, b))), float(np.dot(a, b))))


def scene_sun_irradiance(scene, direction=None) -> np.ndarray:
    """(3,) W·m⁻² the sun delivers in ``scene``: the atmosphere's transmitted irradiance
    (:func:`sun_irradiance`, the sun's colour by time of day, paper §6) when ``scene.sky.model`` is
    "atmosphere" (fading as the disc sets, zero once all of it is below the horizon), else the
    scene's own ``Sun.irradiance``, zero with the sun's centre below the horizon. The renderer and
    the Mitsuba reference both take the sun from here, so they agree. ``direction``: the sun's
    direction instead of ``scene.sun.direction``."""
    sun = scene.sun
    d = np.asarray(sun.direction if direction is None else direction, np.float64)
    if getattr(scene.sky, "model", "constant") == "atmosphere":
        return sun_irradiance(d, sun.angular_diameter_deg)
    if not d[1] > 0.0:
        return np.zeros(3)
    return np.asarray(sun.irradiance, np.float64)
