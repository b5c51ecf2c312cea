"""The ray-traced views (paper §9): ``RayTracingConfig``, the reflections and refractions of
mirror, metal and glass pixels, traced on the CPU through the kd-tree."""

from __future__ import annotations

from dataclasses import dataclass

from serenity.config.image import MAX_IMAGE_SIZE
from serenity.errors import ConfigError

RT_SUN_SHADOWS = ("traced", "osm")
"""How the ray-traced views find the sun's shadows (``RayTracingConfig.sun_shadows``)."""


@dataclass(frozen=True)
class RayTracingConfig:
    """Ray-traced reflections and refractions for mirror/metal/glass pixels (paper §9), composited
    over the main view with a Fresnel blend (``serenity/frame/tracing.py``)."""

    enabled: bool = True
    """Trace the reflections and refractions of the scene's mirror, metal and glass pixels. False:
    nothing is traced (no tracer, no kd-tree) and those pixels show the rasterised surface."""
    reflections: bool = True
    """Trace the reflected rays. False: none are traced, and the reflection term of the Fresnel blend
    shows the rasterised surface instead (a mirror looks as with ``enabled=False``)."""
    refractions: bool = True
    """Trace the refracted rays. False: none are traced, and a glass pixel's transmitted term shows
    the rasterised surface instead (its Fresnel reflection stays)."""
    transmissions: int = 4
    """Transparent interfaces a refraction ray is bent through before the surface it shows (the
    back face of a glass solid, a second pane, total internal reflection inside a prism); 0 = the
    paper's single refraction, where glass solids show their own back faces."""
    sun_shadows: str = "traced"
    """Sun shadows of what reflections and refractions show: "traced" (one shadow ray per traced hit
    in the CPU tracer, a hard shadow; no overlapped shadow maps are drawn) or "osm" (the paper's
    overlapped shadow maps, ``osm_size``; their coarse texels light a wall a few cm behind a window)."""
    osm_size: int = 512
    """Texels per side of each of the 3 overlapped shadow maps (``sun_shadows = "osm"``)."""

    def __post_init__(self):
        if not (isinstance(self.transmissions, int) and 0 <= self.transmissions <= 16):
            raise ConfigError(f"RayTracingConfig.transmissions must be an int in 0..16, got {self.transmissions!r}")
        if self.sun_shadows not in RT_SUN_SHADOWS:
            raise ConfigError(f"RayTracingConfig.sun_shadows must be traced or osm, got {self.sun_shadows!r}")
        if not (isinstance(self.osm_size, int) and 16 <= self.osm_size <= MAX_IMAGE_SIZE):
            raise ConfigError(f"RayTracingConfig.osm_size must be an int in 16..{MAX_IMAGE_SIZE}, "
                              f"got {self.osm_size!r}")
