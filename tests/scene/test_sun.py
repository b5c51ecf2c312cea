"""Solar position against published references, and time parsing."""

from datetime import datetime, timedelta, timezone

import numpy as np
import pytest

from serenity.errors import SceneError
from serenity.scene.model import direction_from_angles
from serenity.scene.sun import parse_time, solar_position, sun_from_time


def test_nrel_spa_reference_case():
    """Reda & Andreas, *Solar Position Algorithm for Solar Radiation Applications* (NREL 2004/2008),
    Table A4.1: 2003-10-17 12:30:30 at UTC-7, 39.742476 N 105.1786 W → topocentric zenith 50.11162°,
    azimuth 194.34024° (east of north). NOAA's algorithm must agree within 0.2° (its stated accuracy
    is ~0.01°; SPA uses 820 hPa and 11 °C, NOAA's refraction standard conditions, ~0.01° apart)."""
    when = datetime(2003, 10, 17, 12, 30, 30, tzinfo=timezone(timedelta(hours=-7)))
    elev, az = solar_position(when, 39.742476, -105.1786)
    assert abs(elev - (90.0 - 50.11162)) < 0.2
    assert abs(az - 194.34024) < 0.2


def test_june_solstice_noon_on_the_equator():
    """At solar noon on the June solstice the sun stands 90° − 23.44° above the northern horizon at
    the equator (declination = obliquity), geometric elevation without refraction."""
    best = max((solar_position(datetime(2024, 6, 20, 12, 0, tzinfo=timezone.utc) + timedelta(minutes=m), 0.0, 0.0,
                               refraction=False) for m in range(-30, 31)), key=lambda p: p[0])
    assert abs(best[0] - (90.0 - 23.44)) < 0.2
    assert abs(best[1] - 0.0) < 1.0 or abs(best[1] - 360.0) < 1.0


def test_direction_convention_matches_angles():
    """Azimuth clockwise from north: 90° is east (+x), 180° is south (+z); y is up."""
    np.testing.assert_allclose(direction_from_angles(0.0, 90.0), [1, 0, 0], atol=1e-12)
    np.testing.assert_allclose(direction_from_angles(0.0, 180.0), [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(direction_from_angles(90.0, 0.0), [0, 1, 0], atol=1e-12)


def test_night_sun_is_below_horizon():
    sun = sun_from_time("2024-06-21 23:30 +01:00", 38.72, -9.14)
    assert not sun.is_up and sun.elevation_deg < 0


@pytest.mark.parametrize("text", ["2026-13-01 12:00", "2026-02-30 10:00", "2026-06-01 24:00", "2026-06-01 12:60",
                                  "2026-06-01 12:00 +15:00", "tomorrow", ""])
def test_impossible_times_raise_one_line_scene_errors(text):
    with pytest.raises(SceneError) as e:
        parse_time(text)
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("lat, lon", [(91.0, 0.0), (0.0, 181.0), (float("nan"), 0.0)])
def test_impossible_places_raise(lat, lon):
    with pytest.raises(SceneError):
        sun_from_time("2024-06-21 12:00", lat, lon)
