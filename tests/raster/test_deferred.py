"""Deferred direct lighting against analytic answers."""

import math
from dataclasses import replace

import numpy as np
import pytest

from serenity.config import LPVConfig, RenderConfig, SkyConfig
from serenity.frame import Renderer

from .scenes import plane_scene, project

#: direct light only: these tests check it against analytic answers
DIRECT = RenderConfig(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False))


@pytest.mark.parametrize("zenith", [0.0, 30.0, 60.0, 80.0])
def test_diffuse_plane_under_sun_is_rho_over_pi_E_cos(gl_ctx, zenith):
    rho, E = 0.5, 1000.0
    scene = plane_scene(albedo=rho, zenith_deg=zenith, irradiance=E)
    frame = Renderer(scene, 96, 54, config=DIRECT).render()
    covered = np.isfinite(frame.aovs["depth"][..., 0])
    assert covered.mean() > 0.3
    expected = rho / math.pi * E * math.cos(math.radians(zenith))
    got = frame.hdr[covered]
    assert abs(got.mean() / expected - 1) < 0.02
    assert np.all(np.abs(got / expected - 1) < 0.02)  # every pixel, not just the mean
    assert np.allclose(frame.aovs["direct"][covered], frame.hdr[covered])


def test_point_in_box_shadow_gets_no_direct_light(gl_ctx):
    # sun due east at 45 deg elevation: the 2 m box casts a shadow from x=-1 to x=-3 (west)
    scene = plane_scene(zenith_deg=45.0, azimuth_deg=90.0, with_box=True)
    w, h = 320, 180
    frame = Renderer(scene, w, h, config=DIRECT).render()
    direct = frame.aovs["direct"][..., 0]
    for p in [(-2.0, 0.0, 0.0), (-2.5, 0.0, 0.5), (-1.6, 0.0, -0.6)]:
        r, c = project(scene, w, h, p)
        assert direct[r, c] == 0.0, p
    for p in [(-2.0, 0.0, 3.5), (3.0, 0.0, 0.0), (-3.6, 0.0, 0.0)]:
        r, c = project(scene, w, h, p)
        assert direct[r, c] > 0.9 * 0.5 / math.pi * 1000 * math.cos(math.radians(45)), p


def test_sun_below_horizon_gives_no_direct_light_and_finite_image(gl_ctx):
    scene = plane_scene(zenith_deg=95.0)
    frame = Renderer(scene, 64, 36, config=DIRECT).render()
    assert np.all(np.isfinite(frame.hdr))
    assert frame.aovs["direct"].max() == 0.0


def test_constant_ambient_adds_pi_L_sky(gl_ctx):
    scene = plane_scene(zenith_deg=95.0)
    scene.sky.radiance = np.array([10.0, 20.0, 30.0])
    frame = Renderer(scene, 64, 36, config=replace(DIRECT, ambient="constant")).render()
    covered = np.isfinite(frame.aovs["depth"][..., 0])
    expected = 0.5 / math.pi * math.pi * np.array([10.0, 20.0, 30.0])
    assert np.allclose(frame.hdr[covered], expected, rtol=2e-3)


def test_frame_layout(gl_ctx):
    scene = plane_scene()
    frame = Renderer(scene, 40, 30).render()
    assert frame.hdr.shape == (30, 40, 3) and frame.hdr.dtype == np.float32
    assert frame.ldr.shape == (30, 40, 3) and frame.ldr.dtype == np.uint8
    for name in ("albedo", "normal", "depth", "direct", "position"):
        assert frame.aovs[name].shape[:2] == (30, 40)
    assert {"shadow maps (CSM)", "g-buffer", "direct lighting", "tone map"} <= set(frame.timings)
    # row 0 is the top of the image: the camera looks down, so the bottom rows are nearer
    d = frame.aovs["depth"][..., 0]
    assert d[-1, 20] < d[5, 20]
    # material index per pixel (the plane's material), -1 on the background
    mat = frame.aovs["material"][..., 0]
    plane = [m.name for m in scene.materials].index("plane")
    assert np.all(mat[np.isfinite(d)] == plane) and np.all(mat[~np.isfinite(d)] == -1)
    assert np.isfinite(d).any() and (~np.isfinite(d)).any()
