"""Reduced-resolution views of the G-buffer (raster/lowres.py): the strided samples the LPV's sky
VPLs read back are exactly the G-buffer's pixels, and the guide holds each low-res texel's
representative normal and view depth; the low-res images' padded layout (raster/context.LowResLayout)
centres them on the rasteriser's tiles and changes no pixel of the frame."""

from __future__ import annotations

import numpy as np
import pytest

from serenity.config import RayTracingConfig, RenderConfig, ScheduleConfig
from serenity.frame import Renderer
from serenity.raster.context import RASTER_TILE, LowResLayout, low_res_layout, low_res_size
from serenity.raster.interop import read_texture
from serenity.raster.lowres import GBufferSamples, LowResGuide
from serenity.scene import load

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def frame():
    r = Renderer(load("courtyard"), 203, 117, config=RenderConfig(rt=RayTracingConfig(enabled=False)))
    r.render(read_back=False)
    yield r
    r.close()


@pytest.mark.parametrize("stride", [1, 3, 8])
def test_samples_are_the_strided_gbuffer_pixels(gl_ctx, frame, stride):
    gbuf = frame.outputs["gbuffer"]
    g = GBufferSamples(frame.ctx, stride)
    g.resize(frame.width, frame.height)
    got = g.read(gbuf)
    c = stride // 2
    for name in GBufferSamples.NAMES:
        want = read_texture(getattr(gbuf, name), 4)[c::stride, c::stride]
        assert got[name].shape == want.shape
        assert np.array_equal(got[name], want), name


@pytest.mark.parametrize("scale", [1, 2, 4])
def test_guide_is_the_representatives_normal_and_depth(gl_ctx, frame, scale):
    gbuf, cam = frame.outputs["gbuffer"], frame.scene.camera
    guide = LowResGuide(frame.ctx, scale)
    guide.resize(frame.width, frame.height)
    got = guide.layout.crop(read_texture(guide.render(gbuf, cam.position, cam.forward), 4))
    assert got.shape[:2] == low_res_size(frame.width, frame.height, scale)[::-1]
    pos, nrm = read_texture(gbuf.position, 4), read_texture(gbuf.normal, 4)
    # representative of low-res texel (i, j) (GL, bottom-up): full pixel min(i·s + s/2, size − 1)
    h, w = frame.height, frame.width
    gl_rows = np.minimum(np.arange(got.shape[0])[::-1] * scale + scale // 2, h - 1)  # GL row of each image row
    cols = np.minimum(np.arange(got.shape[1]) * scale + scale // 2, w - 1)
    rows = h - 1 - gl_rows
    p, n = pos[rows][:, cols], nrm[rows][:, cols]
    covered = p[..., 3] > 0
    z = (p[..., :3] - cam.position) @ cam.forward
    assert np.all(got[~covered, 3] == -1.0)
    assert np.allclose(got[covered, 3], z[covered], rtol=1e-5, atol=1e-5)
    assert np.array_equal(got[covered, :3], n[covered, :3])


def test_guide_depth_holds_each_texels_class(gl_ctx, frame):
    # glsl/lowres.glsl: background 1, k_s >= 0.1 (the glossy LPV term's pixels) 0.25, other surfaces 0.5
    gbuf, cam = frame.outputs["gbuffer"], frame.scene.camera
    guide = LowResGuide(frame.ctx, 2)
    guide.resize(frame.width, frame.height)
    lay = guide.layout
    g = lay.crop(read_texture(guide.render(gbuf, cam.position, cam.forward), 4))
    h, w = g.shape[:2]
    tw, th = lay.texture_size
    depth = lay.crop(np.frombuffer(guide.depth.read(), dtype=np.float32).reshape(th, tw)[::-1])  # top row first
    nrm = read_texture(gbuf.normal, 4)
    rows = frame.height - 1 - np.minimum(np.arange(h)[::-1] * 2 + 1, frame.height - 1)
    cols = np.minimum(np.arange(w) * 2 + 1, frame.width - 1)
    ks = nrm[rows][:, cols, 3]
    background = g[..., 3] < 0
    glossy = ~background & (ks >= 0.1)
    assert background.any() and glossy.any() and (~background & ~glossy).any()
    assert np.all(depth[background] == 1.0)
    assert np.allclose(depth[glossy], 0.25, atol=1e-6) and np.allclose(depth[~background & ~glossy], 0.5, atol=1e-6)


@pytest.mark.parametrize(("width", "height", "scale"), [(320, 180, 4), (640, 360, 4), (203, 117, 2), (1280, 720, 2)])
def test_layout_centres_the_image_on_the_tiles(width, height, scale):
    lay = low_res_layout(width, height, scale)
    assert lay.size == low_res_size(width, height, scale)
    for n, o, t in zip(lay.size, lay.origin, lay.texture_size, strict=True):
        tiles = -(-n // RASTER_TILE)
        assert -(-t // RASTER_TILE) == tiles  # no tile added
        first, last = RASTER_TILE - o, (o + n) - (tiles - 1) * RASTER_TILE  # texels in the end tiles
        assert tiles == 1 or abs(first - last) <= 1
    assert lay.origin == (24, 9) if (width, height, scale) == (320, 180, 4) else True
    assert low_res_layout(width, height, scale, balance=False) == LowResLayout(lay.size)
    assert low_res_layout(width, height, 1) == LowResLayout((width, height))
    img = np.arange(lay.texture_size[0] * lay.texture_size[1]).reshape(lay.texture_size[::-1])
    crop = lay.crop(img)  # top row first: GL row origin_y + size_y - 1 .. origin_y
    assert crop.shape == lay.size[::-1]
    assert crop[-1, 0] == img[img.shape[0] - 1 - lay.origin[1], lay.origin[0]]


@pytest.mark.parametrize("preset", ["lpv-fast", "lpv"])
def test_padded_layout_changes_no_pixel(gl_ctx, preset):
    """The SSAO, the guide and the indirect light drawn into padded targets (the default) give the
    frame of unpadded ones, bit for bit: each pass reads and writes the image's texels only."""
    images = {}
    for balance in (True, False):
        r = Renderer(load("courtyard"), 320, 180,
                     config=RenderConfig.preset(preset, rt={"enabled": False}, indirect={"tile_balance": balance},
                                                schedule=ScheduleConfig(overlap=False)))
        try:
            r.render(read_back=False)
            f = r.render(read_back=("hdr", "aovs"))
            assert (r.lowres.layout.origin != (0, 0)) == balance
            images[balance] = f.hdr, f.aovs["ao"]
        finally:
            r.close()
    assert np.array_equal(images[True][0], images[False][0])
    assert np.array_equal(images[True][1], images[False][1])
