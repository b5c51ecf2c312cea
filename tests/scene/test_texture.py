"""sRGB decoding and mip chains of albedo textures."""

import numpy as np
import pytest
from PIL import Image

from serenity.colour import linear_to_srgb, srgb_to_linear
from serenity.errors import SceneError
from serenity.scene.texture import build_mips, load_texture, texture_from_array


def test_srgb_transfer_known_values_and_inverse():
    # IEC 61966-2-1: 0.5 encoded is 0.2140 linear; the linear toe below 0.04045
    np.testing.assert_allclose(srgb_to_linear(np.array([0.0, 0.04045, 0.5, 1.0])),
                               [0.0, 0.04045 / 12.92, 0.21404114, 1.0], rtol=1e-6)
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(linear_to_srgb(srgb_to_linear(x)), x, atol=1e-9)


def test_mip_chain_is_complete_and_box_filtered():
    rng = np.random.default_rng(0)
    img = rng.random((64, 32, 3)).astype(np.float32)
    mips = build_mips(img)
    assert [m.shape[:2] for m in mips] == [(64 >> k, max(1, 32 >> k)) for k in range(7)]
    np.testing.assert_allclose(mips[1][3, 5], img[6:8, 10:12].mean(axis=(0, 1)), rtol=1e-5)
    np.testing.assert_allclose(mips[-1][0, 0], img.mean(axis=(0, 1)), rtol=1e-4)  # power-of-two: exact mean


def test_loaded_png_is_decoded_to_linear(tmp_path):
    px = np.array([[[128, 64, 255], [0, 10, 200]]], dtype=np.uint8)
    path = tmp_path / "a.png"
    Image.fromarray(px).save(path)
    tex = load_texture(path)
    np.testing.assert_allclose(tex.mips[0], srgb_to_linear(px / 255.0), rtol=1e-6)
    assert tex.mips[-1].shape[:2] == (1, 1)


def test_texture_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"\x89PNG not really")
    with pytest.raises(SceneError, match="bad.png"):
        load_texture(bad)
    with pytest.raises(SceneError, match="gone.png"):
        load_texture(tmp_path / "gone.png")
    with pytest.raises(SceneError, match="NaN"):
        texture_from_array(np.full((2, 2, 3), np.nan, np.float32), name="x")
