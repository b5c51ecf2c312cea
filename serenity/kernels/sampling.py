"""Quasi-Monte Carlo direction sampling: 2-D low-discrepancy points and sphere/hemisphere maps.

Point sets (all in [0, 1)², float32; ``n`` points, index ``i`` in ``[0, n)``):

- **Hammersley** ``(i + 0.5) / n, φ₂(i)`` where φ₂ is the base-2 radical inverse (bit reversal
  of the 32-bit index), decorrelated per probe by a **Cranley–Patterson rotation**: both
  coordinates are shifted by a per-seed offset modulo 1 (Cranley & Patterson 1976). Cheap; keeps
  the lattice-like structure (and its low discrepancy on the torus). The sky volume's default.
- **Owen-scrambled Sobol'** (dimensions 1 and 2 of Sobol' = van der Corput and the Pascal-matrix
  dimension), each dimension scrambled by a hash-driven nested uniform (Owen 1995) permutation:
  for every bit, from the most significant down, the bit is flipped by a hash of the seed and of
  all more significant bits. Any prefix of the sequence is well stratified, at 2×32 hashes per
  point.

Direction maps (input ``u`` in [0, 1)², output a unit float32 vec3; **y is the polar axis**, as the
world's up, so strata boundaries line up with the horizon):

- ``sample_uniform_sphere``: y = 1 − 2u₀, φ = 2πu₁, (x, z) = √(1−y²)(cos φ, sin φ); pdf 1/(4π).
  Equal-area, so a stratified (u₀, u₁) set gives equal-solid-angle strata.
- ``sample_cosine_hemisphere``: about +y, r = √u₀, φ = 2πu₁, y = √(1−u₀); pdf cos θ / π.

Hashing is the 32-bit PCG output permutation of a one-step LCG (O'Neill 2014, as used by Jarzynski &
Olano 2020 for GPU hashing). Every ``@wp.func`` has a numpy mirror (suffix ``_np``) for tests and
host code; they produce the same bits. ``l2_star_discrepancy`` (Warnock's closed form) and the chi²
tests in ``tests/kernels/test_sampling.py`` check the sets.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from serenity.device import resolve_device
from serenity.kernels.launch import launch

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants

INV_2_32 = 1.0 / 4294967296.0
TWO_PI = 2.0 * math.pi
#: largest float32 strictly below 1 (keeps u in [0, 1) after float rounding)
ONE_MINUS_EPS = 0.99999994
SCRAMBLES = ("cp", "owen")
# uint32 constants above 2³¹ must be typed constants: a literal inside a kernel is emitted as an
# int32 (a narrowing conversion the C++ compiler warns about)
_PCG_MUL = wp.constant(wp.uint32(747796405))
_PCG_INC = wp.constant(wp.uint32(2891336453))
_PCG_OUT = wp.constant(wp.uint32(277803737))
_TOP_BIT = wp.constant(wp.uint32(0x80000000))
_GOLDEN = wp.constant(wp.uint32(0x9E3779B9))
_SEED_SOBOL2 = wp.constant(wp.uint32(0x68E31DA4))
_SEED_CP = wp.constant(wp.uint32(0x5BD1E995))


# ---------------------------------------------------------------------------------------------
# funcs


@wp.func
def hash_u32(x: wp.uint32) -> wp.uint32:
    """PCG hash: one LCG step, then the RXS-M-XS output permutation."""
    state = x * _PCG_MUL + _PCG_INC
    word = ((state >> ((state >> wp.uint32(28)) + wp.uint32(4))) ^ state) * _PCG_OUT
    return (word >> wp.uint32(22)) ^ word


@wp.func
def hash_to_unit(x: wp.uint32) -> float:
    """A hash as a float in [0, 1) (top 24 bits, exact in float32)."""
    return float(hash_u32(x) >> wp.uint32(8)) * (1.0 / 16777216.0)


@wp.func
def reverse_bits(x: wp.uint32) -> wp.uint32:
    x = ((x >> wp.uint32(1)) & wp.uint32(0x55555555)) | ((x & wp.uint32(0x55555555)) << wp.uint32(1))
    x = ((x >> wp.uint32(2)) & wp.uint32(0x33333333)) | ((x & wp.uint32(0x33333333)) << wp.uint32(2))
    x = ((x >> wp.uint32(4)) & wp.uint32(0x0F0F0F0F)) | ((x & wp.uint32(0x0F0F0F0F)) << wp.uint32(4))
    x = ((x >> wp.uint32(8)) & wp.uint32(0x00FF00FF)) | ((x & wp.uint32(0x00FF00FF)) << wp.uint32(8))
    return (x >> wp.uint32(16)) | (x << wp.uint32(16))


@wp.func
def sobol2_bits(i: wp.uint32) -> wp.uint32:
    """Sobol' dimension 2 (direction numbers v_k = v_{k-1} xor v_{k-1} >> 1, v_0 = 2^31)."""
    v = _TOP_BIT
    r = wp.uint32(0)
    x = i
    while x != wp.uint32(0):
        if (x & wp.uint32(1)) != wp.uint32(0):
            r = r ^ v
        v = v ^ (v >> wp.uint32(1))
        x = x >> wp.uint32(1)
    return r


@wp.func
def owen_scramble_bits(x: wp.uint32, seed: wp.uint32) -> wp.uint32:
    """Nested uniform scramble of a 32-bit fraction: bit b flips by a hash of seed and bits above b."""
    out = x
    for b in range(32):
        bit = wp.uint32(31 - b)
        # the more significant (already final, unscrambled) bits with a marker bit above them
        prefix = (x >> bit) >> wp.uint32(1)
        key = (prefix << wp.uint32(1)) | wp.uint32(1)
        key = key ^ (bit * _GOLDEN)
        flip = hash_u32(key ^ hash_u32(seed)) & wp.uint32(1)
        out = out ^ (flip << bit)
    return out


@wp.func
def bits_to_unit(x: wp.uint32) -> float:
    return wp.min(float(x >> wp.uint32(8)) * (1.0 / 16777216.0), ONE_MINUS_EPS)


@wp.func
def sample_hammersley_cp(i: int, n: int, rot: wp.vec2) -> wp.vec2:
    """Point ``i`` of ``n`` of the Hammersley set, Cranley–Patterson rotated by ``rot``."""
    u0 = (float(i) + 0.5) / float(n) + rot[0]
    u1 = bits_to_unit(reverse_bits(wp.uint32(i))) + rot[1]
    u0 = u0 - wp.floor(u0)
    u1 = u1 - wp.floor(u1)
    return wp.vec2(wp.min(u0, ONE_MINUS_EPS), wp.min(u1, ONE_MINUS_EPS))


@wp.func
def sample_sobol_owen(i: int, seed: wp.uint32) -> wp.vec2:
    """Point ``i`` of the first two Sobol' dimensions, each Owen-scrambled (seeds derived from ``seed``)."""
    x0 = owen_scramble_bits(reverse_bits(wp.uint32(i)), seed)
    x1 = owen_scramble_bits(sobol2_bits(wp.uint32(i)), hash_u32(seed ^ _SEED_SOBOL2))
    return wp.vec2(bits_to_unit(x0), bits_to_unit(x1))


@wp.func
def cp_rotation(seed: wp.uint32) -> wp.vec2:
    """The Cranley–Patterson offset of a seed (two hashes)."""
    h = hash_u32(seed)
    return wp.vec2(hash_to_unit(h), hash_to_unit(h ^ _SEED_CP))


@wp.func
def sample_uniform_sphere(u: wp.vec2) -> wp.vec3:
    y = 1.0 - 2.0 * u[0]
    r = wp.sqrt(wp.max(0.0, 1.0 - y * y))
    phi = TWO_PI * u[1]
    return wp.vec3(r * wp.cos(phi), y, r * wp.sin(phi))


@wp.func
def sample_probe_direction(k: int, base_points: wp.array(dtype=wp.vec2), rot: wp.vec2, seed: wp.uint32,
                           hammersley: bool) -> wp.vec3:
    """Direction ``k`` of a probe's QMC set on the sphere (uniform, pdf 1/4π): the precomputed point
    ``base_points[k]`` Cranley–Patterson rotated by ``rot`` (``hammersley``), else Owen-scrambled
    Sobol' point k with ``seed``. ``hammersley`` is a compile-time constant (``wp.static``) at every
    call, so each specialised kernel keeps one branch."""
    u = wp.vec2()
    if hammersley:
        u = base_points[k] + rot
        u = wp.vec2(wp.min(u[0] - wp.floor(u[0]), ONE_MINUS_EPS), wp.min(u[1] - wp.floor(u[1]), ONE_MINUS_EPS))
    else:
        u = sample_sobol_owen(k, seed)
    return sample_uniform_sphere(u)


@wp.func
def sample_cosine_hemisphere(u: wp.vec2) -> wp.vec3:
    r = wp.sqrt(u[0])
    phi = TWO_PI * u[1]
    return wp.vec3(r * wp.cos(phi), wp.sqrt(wp.max(0.0, 1.0 - u[0])), r * wp.sin(phi))


# ---------------------------------------------------------------------------------------------
# kernels


@wp.kernel
def generate_points(
    # inputs
    n: int,
    seed: wp.uint32,
    scramble: int,  # 0 = Hammersley + CP rotation, 1 = Owen-scrambled Sobol'
    # outputs
    points: wp.array(dtype=wp.vec2),
    offset: int,
):
    i = wp.tid() + offset
    if scramble == 0:
        points[i] = sample_hammersley_cp(i, n, cp_rotation(seed))
    else:
        points[i] = sample_sobol_owen(i, seed)


# ---------------------------------------------------------------------------------------------
# host: numpy mirrors and helpers

_M32 = np.uint64(0xFFFFFFFF)


def _u32(x) -> np.ndarray:
    return np.asarray(x, dtype=np.uint64) & _M32


def hash_u32_np(x) -> np.ndarray:
    """Mirror of :func:`hash_u32` (uint32 in, uint32 out)."""
    s = (_u32(x) * np.uint64(747796405) + np.uint64(2891336453)) & _M32
    w = (((s >> ((s >> np.uint64(28)) + np.uint64(4))) ^ s) * np.uint64(277803737)) & _M32
    return ((w >> np.uint64(22)) ^ w).astype(np.uint32)


def reverse_bits_np(x) -> np.ndarray:
    x = _u32(x).astype(np.uint32)
    out = np.zeros_like(x)
    for b in range(32):
        out |= ((x >> np.uint32(b)) & np.uint32(1)) << np.uint32(31 - b)
    return out


def sobol2_bits_np(i) -> np.ndarray:
    x = _u32(i)
    r = np.zeros_like(x)
    v = np.uint64(0x80000000)
    for _ in range(32):
        r ^= np.where(x & np.uint64(1), v, np.uint64(0))
        v ^= v >> np.uint64(1)
        x = x >> np.uint64(1)
    return r.astype(np.uint32)


def owen_scramble_bits_np(x, seed: int) -> np.ndarray:
    x = _u32(x)
    hs = _u32(hash_u32_np(np.uint32(seed)))
    out = x.copy()
    for b in range(32):
        bit = np.uint64(31 - b)
        prefix = (x >> bit) >> np.uint64(1)
        key = ((prefix << np.uint64(1)) | np.uint64(1)) & _M32
        key ^= (np.uint64(31 - b) * np.uint64(0x9E3779B9)) & _M32
        flip = _u32(hash_u32_np(key ^ hs)) & np.uint64(1)
        out ^= flip << bit
    return out.astype(np.uint32)


def _bits_to_unit_np(x) -> np.ndarray:
    return np.minimum((np.asarray(x, np.uint32) >> np.uint32(8)).astype(np.float32) / np.float32(16777216.0),
                      np.float32(ONE_MINUS_EPS))


def cp_rotation_np(seed: int) -> np.ndarray:
    h = hash_u32_np(np.uint32(seed))
    a = (hash_u32_np(h) >> np.uint32(8)).astype(np.float32) / np.float32(16777216.0)
    b = (hash_u32_np(h ^ np.uint32(0x5BD1E995)) >> np.uint32(8)).astype(np.float32) / np.float32(16777216.0)
    return np.array([a, b], np.float32)


def hammersley_np(n: int, seed: int | None = None) -> np.ndarray:
    """(n, 2) float32 Hammersley points, CP-rotated by the hash of ``seed`` (None: unrotated)."""
    i = np.arange(n)
    u = np.stack([((i + 0.5) / n).astype(np.float32), _bits_to_unit_np(reverse_bits_np(i))], axis=1)
    if seed is not None:
        u = u + cp_rotation_np(seed)[None]
        u = u - np.floor(u)
    return np.minimum(u, np.float32(ONE_MINUS_EPS)).astype(np.float32)


def sobol_owen_np(n: int, seed: int) -> np.ndarray:
    """(n, 2) float32 Owen-scrambled Sobol' points (mirror of :func:`sample_sobol_owen`)."""
    i = np.arange(n)
    s1 = int(hash_u32_np(np.uint32(seed) ^ np.uint32(0x68E31DA4)))
    x0 = owen_scramble_bits_np(reverse_bits_np(i), seed)
    x1 = owen_scramble_bits_np(sobol2_bits_np(i), s1)
    return np.stack([_bits_to_unit_np(x0), _bits_to_unit_np(x1)], axis=1)


def uniform_sphere_np(u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, np.float64)
    y = 1.0 - 2.0 * u[:, 0]
    r = np.sqrt(np.maximum(0.0, 1.0 - y * y))
    phi = TWO_PI * u[:, 1]
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1)


def cosine_hemisphere_np(u: np.ndarray) -> np.ndarray:
    u = np.asarray(u, np.float64)
    r = np.sqrt(u[:, 0])
    phi = TWO_PI * u[:, 1]
    return np.stack([r * np.cos(phi), np.sqrt(np.maximum(0.0, 1.0 - u[:, 0])), r * np.sin(phi)], axis=1)


def fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) float64 unit directions spread evenly over the sphere (Fibonacci lattice): test and
    benchmark directions for comparing a sampled field against a reference."""
    i = np.arange(n) + 0.5
    y = 1 - 2 * i / n
    r = np.sqrt(1 - y * y)
    phi = math.pi * (1 + 5**0.5) * i
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1)


def l2_star_discrepancy(points: np.ndarray) -> float:
    """L2 star discrepancy of points in [0,1]^d (Warnock 1972 closed form), O(n² d)."""
    x = np.asarray(points, np.float64)
    n, d = x.shape
    t1 = 3.0 ** (-d)
    t2 = np.prod((1.0 - x * x) / 2.0, axis=1).sum() * (2.0 / n)
    m = np.ones((n, n))
    for k in range(d):
        m *= 1.0 - np.maximum(x[:, None, k], x[None, :, k])
    return float(math.sqrt(max(t1 - t2 + m.sum() / (n * n), 0.0)))


def generate_points_warp(n: int, seed: int, scramble: str = "cp", device: str | None = None) -> np.ndarray:
    """(n, 2) float32 points computed by the Warp kernel (for tests / CPU-CUDA agreement)."""
    if scramble not in SCRAMBLES:
        raise ValueError(f"scramble must be one of {SCRAMBLES}, got {scramble!r}")
    device = resolve_device(device)
    out = wp.zeros(n, dtype=wp.vec2, device=device)
    launch(generate_points, n, [int(n), wp.uint32(seed & 0xFFFFFFFF), SCRAMBLES.index(scramble), out], device=device)
    return out.numpy()
