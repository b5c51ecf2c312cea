"""The reference's noise floor: FLIP and relMSE between two independent half-sample renders,
stored with the cached reference; it shrinks as the samples grow, and reference_for_error doubles
the samples until it is at most a quarter of the error being measured, or says it could not."""

import glob
import json
import os
import warnings

import numpy as np
import pytest

from serenity.errors import SerenityError
from serenity.eval import reference as R
from serenity.scene import build_scene

pytest.importorskip("mitsuba")
pytest.importorskip("flip_evaluator")

W, H = 16, 16


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


def test_the_halves_differ_and_the_floor_is_stored_with_the_reference():
    s = build_scene("cornell")
    ref = R.reference_with_floor(s, W, H, spp=8, progress=False)
    a, b = ref.halves
    assert ref.spp == 8 and ref.image.shape == (H, W, 3)
    assert not np.array_equal(a, b) and np.abs(a - b).mean() > 0.01 * a.mean()  # independent seeds
    assert np.allclose(ref.image, (a + b) / 2)
    assert ref.floor["flip"] > 0 and ref.floor["rel_mse"] > 0
    stored = glob.glob(os.path.join(R.cache_dir(), "*.floor.json"))
    assert len(stored) == 1
    with open(stored[0]) as f:
        record = json.load(f)
    assert record["spp"] == 8 and record["scene"] == "cornell" and record["floor"] == pytest.approx(ref.floor)
    again = R.reference_with_floor(s, W, H, spp=8, progress=False)
    assert again.floor == pytest.approx(ref.floor) and np.array_equal(again.image, ref.image)
    with pytest.raises(SerenityError, match="even spp"):
        R.reference_with_floor(s, W, H, spp=7, progress=False)


def test_the_floor_shrinks_as_the_samples_grow():
    s = build_scene("cornell")
    floors = [R.reference_with_floor(s, W, H, spp=n, progress=False).floor for n in (4, 32, 256)]
    for lo, hi in zip(floors[1:], floors[:-1], strict=True):
        assert lo["rel_mse"] < 0.5 * hi["rel_mse"] and lo["flip"] < hi["flip"]


def test_reference_for_error_doubles_until_a_quarter_of_the_error():
    s = build_scene("cornell")
    start = R.reference_with_floor(s, W, H, spp=4, progress=False).floor
    target = start["rel_mse"]  # four times the floor at 4 spp needs about 16 spp or more
    ref = R.reference_for_error(s, W, H, rel_mse=target, spp=4, max_spp=1024, progress=False)
    assert ref.converged and ref.message == ""
    assert ref.floor["rel_mse"] <= target / 4 and ref.spp > 4
    # each half is a sum of cached blocks of 2, 2, 4, 8... spp: the 4-spp render's blocks were reused
    npys = glob.glob(os.path.join(R.cache_dir(), "*.npy"))
    assert len(npys) == 2 * (int(np.log2(ref.spp // 4)) + 1)
    # one step fewer would not have done: the loop stops at the first level that reaches the target
    with pytest.warns(UserWarning, match="rel_mse floor"):
        prev = R.reference_for_error(s, W, H, rel_mse=target, spp=4, max_spp=ref.spp // 2, progress=False)
    assert not prev.converged and prev.spp == ref.spp // 2 and prev.floor["rel_mse"] > target / 4
    assert len(glob.glob(os.path.join(R.cache_dir(), "*.npy"))) == len(npys)  # all from the cache
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        hopeless = R.reference_for_error(s, W, H, flip=1e-6, spp=4, max_spp=16, progress=False)
    assert not hopeless.converged and hopeless.spp == 16
    assert "'cornell'" in hopeless.message and "flip floor" in hopeless.message and "16 spp" in hopeless.message
    assert any(hopeless.message == str(x.message) for x in w)
    with pytest.raises(SerenityError, match="error being measured"):
        R.reference_for_error(s, W, H)
