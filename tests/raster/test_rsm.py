"""RSM: the VPL flux adds up to the sun power the lit surfaces reflect."""

import math

import numpy as np

from serenity.raster.context import get_context
from serenity.raster.rsm import RSMPass
from serenity.raster.scene_gl import SceneGL

from .scenes import plane_scene


def test_rsm_flux_sums_to_reflected_sun_power(gl_ctx):
    scene = plane_scene(albedo=0.5, zenith_deg=30.0, irradiance=1000.0)
    ctx = get_context()
    rsm = RSMPass(ctx, SceneGL(ctx, scene), size=256)
    rsm.render(scene.sun.direction, scene.sun.irradiance, scene.bounds)
    vpl = rsm.read()
    # the 40 x 40 m plane intercepts E cos(theta) per m^2 of its area; it reflects rho of that
    expected = 0.5 * 1000.0 * math.cos(math.radians(30.0)) * 40.0 * 40.0
    assert abs(vpl.flux[:, 0].sum() / expected - 1) < 0.01
    assert np.allclose(vpl.normals, [0, 1, 0], atol=1e-3)
    assert np.allclose(vpl.positions[:, 1], 0.0, atol=1e-3)
