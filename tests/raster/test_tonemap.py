import numpy as np

from serenity.colour import linear_to_srgb, reinhard, reinhard_srgb
from serenity.raster.interop import upload_texture
from serenity.raster.tonemap import TonemapPass


def test_reinhard_known_values():
    # luminance 1 after exposure -> 0.5 display; grey stays grey
    out = reinhard(np.full((1, 1, 3), 50.0), 0.02)
    assert np.allclose(out, 0.5)
    assert np.allclose(reinhard(np.zeros((2, 2, 3)), 1.0), 0.0)
    big = reinhard(np.full((1, 1, 3), 1e9), 1.0)
    assert np.all(big <= 1.0) and np.all(big > 0.999)


def test_srgb_encode_known_values():
    assert np.allclose(linear_to_srgb(np.array([0.0, 1.0, 0.0031308])), [0.0, 1.0, 0.0404500], atol=1e-6)
    assert abs(float(linear_to_srgb(np.array(0.214041))) - 0.5) < 1e-4


def test_gl_tonemap_matches_numpy_twin(gl_ctx):
    rng = np.random.default_rng(1)
    hdr = (rng.random((16, 24, 3)) ** 4 * 2000).astype(np.float32)
    tex = upload_texture(gl_ctx, hdr)
    tp = TonemapPass(gl_ctx)
    tp.resize(24, 16)
    tp.render(tex, 0.02)
    diff = np.abs(tp.read().astype(int) - reinhard_srgb(hdr, 0.02).astype(int))
    assert diff.max() <= 1
    tex.release()


def test_gl_tonemap_counts_nonfinite_pixels(gl_ctx):
    hdr = np.ones((16, 24, 3), np.float32)
    hdr[2, 3, 0] = np.nan
    hdr[5, 7, 2] = np.inf
    hdr[9, 1, :] = -np.inf
    hdr[11, 20] = [np.nan, np.inf, 1.0]  # one pixel, counted once
    tex = upload_texture(gl_ctx, hdr)
    tp = TonemapPass(gl_ctx)
    tp.resize(24, 16)
    tp.render(tex, 0.02)
    assert tp.nonfinite_pixels() == 4
    tex.write(np.ones((16, 24, 3), np.float32).tobytes())  # the counter restarts with every pass
    tp.render(tex, 0.02)
    assert tp.nonfinite_pixels() == 0
    tex.release()
