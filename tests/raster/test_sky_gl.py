"""sky.glsl against the kernels: the sky map lookup, the sky volume irradiance and its glossy term,
pixel by pixel (inside the grid and beyond it, where both fade to the open sky)."""

import numpy as np
import pytest

from serenity.config import SkyConfig
from serenity.kernels import atmosphere as A
from serenity.kernels.skyvolume import SkyVolume
from serenity.raster import context
from serenity.raster.context import load_program
from serenity.raster.sky import SkyTexturesGL
from serenity.scene.procedural import build_scene


@pytest.fixture(scope="module")
def volume():
    vol = SkyVolume(build_scene("courtyard"), SkyConfig(rays_per_probe=64, resolution=(12, 6, 10)))
    vol.rebuild()
    return vol


@pytest.fixture(params=[None, True], ids=["auto", "exact-filter"])
def sky_gl(request, monkeypatch, gl_ctx, volume):
    # auto: the texture unit's filter on llvmpipe, the shader's own on a GPU; True: the shader's own here
    # too (raster/context.EXACT_FILTER)
    monkeypatch.setattr(context, "EXACT_FILTER", request.param)
    g = SkyTexturesGL(gl_ctx)
    g.upload_sky_map(volume.sky.sky_map)
    g.upload_volume(volume.textures(), volume.grid_origin, volume.cell_size, volume.resolution,
                    volume.normal_offset_m)
    g.set_open_sky(volume.open_coefficients())
    return g


def test_sky_map_radiance_matches_kernels(gl_ctx, sky_gl, volume):
    sky = volume.sky.sky_map
    # texel centres inside the disc: exactly the baked texels
    size = sky.shape[0]
    inside = A.sky_map_solid_angles(size).reshape(-1) > 0
    d = A.sky_map_directions(size).reshape(-1, 3)[inside][::13]
    ref = sky.reshape(-1, 3)[inside][::13]
    gl = sky_gl.evaluate_sky_map(d)
    assert np.all(np.abs(gl - ref) <= 1e-3 * np.abs(ref))
    # any direction (incl. below the horizon): the bilinear lookup of the map
    rng = np.random.default_rng(0)
    d = rng.normal(size=(4000, 3))
    ref = A.sample_sky_map_np(sky, d)
    gl = sky_gl.evaluate_sky_map(d)
    assert np.all(np.abs(gl - ref) <= 1e-3 * np.abs(ref) + 1e-7)


def test_sky_volume_irradiance_matches_kernels(gl_ctx, sky_gl, volume):
    rng = np.random.default_rng(1)
    lo, hi = build_scene("courtyard").bounds
    p = rng.uniform(lo - 5, hi + 5, size=(4000, 3))  # inside and outside the grid (clamped)
    n = rng.normal(size=(4000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    ref = volume.irradiance(p, n)
    gl = sky_gl.evaluate_volume(p, n)
    scale = np.maximum(np.abs(ref).max(axis=1, keepdims=True), 1e-3)
    err = np.abs(gl - ref) / scale
    print(f"volume: mean {err.mean():.2e} worst {err.max():.2e} (relative to the pixel's largest channel)")
    assert err.max() <= 1e-3


@pytest.mark.parametrize("shininess", [0.0, 8.0, 200.0])
def test_sky_volume_glossy_matches_kernels(gl_ctx, sky_gl, volume, shininess):
    rng = np.random.default_rng(2)
    lo, hi = build_scene("courtyard").bounds
    p = rng.uniform(lo - 5, hi + 5, size=(3000, 3))
    n = rng.normal(size=(3000, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    r = rng.normal(size=(3000, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    ref = volume.glossy(p, n, r, shininess)
    gl = sky_gl.evaluate_volume_glossy(p, n, r, shininess)
    scale = np.maximum(np.abs(ref).max(axis=1, keepdims=True), 1e-3)
    err = np.abs(gl - ref) / scale
    print(f"glossy m={shininess}: mean {err.mean():.2e} worst {err.max():.2e}")
    assert err.max() <= 1e-3


def test_bind_sets_uniforms(gl_ctx, sky_gl, volume):
    prog = load_program(gl_ctx, "sky_eval.glsl")
    nxt = sky_gl.bind(prog, 2)
    assert nxt == 12
    assert prog["u_sky_map"].value == 2
    assert list(prog["u_sky_volume"].value) == list(range(3, 10))
    assert np.allclose(prog["u_sky_res"].value, volume.resolution)
    assert np.allclose(prog["u_sky_origin"].value, volume.grid_origin, atol=1e-5)
    prog.release()


def test_reupload_same_and_new_size(gl_ctx, sky_gl, volume):
    sky_gl.upload_sky_map(np.full((8, 8, 3), 2.0, np.float32))
    assert np.allclose(sky_gl.evaluate_sky_map(np.array([[0.0, 1.0, 0.0]])), 2.0)
    sky_gl.upload_sky_map(np.full((8, 8, 3), 3.0, np.float32))
    assert np.allclose(sky_gl.evaluate_sky_map(np.array([[0.3, 0.2, 0.1]])), 3.0)


def test_layer_upload_writes_only_its_slab(gl_ctx, volume):
    """``upload_volume_layers`` (the frame's upload after a partial transfer update): writing one
    slab of y-layers over a zeroed volume puts exactly that slab's texels there and leaves the rest."""
    g = SkyTexturesGL(gl_ctx)
    full = volume.textures()
    g.upload_volume([np.zeros_like(t) for t in full], volume.grid_origin, volume.cell_size, volume.resolution,
                    volume.normal_offset_m)
    first, n = 2, 3
    g.upload_volume_layers(volume.textures(layers=(first, n)), first)
    for tex, want in zip(g.volume, full, strict=True):
        got = np.frombuffer(tex.read(), np.float32).reshape(want.shape)
        assert np.array_equal(got[:, first:first + n], want[:, first:first + n])
        assert not got[:, :first].any() and not got[:, first + n:].any()
    with pytest.raises(ValueError, match="does not fit"):
        g.upload_volume_layers(volume.textures(layers=(first, n)), volume.resolution[1] - 1)


@pytest.fixture(scope="module")
def gathered():
    """A small gathered volume of the courtyard, with the probes' visibility."""
    vol = SkyVolume(build_scene("courtyard"), SkyConfig(method="gather", target_probes=1500, gather_rays=64,
                                                        fit="content", normal_offset=0.25))
    vol.rebuild()
    assert vol.visibility is not None
    return vol


def test_sky_volume_with_probe_visibility_matches_kernels(gl_ctx, gathered):
    """SKY_VISIBILITY: the 8 probes read one by one and weighed by their depth moments, against the
    numpy twin (irradiance and glossy) — on the courtyard's surfaces, where the weights matter."""
    g = SkyTexturesGL(gl_ctx)
    g.upload_sky_map(gathered.sky.sky_map)
    g.upload_volume(gathered.textures(), gathered.grid_origin, gathered.cell_size, gathered.resolution,
                    gathered.normal_offset_m)
    g.set_open_sky(gathered.open_coefficients())
    g.upload_visibility(*gathered.visibility_textures())
    rng = np.random.default_rng(5)
    gp = gathered.method.probes
    pick = rng.choice(gp.surfel_count, 3000, replace=False)
    p = gp.surfel_positions[pick] + rng.normal(scale=0.05, size=(3000, 3))
    n = gp.surfel_normals[pick]
    r = rng.normal(size=(3000, 3))
    r /= np.linalg.norm(r, axis=1, keepdims=True)
    for ref, gl in ((gathered.irradiance(p, n), g.evaluate_volume(p, n)),
                    (gathered.glossy(p, n, r, 16.0), g.evaluate_volume_glossy(p, n, r, 16.0))):
        scale = np.maximum(np.abs(ref).max(axis=1, keepdims=True), 1e-2)
        err = np.abs(gl - ref) / scale
        print(f"visibility: mean {err.mean():.2e} worst {err.max():.2e}")
        assert err.max() <= 1e-3
