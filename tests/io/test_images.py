import numpy as np
import pytest

from serenity.errors import SerenityError
from serenity.io.exr import read_exr, write_exr
from serenity.io.png import read_png, write_png


def test_exr_layers_round_trip_exactly(tmp_path):
    rng = np.random.default_rng(1)
    layers = {
        "beauty": rng.random((5, 7, 3), dtype=np.float32) * 1e4,
        "depth": np.full((5, 7, 1), np.inf, np.float32),
        "albedo": rng.random((5, 7, 3), dtype=np.float32),
        "rgba": rng.random((5, 7, 4), dtype=np.float32),
    }
    path = str(tmp_path / "x.exr")
    write_exr(path, layers)
    back = read_exr(path)
    assert set(back) == set(layers)
    for k, v in layers.items():
        np.testing.assert_array_equal(back[k], v)


def test_exr_errors_name_the_file(tmp_path):
    bad = tmp_path / "bad.exr"
    bad.write_bytes(b"not an exr")
    with pytest.raises(SerenityError, match="bad.exr"):
        read_exr(str(bad))
    with pytest.raises(SerenityError, match="missing.exr"):
        read_exr(str(tmp_path / "missing.exr"))
    with pytest.raises(SerenityError, match="shape"):
        write_exr(str(tmp_path / "y.exr"), {"beauty": np.zeros((2, 2, 3)), "a": np.zeros((3, 2, 3))})


def test_png_round_trip(tmp_path):
    img = (np.arange(4 * 6 * 3) % 256).astype(np.uint8).reshape(4, 6, 3)
    path = str(tmp_path / "a.png")
    write_png(path, img)
    np.testing.assert_array_equal(read_png(path), img)
    with pytest.raises(SerenityError, match="uint8"):
        write_png(path, img.astype(np.float32))
