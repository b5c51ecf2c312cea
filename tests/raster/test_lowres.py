"""Reduced-resolution views of the G-buffer (raster/lowres.py): the strided samples the LPV's sky
VPLs read back are exactly the G-buffer's pixels, and the guide holds each low-res texel's
representative normal and view depth."""

from __future__ import annotations

import numpy as np
import pytest

from serenity.config import RenderConfig
from serenity.frame import Renderer
from serenity.raster.context import low_res_size
from serenity.raster.interop import read_texture
from serenity.raster.lowres import GBufferSamples, LowResGuide
from serenity.scene import load

pytestmark = pytest.mark.gl


@pytest.fixture(scope="module")
def frame():
    r = Renderer(load("courtyard"), 203, 117, config=RenderConfig(ray_tracing=False))
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
    got = read_texture(guide.render(gbuf, cam.position, cam.forward), 4)
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
    g = read_texture(guide.render(gbuf, cam.position, cam.forward), 4)
    h, w = g.shape[:2]
    depth = np.frombuffer(guide.depth.read(), dtype=np.float32).reshape(h, w)[::-1]  # image rows, top first
    nrm = read_texture(gbuf.normal, 4)
    rows = frame.height - 1 - np.minimum(np.arange(h)[::-1] * 2 + 1, frame.height - 1)
    cols = np.minimum(np.arange(w) * 2 + 1, frame.width - 1)
    ks = nrm[rows][:, cols, 3]
    background = g[..., 3] < 0
    glossy = ~background & (ks >= 0.1)
    assert background.any() and glossy.any() and (~background & ~glossy).any()
    assert np.all(depth[background] == 1.0)
    assert np.allclose(depth[glossy], 0.25, atol=1e-6) and np.allclose(depth[~background & ~glossy], 0.5, atol=1e-6)
