"""Real L2 spherical harmonics (9 coefficients): basis, projection, irradiance, windowing.

Basis (Ramamoorthi & Hanrahan 2001, "An Efficient Representation for Irradiance Environment
Maps", eq. 3; orthonormal real SH, index k = l² + l + m, in the world's x, y, z — the basis is
complete at each band, so which axis is "polar" is immaterial; we keep R&H's formulas verbatim):

    k  (l, m)   Y_k(x, y, z)
    0  (0, 0)   0.282095
    1  (1,-1)   0.488603 y          2 (1, 0)  0.488603 z          3 (1, 1)  0.488603 x
    4  (2,-2)   1.092548 xy         5 (2,-1)  1.092548 yz         6 (2, 0)  0.315392 (3z² − 1)
    7  (2, 1)   1.092548 xz         8 (2, 2)  0.546274 (x² − y²)

Projection of radiance L(ω) (W·m⁻²·sr⁻¹): L_k = ∫ L(ω) Y_k(ω) dω, estimated from N directions
with pdf p as (1/N) Σ L(ωᵢ) Y_k(ωᵢ)/p(ωᵢ) (uniform sphere: p = 1/4π). Coefficients are (9, 3):
one column per RGB channel.

Irradiance (R&H 2001 eq. 7–8: the clamped-cosine kernel is zonal, so convolution is a per-band
scale): E(n) = Σ_k Â_l·w_l·L_k·Y_k(n), Â₀ = π, Â₁ = 2π/3, Â₂ = π/4 (W·m⁻²). The L2 truncation
of the cosine lobe is accurate to ~1% on average for smooth lighting (R&H §3), worse for peaked
light. We call E_k = Â_l·w_l·L_k the **irradiance coefficients** (what the sky volume stores).

Windowing against ringing (Sloan 2008, "Stupid Spherical Harmonics (SH) Tricks", GDC, §
"Windowing"): truncating a peaked function (the sun disc, a hard occlusion edge) rings, and the L2
irradiance of a point light dips to −4% of its peak opposite it. Scaling band l by a window w_l
trades sharpness for less ringing:

    "none":    w_l = 1
    "hanning": w_l = (1 + cos(π l / W)) / 2   for l < W, else 0
    "lanczos": w_l = sin(π l / W) / (π l / W) (w₀ = 1)

    "nonneg":  w = (1, √3/2, 4/5)

W is the window size (Sloan uses W > L). Hanning and Lanczos only *reduce* the dip: for a point
light the best they reach is −1.9% of the peak (Hanning W ≈ 4.75, Lanczos W ≈ 4), not enough under
a low sun whose disc outshines the sky. "nonneg" is derived here (not in Sloan): the irradiance of
a point light at angle γ under band weights w is the zonal kernel
f(c) = ¼ + (w₁/2)·c + (5/32)·w₂·(3c² − 1), c = cos γ; f ≥ 0 on [−1, 1] iff w₁ ≤ √3/2 with
w₂ = √(64/75)·w₁ = 4/5 at the limit (a double root at c = −1/√3). Since any non-negative radiance
is a positive sum of point lights, these weights give **non-negative irradiance for every
non-negative radiance** with the least damping of band 1 — at the cost of blur (the tests measure
it). A clamp at evaluation time (max(E, 0)) is the consumer's choice.

Warp funcs for kernels (``eval_sh9``, ``eval_sh9_dot``) and numpy twins (``sh_basis``,
``project_radiance``, ``irradiance_coefficients``, ``eval_irradiance``) for tests and host code.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from serenity.config import SH_WINDOWS

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants

SH_C0 = 0.282094791773878  # 1/(2√π)
SH_C1 = 0.488602511902920  # √3/(2√π)
SH_C2 = 1.092548430592079  # √15/(2√π)
SH_C20 = 0.315391565252520  # √5/(4√π)
SH_C22 = 0.546274215296040  # √15/(4√π)
#: clamped-cosine convolution per band (R&H 2001 eq. 8)
A_HAT = (math.pi, 2.0 * math.pi / 3.0, math.pi / 4.0)
#: band of each coefficient index
BAND = (0, 1, 1, 1, 2, 2, 2, 2, 2)
WINDOWS = SH_WINDOWS

vec9 = wp.types.vector(length=9, dtype=wp.float32)

_C0 = wp.constant(SH_C0)
_C1 = wp.constant(SH_C1)
_C2 = wp.constant(SH_C2)
_C20 = wp.constant(SH_C20)
_C22 = wp.constant(SH_C22)


# ---------------------------------------------------------------------------------------------
# funcs


@wp.func
def eval_sh9(d: wp.vec3) -> vec9:
    """The 9 real SH basis functions at unit direction ``d``."""
    x = d[0]
    y = d[1]
    z = d[2]
    return vec9(_C0, _C1 * y, _C1 * z, _C1 * x, _C2 * x * y, _C2 * y * z, _C20 * (3.0 * z * z - 1.0),
                _C2 * x * z, _C22 * (x * x - y * y))


@wp.func
def eval_sh9_dot(coeffs_r: vec9, coeffs_g: vec9, coeffs_b: vec9, d: wp.vec3) -> wp.vec3:
    """Σ_k c_k Y_k(d) per channel (with irradiance coefficients: the irradiance at normal d)."""
    y = eval_sh9(d)
    return wp.vec3(wp.dot(coeffs_r, y), wp.dot(coeffs_g, y), wp.dot(coeffs_b, y))


# ---------------------------------------------------------------------------------------------
# host (numpy twins)


def sh_basis(directions) -> np.ndarray:
    """(N, 9) float64 basis values at (N, 3) unit directions (twin of :func:`eval_sh9`)."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    one = np.ones_like(x)
    return np.stack([SH_C0 * one, SH_C1 * y, SH_C1 * z, SH_C1 * x, SH_C2 * x * y, SH_C2 * y * z,
                     SH_C20 * (3 * z * z - 1), SH_C2 * x * z, SH_C22 * (x * x - y * y)], axis=1)


def window_weights(window: str = "none", size: float = 4.0) -> np.ndarray:
    """(3,) per-band window w_l (l = 0, 1, 2) after Sloan 2008 (see the module docstring)."""
    if window not in WINDOWS:
        raise ValueError(f"window must be one of {WINDOWS}, got {window!r}")
    if window in ("hanning", "lanczos") and not size > 0:
        raise ValueError(f"window size must be positive, got {size}")
    ls = np.arange(3, dtype=np.float64)
    if window == "none":
        return np.ones(3)
    if window == "nonneg":
        return np.array([1.0, math.sqrt(3.0) / 2.0, 0.8])
    if window == "hanning":
        return np.where(ls < size, 0.5 * (1.0 + np.cos(np.pi * ls / size)), 0.0)
    return np.sinc(ls / size)  # numpy's sinc is sin(πx)/(πx)


def irradiance_scale(window: str = "none", size: float = 4.0) -> np.ndarray:
    """(9,) Â_l·w_l per coefficient: radiance SH → irradiance SH."""
    band = np.asarray(A_HAT) * window_weights(window, size)
    return band[np.asarray(BAND)]


def project_radiance(directions, radiance, pdf=None) -> np.ndarray:
    """(9, 3) radiance SH from samples: (1/N) Σ L(ωᵢ) Y(ωᵢ) / p(ωᵢ); ``pdf`` default 1/(4π) (uniform sphere)."""
    y = sh_basis(directions)
    r = np.asarray(radiance, np.float64).reshape(len(y), -1)
    p = np.full(len(y), 1.0 / (4.0 * np.pi)) if pdf is None else np.broadcast_to(np.asarray(pdf, np.float64), len(y))
    return (y / p[:, None]).T @ r / len(y)


def irradiance_coefficients(radiance_sh, window: str = "none", size: float = 4.0) -> np.ndarray:
    """(9, C) irradiance coefficients E_k = Â_l·w_l·L_k."""
    return np.asarray(radiance_sh, np.float64) * irradiance_scale(window, size)[:, None]


def eval_irradiance(irradiance_sh, normals) -> np.ndarray:
    """(N, C) irradiance Σ_k E_k Y_k(n) at (N, 3) unit normals (no clamp)."""
    return sh_basis(normals) @ np.asarray(irradiance_sh, np.float64)


def eval_radiance(radiance_sh, directions) -> np.ndarray:
    """(N, C) the band-limited radiance Σ_k L_k Y_k(ω)."""
    return sh_basis(directions) @ np.asarray(radiance_sh, np.float64)
