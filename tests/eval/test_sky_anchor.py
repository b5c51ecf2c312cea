"""The sky anchor's frame conversion (benchmarks/bench_sky_anchor.py): Mitsuba's sunsky is z-up, ours y-up."""

import importlib.util
import math
import os

import numpy as np
import pytest

from serenity.scene.model import direction_from_angles

pytest.importorskip("mitsuba")
_PATH = os.path.join(os.path.dirname(__file__), "..", "..", "benchmarks", "bench_sky_anchor.py")


@pytest.fixture(scope="module")
def anchor():
    spec = importlib.util.spec_from_file_location("bench_sky_anchor", _PATH)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_mitsuba_sky_in_our_frame(anchor):
    el = 30.0
    sun = direction_from_angles(el, 0.0)
    away = direction_from_angles(el, 180.0)
    near_sun = (sun + [0, 0.05, 0]) / np.linalg.norm(sun + [0, 0.05, 0])
    dirs = np.array([[0.0, 1.0, 0.0], sun, away, [0.0, -0.5, 0.866], near_sun])
    rad, sun_e = anchor.mitsuba_sky(sun, dirs, 3.0)
    lum = rad @ anchor.LUM
    assert lum[3] == 0.0  # below our horizon: no sky
    assert lum[4] > lum[2] and lum[4] > lum[0]  # the aureole is around our sun, not opposite it
    # the sun's horizontal irradiance is its normal irradiance × sin(elevation): compare two elevations
    _, sun_hi = anchor.mitsuba_sky(direction_from_angles(80.0, 0.0), dirs[:1], 3.0)
    ratio = (sun_e @ anchor.LUM) / (sun_hi @ anchor.LUM)
    assert 0.2 < ratio < math.sin(math.radians(el)) / math.sin(math.radians(80.0)) + 0.01
