"""Metrics on synthetic images whose error is known analytically."""

import numpy as np
import pytest

from serenity.errors import SerenityError
from serenity.eval import metrics as M

pytest.importorskip("flip_evaluator")


@pytest.fixture
def ref():
    rng = np.random.default_rng(0)
    return rng.uniform(5.0, 80.0, (40, 64, 3)).astype(np.float32)


def test_identical_images_have_zero_error(ref):
    assert M.rel_mse(ref, ref) == 0.0
    assert M.flip(ref, ref) == 0.0


def test_rel_mse_of_constant_offset_is_analytic(ref):
    c = 3.0
    b = ref.astype(np.float64)
    expect = np.mean(c * c / (b * b + M.REL_MSE_EPS), axis=(0, 1))
    got = M.rel_mse_per_channel(ref + c, ref)
    assert np.allclose(got, expect, rtol=1e-6)
    assert M.rel_mse(ref + c, ref) == pytest.approx(expect.mean(), rel=1e-6)


def test_rel_mse_of_relative_scale_and_epsilon():
    ref = np.full((8, 8, 3), 10.0, np.float32)
    # a 10% error everywhere -> 0.01 * 100 / (100 + eps)
    assert M.rel_mse(ref * 1.1, ref) == pytest.approx(0.01 * 100 / (100 + 1e-2), rel=1e-5)
    # a black reference: (a - 0)^2 / eps
    zero = np.zeros((4, 4, 3), np.float32)
    assert M.rel_mse(zero + 0.1, zero) == pytest.approx(0.01 / M.REL_MSE_EPS, rel=1e-5)


def test_rel_mse_trim_drops_the_worst_pixels(ref):
    img = ref.copy()
    img[0, 0] = 1e4  # one light leak
    assert M.rel_mse(img, ref) > 10.0
    assert M.rel_mse(img, ref, trim=1e-3) == 0.0
    assert M.rel_mse(ref + 3.0, ref, trim=1e-3) == pytest.approx(M.rel_mse(ref + 3.0, ref), rel=0.01)


def test_mask_restricts_both_metrics(ref):
    img = ref.copy()
    img[:, 32:] *= 3.0  # error on the right half only
    left = np.zeros(ref.shape[:2], bool)
    left[:, :32] = True
    assert M.rel_mse(img, ref, mask=left) == 0.0
    assert M.rel_mse(img, ref, mask=~left) == pytest.approx(4.0, rel=1e-3)
    whole = M.flip(img, ref)
    # the FLIP filters see across the border, so the left half is not exactly 0, but far below the right
    assert M.flip(img, ref, mask=left) < 0.2 * M.flip(img, ref, mask=~left)
    assert M.flip(img, ref, mask=left) < whole < M.flip(img, ref, mask=~left)


def test_flip_grows_with_the_error_and_sees_the_tone_map(ref):
    errs = [M.flip(ref * s, ref) for s in (1.0, 1.02, 1.1, 1.5, 3.0)]
    assert errs[0] == 0.0
    assert np.all(np.diff(errs) > 0)
    # an exposure so low that both tone-map to black: nothing to see
    assert M.flip(ref * 3.0, ref, exposure=1e-8) == 0.0


def test_flip_map_and_png(ref):
    m = M.flip_map(ref * 1.5, ref)
    assert m.shape == ref.shape[:2] and m.dtype == np.float32
    assert 0.0 <= m.min() and m.max() <= 1.0
    png = M.flip_png(m)
    assert png.shape == (*ref.shape[:2], 3) and png.dtype == np.uint8


def test_compare_returns_everything(ref):
    r = M.compare(ref + 1.0, ref)
    assert set(r) == {"rel_mse", "rel_mse_rgb", "flip", "flip_map"}
    assert len(r["rel_mse_rgb"]) == 3 and r["flip"] > 0


def test_bad_inputs_are_one_line_errors(ref):
    with pytest.raises(SerenityError, match="shape mismatch"):
        M.rel_mse(ref[:10], ref)
    with pytest.raises(SerenityError, match="NaN"):
        M.rel_mse(np.full_like(ref, np.nan), ref)
    with pytest.raises(SerenityError, match="no pixels"):
        M.rel_mse(ref, ref, mask=np.zeros(ref.shape[:2], bool))


def test_depth_edges_and_iou():
    d = np.full((20, 30), 10.0)
    d[5:15, 10:20] = 5.0  # a box in front
    d[:, 25:] = np.inf  # background
    e = M.depth_edges(d)
    assert e[5, 12] and e[4, 12] and e[10, 9] and e[10, 10] and e[3, 24] and e[3, 25]
    assert not e[10, 15] and not e[0, 0]
    assert M.edge_iou(d, d) == 1.0
    shifted = np.roll(d, 1, axis=1)
    assert M.edge_iou(d, shifted) < 0.6
