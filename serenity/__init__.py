"""Serenity: real-time global illumination by combining rasterisation and ray tracing
(after Cabeleira, "Combining Rasterization and Ray Tracing Techniques to Approximate Global
Illumination in Real-Time").

Public API (re-exported lazily, so ``import serenity`` loads neither Warp nor OpenGL)::

    import serenity
    scene = serenity.load("courtyard")            # built-in name or .glb/.gltf/.obj/.ply/.toml
    with serenity.Renderer(scene, 640, 360) as renderer:   # the default preset, as `serenity render`
        frame = renderer.render()
    frame.hdr, frame.ldr, frame.aovs, frame.timings

Another preset: ``serenity.Renderer(scene, 640, 360, config=serenity.RenderConfig.preset("lpv"))``
(``serenity.config.QUALITY_PRESETS``; the default is ``DEFAULT_QUALITY``, "traced-probes").
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

_EXPORTS = {
    "Renderer": "serenity.frame",
    "Frame": "serenity.frame",
    "RenderConfig": "serenity.config",
    "ShadowConfig": "serenity.config",
    "SSAOConfig": "serenity.config",
    "SkyConfig": "serenity.config",
    "LPVConfig": "serenity.config",
    "ScheduleConfig": "serenity.config",
    "IndirectConfig": "serenity.config",
    "RayTracingConfig": "serenity.config",
    "SerenityError": "serenity.errors",
    "SceneError": "serenity.errors",
    "load": "serenity.scene",
}

__all__ = [*_EXPORTS, "__version__"]


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'serenity' has no attribute {name!r}")
