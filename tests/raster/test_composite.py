"""The Fresnel composite (``glsl/composite.glsl``) against its formula, pixel by pixel: glass is
T·(F·L_reflection + (1−F)·L_refraction) + (1−T)·L_surface (the reference's
``blendbsdf(T, phong, dielectric)``), F = Schlick's with f0 = ((ior−1)/(ior+1))², 1 under total
internal reflection; a mirror is F·L_reflection + (1−F)·L_surface with F = Schlick's from R."""

from types import SimpleNamespace

import numpy as np
import pytest

from serenity.raster.composite import CompositePass
from serenity.raster.interop import read_texture

SURFACE = np.array([1.0, 2.0, 3.0])


def schlick(f0, cos):
    return f0 + (1 - f0) * (1 - cos) ** 5


def _texture(ctx, rows):
    a = np.asarray(rows, np.float32).reshape(1, -1, 4)
    return ctx.texture((a.shape[1], 1), 4, a.tobytes(), dtype="f4")


def test_glass_and_mirror_composite_match_the_formula(gl_ctx):
    """Four pixels of a 4×1 view, camera at the origin, every surface point at (0, 0, −1): glass
    (T 0.9, ior 1.5) at normal incidence and at cos θ = 0.5, glass under total internal reflection,
    and a mirror (R 0.6); the traced rays hold distinct radiances."""
    ctx = gl_ctx
    s60 = np.sqrt(0.75)
    normals = [[0, 0, 1, 0.5], [s60, 0, 0.5, 0.5], [0, 0, 1, 0.5], [0, 0, 1, 0.9]]
    materials = [[500, 0, 0.9, 1.5], [500, 0, 0.9, 1.5], [500, 0, 0.9, 1.5], [2000, 0.6, 0, 1]]
    refl = [np.array([10.0, 20.0, 30.0]), np.array([7.0, 8.0, 9.0]), np.array([4.0, 4.0, 4.0]),
            np.array([50.0, 60.0, 70.0])]
    refr = [np.array([100.0, 50.0, 25.0]), np.array([30.0, 20.0, 10.0])]
    effects = _texture(ctx, [[*c, 1.0] for c in (*refl, *refr)])  # reflection texels 0-3, refraction 4-5
    gbuffer = SimpleNamespace(normal=_texture(ctx, normals), position=_texture(ctx, [[0, 0, -1, 1]] * 4),
                              material=_texture(ctx, materials))
    surface = _texture(ctx, [[*SURFACE, 1.0]] * 4)
    points = np.array([[0, 0, 4], [1, 1, 5], [2, 2, -2], [3, 3, -1]], np.float32)
    out = read_texture(CompositePass(ctx).render(surface, effects, points, gbuffer, (0.0, 0.0, 0.0)), 3)[0]

    f0, t = 0.04, 0.9
    expected = [
        t * (f0 * refl[0] + (1 - f0) * refr[0]) + (1 - t) * SURFACE,
        t * (schlick(f0, 0.5) * refl[1] + (1 - schlick(f0, 0.5)) * refr[1]) + (1 - t) * SURFACE,
        t * refl[2] + (1 - t) * SURFACE,  # total internal reflection: F = 1
        0.6 * refl[3] + 0.4 * SURFACE,    # mirror: Schlick from R at normal incidence = R
    ]
    np.testing.assert_allclose(out, np.array(expected), rtol=1e-5)
    # by hand: 0.9·(0.04·10 + 0.96·100) + 0.1·1 (the old F·A + (1−F)·(T·B + (1−T)·S) gave 86.896)
    assert out[0] == pytest.approx([86.86, 44.12, 22.98], rel=1e-5)
