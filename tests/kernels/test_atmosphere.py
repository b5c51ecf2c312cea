"""Atmosphere: the fast sky (sky map kernel) against the numerical reference, the mapping, the sun,
night, the cache."""

import math

import numpy as np
import pytest

from serenity.kernels import atmosphere as A
from serenity.scene.model import direction_from_angles

# the fast model at DEFAULT_STEPS vs the reference, per-texel relative error over every 16th texel
# inside the disc; measured (24 steps), every texel marched: mean 0.17/0.17/0.13/0.10 %, worst
# 1.2/1.2/1.1/1.0 %; through the default 64² sky-view table: 0.12 % / 0.92 % at 2°
ELEVATIONS = {90.0: (0.004, 0.025), 45.0: (0.004, 0.025), 10.0: (0.004, 0.025), 2.0: (0.004, 0.025)}


def _texel_sample(size=256, step=16):
    d = A.sky_map_directions(size)[step // 2::step, step // 2::step].reshape(-1, 3)
    inside = A.sky_map_solid_angles(size)[step // 2::step, step // 2::step].reshape(-1) > 0
    return d[inside], inside


@pytest.mark.parametrize("table", [0, None])
@pytest.mark.parametrize("elevation", sorted(ELEVATIONS))
def test_sky_map_vs_reference(device, elevation, table):
    sun = direction_from_angles(elevation, 135.0)
    sky = A.bake_sky_map(sun, device=device, table=table)
    assert sky.shape == (256, 256, 3) and sky.dtype == np.float32
    dirs, inside = _texel_sample()
    ours = sky[8::16, 8::16].reshape(-1, 3)[inside]
    ref = A.sky_radiance_reference(dirs, sun, view_steps=256, sun_steps=128)
    rel = np.abs(ours - ref) / ref
    mean_tol, worst_tol = ELEVATIONS[elevation]
    print(f"elevation {elevation}, table {table}: mean {rel.mean():.4%} worst {rel.max():.4%}")
    assert rel.mean() < mean_tol and rel.max() < worst_tol


def test_reference_is_converged():
    sun = direction_from_angles(10.0, 90.0)
    d = np.array([[0, 1, 0], [0.7, 0.1, 0.7], [1, 0.01, 0], [-1, 0.05, 0.2]], float)
    a = A.sky_radiance_reference(d, sun, view_steps=256, sun_steps=128)
    b = A.sky_radiance_reference(d, sun, view_steps=1024, sun_steps=512)
    assert np.all(np.abs(a - b) / b < 2e-3)


def test_sky_radiance_matches_map_texels(device):
    sun = direction_from_angles(30.0, 200.0)
    sky = A.bake_sky_map(sun, size=64, device=device, table=0)
    d = A.sky_map_directions(64).reshape(-1, 3)
    assert np.allclose(A.sky_radiance(d, sun, device=device), sky.reshape(-1, 3), rtol=1e-5, atol=1e-9)


# the sky-view table against marching every texel (96²): relative error of
# the luminance over the disc — mean, 99th percentile, worst — and of the horizontal irradiance
TABLE_BOUNDS = {1.0: (0.003, 0.03, 0.05), 5.0: (0.002, 0.01, 0.02), 30.0: (0.002, 0.01, 0.02),
                90.0: (0.002, 0.01, 0.02)}


@pytest.mark.parametrize("elevation", sorted(TABLE_BOUNDS))
def test_sky_view_table_matches_per_texel_march(device, elevation):
    sun = direction_from_angles(elevation, 200.0)
    marched = A.bake_sky_map(sun, size=96, device=device, steps=12, table=0)
    tabled = A.bake_sky_map(sun, size=96, device=device, steps=12)
    inside = A.sky_map_solid_angles(96) > 0
    lum = np.array([0.2126, 0.7152, 0.0722])
    ya, yb = marched @ lum, tabled @ lum
    rel = (np.abs(yb - ya) / ya)[inside]
    e_rel = abs(A.horizontal_irradiance(tabled) @ lum / (A.horizontal_irradiance(marched) @ lum) - 1)
    print(f"{elevation}°: mean {rel.mean():.4%} p99 {np.percentile(rel, 99):.4%} worst {rel.max():.4%} E {e_rel:.4%}")
    mean_tol, p99_tol, worst_tol = TABLE_BOUNDS[elevation]
    assert rel.mean() < mean_tol and np.percentile(rel, 99) < p99_tol and rel.max() < worst_tol
    assert e_rel < 1e-3


@pytest.mark.parametrize("elevation", [0.5, -4.0])
def test_low_sun_marches_every_texel(device, elevation):
    """Below SKY_VIEW_TABLE_MIN_ELEVATION_DEG the Earth's shadow is an edge the table cannot follow."""
    sun = direction_from_angles(elevation, 200.0)
    assert np.array_equal(A.bake_sky_map(sun, size=32, device=device),
                          A.bake_sky_map(sun, size=32, device=device, table=0))


def test_sky_is_blue_overhead_and_reddens_at_sunset(device):
    noon = A.sky_radiance([[0.0, 1.0, 0.3]], direction_from_angles(45.0, 180.0), device=device)[0]
    assert noon[2] > noon[1] > noon[0] > 0
    e_noon, e_set = A.sun_irradiance(direction_from_angles(80, 180)), A.sun_irradiance(direction_from_angles(2, 270))
    assert e_noon[2] / e_noon[0] > 0.75 and e_set[2] / e_set[0] < 0.05


def test_paraboloid_mapping_roundtrip_and_solid_angles():
    rng = np.random.default_rng(0)
    d = rng.normal(size=(1000, 3))
    d[:, 1] = np.abs(d[:, 1])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    uv = A.direction_to_paraboloid(d)
    assert np.allclose(A.paraboloid_direction(uv[:, 0], uv[:, 1]), d, atol=1e-12)
    # zenith at the centre, +x east at u = 1, +z south at v = 1, horizon on the unit circle
    assert np.allclose(A.direction_to_paraboloid([[0, 1, 0], [1, 0, 0], [0, 0, 1]]), [[0.5, 0.5], [1, 0.5], [0.5, 1]])
    assert abs(A.sky_map_solid_angles(512).sum() - 2 * math.pi) < 0.01
    # below the horizon: the horizon
    assert np.allclose(A.direction_to_paraboloid([[1, -0.5, 0]]), [[1, 0.5]])


def test_warp_lookup_matches_numpy(device):
    rng = np.random.default_rng(3)
    sky = rng.random((32, 32, 3)).astype(np.float32)
    d = rng.normal(size=(500, 3))
    assert np.allclose(A.sample_sky_map_wp(sky, d, device=device), A.sample_sky_map_np(sky, d), atol=2e-5)


def test_sampling_operator_is_the_lookup_projected():
    """sampling_operator(size, d, B) @ map = Bᵀ @ sample_sky_map_np(map, d) for any map: the open
    sky's coefficients are computed that way, once per map size, instead of sampling each frame."""
    rng = np.random.default_rng(4)
    d = rng.normal(size=(700, 3))
    d[:5] = [[0, 1, 0], [1, 0, 0], [0, 0, -1], [1, 1e-9, 0], [0.3, 0.2, 0.9]]  # zenith, horizon, edges
    basis = rng.normal(size=(700, 9))
    for size in (2, 17, 64):
        op = A.sampling_operator(size, d, basis)
        assert op.shape == (9, size * size)
        for _ in range(2):
            sky = rng.random((size, size, 3)).astype(np.float32)
            direct = basis.T @ A.sample_sky_map_np(sky, d)
            assert np.allclose(op @ sky.reshape(-1, 3).astype(np.float64), direct, rtol=1e-12, atol=1e-12)


def test_sun_units_and_default_scale():
    e = A.sun_irradiance([0, 1, 0])
    assert 900 < e[1] < 1100  # noon sun on the order of 1000 W/m² (Sun model default (1000, 960, 900))
    omega = 2 * math.pi * (1 - math.cos(math.radians(0.53) / 2))
    assert np.allclose(A.sun_radiance([0, 1, 0]) * omega, e)
    sun = A.make_sun(direction_from_angles(30, 100))
    assert np.allclose(sun.irradiance, A.sun_irradiance(sun.direction))
    assert np.all(A.sun_irradiance(direction_from_angles(-1, 100)) == 0)
    # monotone: higher sun, more light
    es = [A.sun_irradiance(direction_from_angles(el, 0))[2] for el in (1, 5, 20, 60, 90)]
    assert all(b > a for a, b in zip(es, es[1:], strict=False))


@pytest.mark.parametrize("elevation", [0.0, -2.0, -10.0, -45.0, -90.0])
def test_night_is_dark_finite_non_negative(device, elevation):
    sky = A.bake_sky_map(direction_from_angles(elevation, 300.0), size=64, device=device)
    assert np.all(np.isfinite(sky)) and sky.min() >= 0.0
    if elevation <= -10:  # nautical twilight at -10°, night below
        assert sky.max() < (0.1 if elevation > -18 else 1e-5)
        assert sky.min() >= min(A.NIGHT_SKY_RADIANCE) * 0.999
    eq = A.equirect_sky(direction_from_angles(elevation, 300.0), 64, 32, device=device)
    assert np.all(np.isfinite(eq)) and eq.min() >= 0.0


def test_equirect_orientation(device):
    # sun due east at 20°: the brightest sky pixel sits at azimuth 90° (u = 0.25), above the horizon
    eq = A.equirect_sky(direction_from_angles(20.0, 90.0), 128, 64, device=device)
    assert np.all(eq[32:] == 0)  # below the horizon
    i, j = np.unravel_index(np.argmax(eq[..., 1]), eq.shape[:2])
    assert abs((j + 0.5) / 128 - 0.25) < 0.03 and i < 32
    d = A.equirect_directions(128, 64)
    assert np.allclose(d[0, 0], [np.sin(np.pi / 128) * np.sin(np.pi / 128), np.cos(np.pi / 128),
                                 -np.sin(np.pi / 128) * np.cos(np.pi / 128)])


def test_cache_rebuilds_only_past_the_angle(device):
    cache = A.SkyMapCache(size=32, rebuild_angle_deg=1.0, device=device)
    _, rebuilt = cache.get(direction_from_angles(30, 100))
    assert rebuilt and cache.version == 1
    _, rebuilt = cache.get(direction_from_angles(30.5, 100))
    assert not rebuilt and cache.version == 1
    _, rebuilt = cache.get(direction_from_angles(31.5, 100))
    assert rebuilt and cache.version == 2
    assert cache.sky_map.shape == (32, 32, 3)
