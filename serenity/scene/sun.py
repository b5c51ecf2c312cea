"""The sun's position from a date, time and place (NOAA's solar-position algorithm).

The equations are those of NOAA's Solar Calculator (after Meeus, *Astronomical Algorithms*):
Julian day → Julian century T → geometric mean longitude L0 and mean anomaly M → equation of the
centre C → true and apparent longitude λ (nutation/aberration term with Ω) → mean and corrected
obliquity ε → declination δ, equation of time → true solar time → hour angle H → zenith and
azimuth. Stated accuracy ≈ 0.01° for dates within a few centuries of 2000 (ΔT = TT − UT is
ignored, ~0.0005°).

Atmospheric refraction: by default the returned elevation is the *apparent* one (what is seen,
as the NOAA calculator reports), using NOAA's piecewise refraction approximation for standard
conditions (1010 hPa, 10 °C): about +0.57° at the horizon, +0.03° at 60°, zero above 85°.
``refraction=False`` returns the geometric (airless) elevation.

Conventions: elevation in degrees above the horizon; azimuth in degrees clockwise from north
(0 = north, 90 = east), as :func:`serenity.scene.model.direction_from_angles` expects.

Times: a timezone-aware ``datetime`` is used as is. A naive one is local time with
``utc_offset_hours`` when given, otherwise the *nautical* time zone of the longitude,
``round(longitude / 15)`` hours (civil zones and daylight saving differ: give an offset, e.g.
``parse_time("2024-06-21 15:00 +01:00")``, to be exact).
"""

from __future__ import annotations

import calendar
import math
import re
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone

import numpy as np

from serenity.errors import SceneError
from serenity.scene.model import Sun, direction_from_angles

__all__ = [
    "DEFAULT_LOCATION",
    "DEFAULT_TIME",
    "SolarPosition",
    "julian_day",
    "parse_time",
    "solar_position",
    "solar_position_details",
    "sun_from_time",
]

#: Lisbon (the paper's home): latitude, longitude in degrees (north, east positive)
DEFAULT_LOCATION = (38.72, -9.14)
#: a summer afternoon in Lisbon (WEST = UTC+1)
DEFAULT_TIME = "2024-06-21 16:00 +01:00"

_J2000 = datetime(2000, 1, 1, 12, 0, 0, tzinfo=timezone.utc)  # JD 2451545.0


@dataclass(frozen=True)
class SolarPosition:
    """Everything the algorithm computes for one instant and place (degrees unless stated)."""

    elevation_deg: float  # apparent when refraction was applied, else geometric
    azimuth_deg: float  # clockwise from north
    zenith_deg: float  # 90 - elevation_deg
    declination_deg: float
    equation_of_time_min: float  # apparent minus mean solar time, minutes
    hour_angle_deg: float  # negative before solar noon
    refraction_deg: float  # added to the geometric elevation (0 when disabled)
    julian_day: float


def _check_place(latitude_deg, longitude_deg) -> tuple[float, float]:
    try:
        lat, lon = float(latitude_deg), float(longitude_deg)
    except (TypeError, ValueError):
        raise SceneError(f"latitude/longitude must be numbers, got {latitude_deg!r}, {longitude_deg!r}") from None
    if not (math.isfinite(lat) and -90.0 <= lat <= 90.0):
        raise SceneError(f"latitude {latitude_deg} is outside [-90, 90] degrees")
    if not (math.isfinite(lon) and -180.0 <= lon <= 180.0):
        raise SceneError(f"longitude {longitude_deg} is outside [-180, 180] degrees")
    return lat, lon


def _to_utc(when: datetime, longitude_deg: float, utc_offset_hours: float | None) -> datetime:
    if not isinstance(when, datetime):
        raise SceneError(f"a time must be a datetime, got {type(when).__name__}")
    if when.tzinfo is not None and when.utcoffset() is not None:
        if utc_offset_hours is not None:
            raise SceneError("give either a timezone-aware time or utc_offset_hours, not both")
        return when.astimezone(timezone.utc)
    if utc_offset_hours is None:
        utc_offset_hours = float(round(longitude_deg / 15.0))
    if not (math.isfinite(utc_offset_hours) and -14.0 <= utc_offset_hours <= 14.0):
        raise SceneError(f"UTC offset {utc_offset_hours} h is outside [-14, 14] hours")
    return (when - timedelta(hours=utc_offset_hours)).replace(tzinfo=timezone.utc)


def julian_day(when_utc: datetime) -> float:
    """Julian day of a timezone-aware datetime (UT)."""
    return 2451545.0 + (when_utc - _J2000).total_seconds() / 86400.0


def _refraction_deg(elevation_deg: float) -> float:
    """NOAA's approximation of atmospheric refraction (degrees) at a geometric elevation."""
    e = elevation_deg
    if e > 85.0:
        return 0.0
    te = math.tan(math.radians(e))
    if e > 5.0:
        arcsec = 58.1 / te - 0.07 / te**3 + 0.000086 / te**5
    elif e > -0.575:
        arcsec = 1735.0 + e * (-518.2 + e * (103.4 + e * (-12.79 + e * 0.711)))
    else:
        arcsec = -20.772 / te
    return arcsec / 3600.0


def solar_position_details(when: datetime, latitude_deg: float, longitude_deg: float, *,
                           utc_offset_hours: float | None = None, refraction: bool = True) -> SolarPosition:
    """The full NOAA computation for ``when`` at (latitude, longitude) — see the module docstring."""
    lat, lon = _check_place(latitude_deg, longitude_deg)
    utc = _to_utc(when, lon, utc_offset_hours)
    jd = julian_day(utc)
    t = (jd - 2451545.0) / 36525.0  # Julian century

    l0 = (280.46646 + t * (36000.76983 + t * 0.0003032)) % 360.0  # geometric mean longitude
    m = 357.52911 + t * (35999.05029 - 0.0001537 * t)  # geometric mean anomaly
    e = 0.016708634 - t * (0.000042037 + 0.0000001267 * t)  # eccentricity of Earth's orbit
    mr = math.radians(m)
    c = (math.sin(mr) * (1.914602 - t * (0.004817 + 0.000014 * t))
         + math.sin(2 * mr) * (0.019993 - 0.000101 * t)
         + math.sin(3 * mr) * 0.000289)  # equation of the centre
    true_long = l0 + c
    omega = math.radians(125.04 - 1934.136 * t)
    app_long = true_long - 0.00569 - 0.00478 * math.sin(omega)  # apparent longitude
    eps0 = 23.0 + (26.0 + (21.448 - t * (46.815 + t * (0.00059 - t * 0.001813))) / 60.0) / 60.0
    eps = math.radians(eps0 + 0.00256 * math.cos(omega))  # corrected obliquity
    decl = math.asin(math.sin(eps) * math.sin(math.radians(app_long)))

    y = math.tan(eps / 2) ** 2
    l0r = math.radians(l0)
    eot = 4.0 * math.degrees(
        y * math.sin(2 * l0r) - 2 * e * math.sin(mr) + 4 * e * y * math.sin(mr) * math.cos(2 * l0r)
        - 0.5 * y * y * math.sin(4 * l0r) - 1.25 * e * e * math.sin(2 * mr))  # minutes

    minutes_utc = utc.hour * 60.0 + utc.minute + (utc.second + utc.microsecond * 1e-6) / 60.0
    true_solar_time = (minutes_utc + eot + 4.0 * lon) % 1440.0
    hour_angle = true_solar_time / 4.0 - 180.0  # degrees, negative in the morning

    phi, h = math.radians(lat), math.radians(hour_angle)
    cos_zen = math.sin(phi) * math.sin(decl) + math.cos(phi) * math.cos(decl) * math.cos(h)
    zen = math.degrees(math.acos(max(-1.0, min(1.0, cos_zen))))
    # azimuth from north, clockwise (Meeus' south-based form + 180°); well defined except at the poles' zenith
    az = math.degrees(math.atan2(math.sin(h), math.cos(h) * math.sin(phi) - math.tan(decl) * math.cos(phi)))
    az = (az + 180.0) % 360.0

    elev = 90.0 - zen
    refr = _refraction_deg(elev) if refraction else 0.0
    elev = min(90.0, elev + refr)
    return SolarPosition(
        elevation_deg=elev, azimuth_deg=az, zenith_deg=90.0 - elev, declination_deg=math.degrees(decl),
        equation_of_time_min=eot, hour_angle_deg=hour_angle, refraction_deg=refr, julian_day=jd,
    )


def solar_position(when: datetime, latitude_deg: float, longitude_deg: float, *,
                   utc_offset_hours: float | None = None, refraction: bool = True) -> tuple[float, float]:
    """(elevation_deg, azimuth_deg) of the sun at ``when`` seen from (latitude, longitude).

    Latitude north-positive in [-90, 90], longitude east-positive in [-180, 180]. See the module
    docstring for naive times and refraction.
    """
    p = solar_position_details(when, latitude_deg, longitude_deg, utc_offset_hours=utc_offset_hours,
                               refraction=refraction)
    return p.elevation_deg, p.azimuth_deg


def sun_from_time(when: datetime | str, latitude_deg: float, longitude_deg: float, irradiance=None, *,
                  utc_offset_hours: float | None = None, refraction: bool = True) -> Sun:
    """A :class:`Sun` pointing at the solar position for ``when`` (a datetime or a
    :func:`parse_time` string) at (latitude, longitude).

    ``irradiance`` (scalar or (3,), W·m⁻²) defaults to :class:`Sun`'s default; it is not reduced
    when the sun is low or below the horizon — the renderer checks ``Sun.is_up`` and the sky
    model derives the transmitted irradiance.
    """
    if isinstance(when, str):
        when = parse_time(when)
    elev, az = solar_position(when, latitude_deg, longitude_deg, utc_offset_hours=utc_offset_hours,
                              refraction=refraction)
    direction = direction_from_angles(elev, az)
    if irradiance is None:
        return Sun(direction)
    return Sun(direction, irradiance=np.broadcast_to(np.asarray(irradiance, dtype=np.float64), (3,)).copy())


_TIME_RE = re.compile(
    r"^\s*(?P<y>\d{4})-(?P<mo>\d{1,2})-(?P<d>\d{1,2})"
    r"(?:[ T]+(?P<h>\d{1,2}):(?P<mi>\d{1,2})(?::(?P<s>\d{1,2}(?:\.\d+)?))?)?"
    r"\s*(?P<tz>Z|UTC|[+-]\d{1,2}(?::?\d{2})?)?\s*$",
    re.IGNORECASE,
)


def parse_time(text: str) -> datetime:
    """Parse ``"YYYY-MM-DD HH:MM[:SS][ ±HH:MM|Z|UTC]"`` (a ``T`` may separate date and time).

    With an offset the result is timezone-aware, otherwise naive (local time, see the module
    docstring). A date alone means 12:00. Impossible dates and times raise :class:`SceneError`
    with a one-line message (month 13, 30 February, hour 25, offset beyond ±14 h, ...).
    """
    if not isinstance(text, str):
        raise SceneError(f"a time must be a string like '2024-06-21 15:00', got {text!r}")
    m = _TIME_RE.match(text)
    if not m:
        raise SceneError(f"time {text!r} is not of the form 'YYYY-MM-DD HH:MM' (optionally ' +HH:MM')")
    year, month, day = int(m["y"]), int(m["mo"]), int(m["d"])
    hour = int(m["h"]) if m["h"] is not None else 12
    minute = int(m["mi"]) if m["mi"] is not None else 0
    sec = float(m["s"]) if m["s"] is not None else 0.0
    where = f"time {text.strip()!r}"
    if not 1 <= year <= 9999:
        raise SceneError(f"{where}: year {year} is out of range")
    if not 1 <= month <= 12:
        raise SceneError(f"{where}: month {month} does not exist (1..12)")
    ndays = calendar.monthrange(year, month)[1]
    if not 1 <= day <= ndays:
        raise SceneError(f"{where}: day {day} does not exist in {calendar.month_name[month]} {year} "
                         f"(1..{ndays})")
    if not 0 <= hour <= 23:
        raise SceneError(f"{where}: hour {hour} does not exist (0..23)")
    if not 0 <= minute <= 59:
        raise SceneError(f"{where}: minute {minute} does not exist (0..59)")
    if not 0 <= sec < 60:
        raise SceneError(f"{where}: second {m['s']} does not exist (0..59)")
    whole = int(sec)
    micro = int(round((sec - whole) * 1e6))
    micro = min(micro, 999999)
    tz = None
    if m["tz"] is not None:
        z = m["tz"].upper()
        if z in ("Z", "UTC"):
            tz = timezone.utc
        else:
            sign = -1 if z[0] == "-" else 1
            body = z[1:].replace(":", "")
            oh, om = (int(body), 0) if len(body) <= 2 else (int(body[:-2]), int(body[-2:]))
            if om > 59 or oh * 60 + om > 14 * 60:
                raise SceneError(f"{where}: UTC offset {m['tz']} is impossible (at most ±14:00)")
            tz = timezone(sign * timedelta(hours=oh, minutes=om))
    return datetime(year, month, day, hour, minute, whole, micro, tzinfo=tz)
