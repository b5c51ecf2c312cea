"""Former top-level fields of ``RenderConfig`` that live in a sub-config (``MOVED_SETTINGS``): each
is still accepted under its former name, with a one-line ``SettingMovedWarning`` that names its
place now, wherever a config is built from names (``RenderConfig.from_dict``, ``RenderConfig.preset``'s
overrides, ``RenderConfig(...)``'s keywords, ``dataclasses.replace``) and read as an attribute."""

from __future__ import annotations

import warnings

MOVED_SETTINGS: dict[str, str] = {
    "ray_tracing": "rt.enabled",
    "reflections": "rt.reflections",
    "refractions": "rt.refractions",
    "transmissions": "rt.transmissions",
    "rt_sun_shadows": "rt.sun_shadows",
    "osm_size": "rt.osm_size",
    "indirect_scale": "indirect.scale",
    "indirect_history": "indirect.history",
    "indirect_refine_below": "indirect.refine_below",
    "lowres_tile_balance": "indirect.tile_balance",
    "rsm_size": "lpv.rsm_size",
    "sky_vpl_stride": "lpv.sky_vpl_stride",
    "sky_layers_per_frame": "sky.layers_per_frame",
}
"""Former name of a ``RenderConfig`` field → its dotted path now (sub-config, field)."""


class SettingMovedWarning(FutureWarning):
    """A former name of a ``RenderConfig`` setting was used (``MOVED_SETTINGS``); the message names
    its dotted path now. A ``FutureWarning``, so that Python shows it by default; the ``serenity``
    command prints it as one line."""


def moved_setting(name: str, where: str | None = None, stacklevel: int = 2) -> str:
    """The dotted path now of former setting ``name`` (a key of ``MOVED_SETTINGS``), with a one-line
    ``SettingMovedWarning`` (prefixed with ``where``, e.g. a file, when given); ``stacklevel`` is
    what ``warnings.warn`` would take in the caller (2: the caller's caller's line)."""
    new = MOVED_SETTINGS[name]
    prefix = f"{where}: " if where else ""
    warnings.warn(f"{prefix}setting {name!r} is now called {new!r}", SettingMovedWarning, stacklevel=stacklevel + 1)
    return new
