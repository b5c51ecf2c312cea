"""QMC point sets and sphere maps: Warp == numpy bit for bit, stratification, discrepancy, chi²."""

import math

import numpy as np
import pytest
from scipy import stats

from serenity.kernels import sampling as S


@pytest.mark.parametrize("scramble", S.SCRAMBLES)
def test_warp_matches_numpy_bit_for_bit(device, scramble):
    for seed in (0, 1, 12345, 0xFFFFFFFF):
        w = S.generate_points_warp(1000, seed, scramble, device=device)
        n = S.hammersley_np(1000, seed) if scramble == "cp" else S.sobol_owen_np(1000, seed)
        assert np.array_equal(w, n)
        assert w.min() >= 0.0 and w.max() < 1.0


def test_owen_sobol_prefixes_are_0_m_2_nets():
    # every power-of-two prefix has exactly one point in each elementary interval of volume 1/n
    for seed in (3, 99):
        pts = S.sobol_owen_np(256, seed)
        for m in (4, 6, 8):
            n = 1 << m
            p = pts[:n]
            for k in range(m + 1):
                cells = set(zip((p[:, 0] * (1 << k)).astype(int), (p[:, 1] * (1 << (m - k))).astype(int), strict=True))
                assert len(cells) == n


def test_hammersley_is_stratified_after_rotation():
    # rotation modulo 1 keeps one point per 1/n stripe in u0 and per 1/n stripe in u1 (n = 2^k)
    p = S.hammersley_np(256, seed=7)
    assert len(set((p[:, 0] * 256).astype(int))) == 256
    assert len(set((p[:, 1] * 256).astype(int))) == 256


def test_discrepancy_beats_random():
    rng = np.random.default_rng(0)
    rand = np.mean([S.l2_star_discrepancy(rng.random((256, 2))) for _ in range(4)])
    assert S.l2_star_discrepancy(S.sobol_owen_np(256, 5)) < rand / 5
    assert S.l2_star_discrepancy(S.hammersley_np(256)) < rand / 5


def test_scrambles_decorrelate_seeds():
    # per-probe seeds give different point sets whose integration errors average out (unbiased)
    f = lambda d: np.maximum(d[:, 1], 0.0) ** 3  # noqa: E731  ∫ over the sphere = π/2
    for gen in (lambda s: S.sobol_owen_np(64, s), lambda s: S.hammersley_np(64, s)):
        est = np.array([f(S.uniform_sphere_np(gen(s).astype(np.float64))).mean() * 4 * math.pi for s in range(64)])
        assert len(np.unique(est)) > 32
        assert abs(est.mean() - math.pi / 2) < 3 * est.std() / 8 + 1e-3


def _chi2_sphere(dirs, bins_y=8, bins_phi=16, weights=None):
    """chi² p-value of direction counts in equal-solid-angle (y, φ) cells against ``weights``."""
    y = np.clip(((dirs[:, 1] + 1) / 2 * bins_y).astype(int), 0, bins_y - 1)
    phi = np.clip(((np.arctan2(dirs[:, 2], dirs[:, 0]) % (2 * np.pi)) / (2 * np.pi) * bins_phi).astype(int),
                  0, bins_phi - 1)
    counts = np.bincount(y * bins_phi + phi, minlength=bins_y * bins_phi)
    w = np.full(bins_y * bins_phi, 1.0) if weights is None else weights
    expected = w / w.sum() * len(dirs)
    return stats.chisquare(counts, expected).pvalue


def test_uniform_sphere_chi2_and_unit_length():
    rng = np.random.default_rng(1)
    d = S.uniform_sphere_np(rng.random((20000, 2)))
    assert np.allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-12)
    assert _chi2_sphere(d) > 1e-3
    # a QMC set fills the cells almost exactly (far better than chance)
    q = S.uniform_sphere_np(S.sobol_owen_np(1024, 3).astype(np.float64))
    assert _chi2_sphere(q) > 0.99


def test_cosine_hemisphere_chi2():
    rng = np.random.default_rng(2)
    d = S.cosine_hemisphere_np(rng.random((40000, 2)))
    assert d[:, 1].min() >= 0.0
    # expected mass of y-band [a, b] under cos θ/π on the upper hemisphere is b² − a²
    edges = np.linspace(0, 1, 9)
    mass = edges[1:] ** 2 - edges[:-1] ** 2
    counts = np.histogram(d[:, 1], bins=edges)[0]
    assert stats.chisquare(counts, mass / mass.sum() * len(d)).pvalue > 1e-3
    # E[cos θ] = 2/3 under the cosine pdf
    assert abs(d[:, 1].mean() - 2 / 3) < 0.01


def test_qmc_sphere_integration_converges():
    # ∫ max(0, y)·1 dω = π; QMC error at 1024 points is far below MC's ~3%
    f = lambda d: np.maximum(d[:, 1], 0.0)  # noqa: E731
    q = S.uniform_sphere_np(S.hammersley_np(1024, seed=11).astype(np.float64))
    est = f(q).mean() * 4 * math.pi
    assert abs(est - math.pi) / math.pi < 0.005
