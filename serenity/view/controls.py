"""The viewer's state without a window: the fly camera, the time of day, the technique switches and
the quality preset, each turned into what ``Renderer`` reads (``Scene.camera``, ``Scene.sun``,
``RenderConfig``). Pure Python, so the tests drive it without a display.

Fly camera: yaw (degrees, 0 = looking north along -z, 90 = east along +x) and pitch (degrees, up
positive, clamped to ±89) from mouse-look; WASD moves along the view direction and its right vector,
Q/E down/up along world y, at ``speed`` m/s (Shift ×4). ``look(dx, dy)`` turns by
``sensitivity`` degrees per pixel of mouse motion.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from serenity.config import DEFAULT_EXPOSURE, DEFAULT_QUALITY, RenderConfig
from serenity.errors import SerenityError
from serenity.scene.sun import DEFAULT_LOCATION, DEFAULT_TIME, parse_time, sun_from_time

#: the techniques the panel switches; "live" ones change per frame, the others rebuild the Renderer.
#: A pair (LPV diffuse/glossy, reflections/refractions) is live while one of the two stays on;
#: switching off both turns the whole technique off (``LPVConfig.enabled``, ``RayTracingConfig.enabled``): a rebuild
LIVE_TOGGLES = ("ssao", "lpv_diffuse", "lpv_glossy", "reflections", "refractions", "taa")
REBUILD_TOGGLES = ("sky_lighting",)
SHADOW_FILTERS = ("hard", "pcf", "pcss")
#: view name -> what it shows (the panel's combo, a script's ``set = { view = ... }``, V cycles)
VIEWS = {
    "final": "the tone-mapped frame",
    "albedo": "G-buffer albedo",
    "normal": "G-buffer world normal (0.5 + 0.5 n)",
    "direct": "direct sun light (tone-mapped)",
    "sky light": "sky-volume light, full resolution, without AO (tone-mapped)",
    "lpv indirect": "LPV diffuse + glossy light (as switched), full resolution, without AO (tone-mapped)",
    "ao": "SSAO (1 = open; at the indirect light's resolution)",
    "rt mask": "pixels with ray-traced reflection/refraction",
    "lpv cascades": "the frame with the LPV cascades' bounds",
    "reference split": "ours when R was pressed (left) | its path-traced reference (right)",
    "flip error": "FLIP error map of that comparison",
}


def quality_config(name: str) -> RenderConfig:
    """The ``RenderConfig`` of a quality preset (``RenderConfig.preset``, as ``serenity render
    --quality``); an unknown name is a one-line ``ConfigError``."""
    return RenderConfig.preset(name)


@dataclass
class FlyCamera:
    """Position (m) and yaw/pitch (degrees) of a free-flying camera; see the module docstring."""

    position: np.ndarray
    yaw_deg: float
    pitch_deg: float
    speed: float = 3.0
    """Metres per second."""
    sensitivity: float = 0.15
    """Degrees per pixel of mouse motion."""

    @classmethod
    def from_camera(cls, camera, speed: float = 3.0) -> FlyCamera:
        f = camera.forward
        pitch = math.degrees(math.asin(max(-1.0, min(1.0, float(f[1])))))
        yaw = math.degrees(math.atan2(float(f[0]), float(-f[2])))
        return cls(np.array(camera.position, np.float64), yaw, max(-89.0, min(89.0, pitch)), speed)

    @property
    def forward(self) -> np.ndarray:
        y, p = math.radians(self.yaw_deg), math.radians(self.pitch_deg)
        return np.array([math.cos(p) * math.sin(y), math.sin(p), -math.cos(p) * math.cos(y)])

    @property
    def right(self) -> np.ndarray:
        y = math.radians(self.yaw_deg)
        return np.array([math.cos(y), 0.0, math.sin(y)])

    def look(self, dx: float, dy: float) -> None:
        """Mouse-look by (dx, dy) pixels (dy positive = mouse moved down = look down)."""
        self.yaw_deg = (self.yaw_deg + dx * self.sensitivity) % 360.0
        self.pitch_deg = max(-89.0, min(89.0, self.pitch_deg - dy * self.sensitivity))

    def move(self, keys: set[str], dt: float, fast: bool = False) -> bool:
        """Move for ``dt`` seconds with the held ``keys`` (upper-case letters W A S D Q E).
        Returns whether the camera moved."""
        d = np.zeros(3)
        for key, axis, sign in (("W", self.forward, 1), ("S", self.forward, -1), ("D", self.right, 1),
                                ("A", self.right, -1), ("E", np.array([0.0, 1.0, 0.0]), 1),
                                ("Q", np.array([0.0, 1.0, 0.0]), -1)):
            if key in keys:
                d += sign * axis
        n = float(np.linalg.norm(d))
        if n == 0.0 or dt <= 0.0:
            return False
        self.position = self.position + d / n * self.speed * (4.0 if fast else 1.0) * dt
        return True

    def apply(self, camera) -> None:
        """Write position and direction into a ``serenity.scene.model.Camera`` (in place)."""
        camera.position = np.array(self.position, np.float64)
        camera.target = camera.position + self.forward
        camera.up = np.array([0.0, 1.0, 0.0])


@dataclass
class TimeOfDay:
    """Date, local hour and place that set the sun (NOAA's solar position, ``serenity.scene.sun``)."""

    date: str = "2024-06-21"
    hour: float = 16.0
    """Local hours, 0–24."""
    latitude: float = DEFAULT_LOCATION[0]
    longitude: float = DEFAULT_LOCATION[1]
    utc_offset: float = 1.0
    """Hours from UTC of the local time."""

    @classmethod
    def for_scene(cls, scene) -> TimeOfDay:
        """The slider's start: the scene's place (Lisbon when it has none) on the built-in scenes'
        default date and hour (``serenity.scene.sun.DEFAULT_TIME``), in that time's zone at Lisbon and
        in the nautical zone of the longitude elsewhere. It moves the sun only once it is changed."""
        when = parse_time(DEFAULT_TIME)
        lat, lon = getattr(scene, "location", None) or DEFAULT_LOCATION
        at_default = np.allclose((lat, lon), DEFAULT_LOCATION)
        offset = when.utcoffset().total_seconds() / 3600.0 if at_default else float(round(lon / 15.0))
        return cls(date=when.strftime("%Y-%m-%d"), hour=when.hour + when.minute / 60.0, latitude=float(lat),
                   longitude=float(lon), utc_offset=offset)

    def text(self) -> str:
        minutes = int(round(max(0.0, min(23.999, self.hour)) * 60.0))
        sign = "+" if self.utc_offset >= 0 else "-"
        off = int(round(abs(self.utc_offset) * 60))
        return f"{self.date} {minutes // 60:02d}:{minutes % 60:02d} {sign}{off // 60:02d}:{off % 60:02d}"

    def sun(self, old):
        """A new ``Sun`` at this time and place, keeping ``old``'s irradiance and disc size."""
        new = sun_from_time(self.text(), self.latitude, self.longitude, irradiance=old.irradiance)
        new.angular_diameter_deg = old.angular_diameter_deg
        return new


@dataclass
class Settings:
    """What the panel edits: the quality preset, the technique switches, the shadow filter and the
    exposure. ``config()`` is the ``RenderConfig`` they give. ``taa`` (temporal anti-aliasing of a
    still view) is the viewer's own and not part of it."""

    quality: str = DEFAULT_QUALITY
    exposure: float = DEFAULT_EXPOSURE
    ssao: bool = True
    sky_lighting: bool = True
    lpv_diffuse: bool = True
    lpv_glossy: bool = True
    reflections: bool = True
    refractions: bool = True
    shadow_filter: str = "pcss"
    overlap: bool = True
    taa: bool = True

    def config(self) -> RenderConfig:
        base = quality_config(self.quality)
        if self.shadow_filter not in SHADOW_FILTERS:
            raise SerenityError(f"shadow filter must be one of {', '.join(SHADOW_FILTERS)}, got {self.shadow_filter!r}")
        return dataclasses.replace(
            base, exposure=float(self.exposure), schedule=dataclasses.replace(base.schedule, overlap=self.overlap),
            ssao=dataclasses.replace(base.ssao, enabled=bool(self.ssao) and base.ssao.enabled),
            shadow=dataclasses.replace(base.shadow, filter=self.shadow_filter),
            sky=dataclasses.replace(base.sky, enabled=bool(self.sky_lighting) and base.sky.enabled),
            lpv=dataclasses.replace(base.lpv, enabled=(self.lpv_diffuse or self.lpv_glossy) and base.lpv.enabled,
                                    diffuse=bool(self.lpv_diffuse), glossy=bool(self.lpv_glossy)),
            rt=dataclasses.replace(base.rt, enabled=(self.reflections or self.refractions) and base.rt.enabled,
                                   reflections=bool(self.reflections), refractions=bool(self.refractions)))
