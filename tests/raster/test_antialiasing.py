"""Anti-aliasing: the FXAA post pass and jittered temporal accumulation on a static camera."""

import numpy as np
import pytest

from serenity.config import LPVConfig, RayTracingConfig, RenderConfig, SkyConfig
from serenity.errors import SerenityError
from serenity.frame import Renderer, halton
from serenity.raster.context import is_software
from serenity.scene.texture import texture_from_array

from .scenes import plane_scene

W, H = 64, 36
#: direct light only on a bare plane: every covered pixel has the same radiance, the background 0
QUICK = dict(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False), rt=RayTracingConfig(enabled=False))


def _plane_frame(**config):
    return Renderer(plane_scene(with_box=True), W, H, config=RenderConfig(**QUICK, **config))


def test_halton():
    assert [halton(i, 2) for i in range(4)] == [0.5, 0.25, 0.75, 0.125]
    assert halton(0, 3) == pytest.approx(1 / 3) and halton(1, 3) == pytest.approx(2 / 3)


def test_accumulation_converges_to_partial_coverage_on_a_static_camera(gl_ctx):
    r = _plane_frame()
    one = r.render_accumulated(1)
    assert np.array_equal(one.hdr, r.render().hdr)  # one sample = the ordinary, unjittered frame
    images = {n: r.render_accumulated(n).hdr for n in (2, 8, 16)}
    lum = {n: img.mean(-1) for n, img in images.items()}
    # convergence: 8 → 16 samples moves the image less than 2 → 16
    assert np.abs(lum[8] - lum[16]).mean() < 0.5 * np.abs(lum[2] - lum[16]).mean()
    # flat interiors keep their radiance; edge pixels get partial coverage, strictly between their sides
    flat = one.hdr.mean(-1)
    plane = np.median(flat[np.isfinite(one.aovs["depth"][..., 0])])
    steps = (lum[16] > 0.05 * plane) & (lum[16] < 0.95 * plane)
    assert steps.sum() >= W // 2  # the plane's far edge against the black background, at least
    interior = np.abs(flat - plane) < 1e-3 * plane
    interior &= np.roll(interior, 1, 0) & np.roll(interior, -1, 0) & np.roll(interior, 1, 1) & np.roll(interior, -1, 1)
    assert np.allclose(lum[16][interior], plane, rtol=2e-2)
    with pytest.raises(SerenityError, match="samples"):
        r.render_accumulated(0)


def test_fxaa_blends_edges_and_leaves_flat_areas(gl_ctx):
    plain = _plane_frame().render()
    fxaa = _plane_frame(antialiasing="fxaa").render()
    a, b = plain.hdr.mean(-1), fxaa.hdr.mean(-1)
    changed = np.abs(a - b) > 1e-3 * a.max()
    assert changed.any() and "anti-aliasing" in fxaa.timings
    # only pixels on or next to a contrast step change (the 3x3 neighbourhood spans lumaMax - lumaMin)
    span = np.zeros_like(a)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            span = np.maximum(span, np.abs(np.roll(np.roll(a, dy, 0), dx, 1) - a))
    assert not (changed & (span < 1e-3 * a.max())).any()
    # blends stay within the local range of the unfiltered image
    lo = np.minimum.reduce([np.roll(np.roll(a, dy, 0), dx, 1) for dy in (-2, -1, 0, 1, 2) for dx in (-2, -1, 0, 1, 2)])
    hi = np.maximum.reduce([np.roll(np.roll(a, dy, 0), dx, 1) for dy in (-2, -1, 0, 1, 2) for dx in (-2, -1, 0, 1, 2)])
    inner = (slice(2, -2), slice(2, -2))
    assert np.all(b[inner] >= lo[inner] - 1e-3 * a.max()) and np.all(b[inner] <= hi[inner] + 1e-3 * a.max())


def test_bad_antialiasing_setting():
    with pytest.raises(SerenityError, match="antialiasing"):
        RenderConfig(antialiasing="msaa")


def test_shader_anisotropic_filtering_is_closer_to_supersampling_at_grazing_angles(gl_ctx):
    if not is_software(gl_ctx):
        pytest.skip("hardware GL filters textures anisotropically (raster/context.anisotropy): the shader's "
                    "taps stand in for that on software rasterisers only")
    # a fine checker (4 texels per square) on the 40 m plane seen at ~25-40 deg from grazing: GL's isotropic
    # LOD blurs the far rows to grey; N taps along the footprint's long axis keep what a 4x4-supersampled
    # frame (each sample's footprint 4x smaller, then box-averaged) still resolves
    i = np.arange(256)
    checker = (((i[:, None] // 4) + (i[None, :] // 4)) % 2).astype(np.float32)
    tex = texture_from_array(np.repeat(checker[..., None], 3, -1) * 0.8 + 0.1, "checker")
    scene = plane_scene()
    scene.materials[0].albedo_texture = tex

    def albedo(taps, scale=1):
        cfg = RenderConfig(texture_taps=taps, **QUICK)
        a = Renderer(scene, W * scale, H * scale, config=cfg).render().aovs["albedo"][..., 1]
        return a.reshape(H, scale, W, scale).mean((1, 3))

    ref = albedo(1, scale=4)
    far = slice(2, H // 2)  # the grazing half of the plane (top rows), away from the far edge
    err = {taps: float(np.abs(albedo(taps)[far] - ref[far]).mean()) for taps in (1, 4)}
    assert err[4] < 0.8 * err[1], err
