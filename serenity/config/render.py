"""``RenderConfig``: everything one ``Renderer`` renders with, one typed tree of the sub-configs
(``SUB_CONFIGS``), built field by field, from a preset (``RenderConfig.preset``) or from plain data
(``RenderConfig.from_dict``); and ``changed_settings``, the dotted paths in which two configs differ."""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from serenity.config.image import DEFAULT_EXPOSURE
from serenity.config.indirect import IndirectConfig
from serenity.config.lpv import LPVConfig
from serenity.config.moved import MOVED_SETTINGS, moved_setting
from serenity.config.presets import DEFAULT_QUALITY, PRESETS, preset_name
from serenity.config.ray_tracing import RayTracingConfig
from serenity.config.schedule import ScheduleConfig
from serenity.config.shadow import ShadowConfig
from serenity.config.sky import SkyConfig
from serenity.config.ssao import SSAOConfig
from serenity.errors import ConfigError

SUB_CONFIGS = {"shadow": ShadowConfig, "ssao": SSAOConfig, "sky": SkyConfig, "lpv": LPVConfig,
               "indirect": IndirectConfig, "rt": RayTracingConfig, "schedule": ScheduleConfig}
"""``RenderConfig``'s sub-configs: field name → class."""

ANTIALIASING = ("none", "fxaa", "taa")
AMBIENT = ("none", "constant")


@dataclass(frozen=True)
class RenderConfig:
    """Everything one ``serenity.frame.Renderer`` renders with: the image's own settings (exposure,
    the ambient baseline, texture filtering, levels of detail, anti-aliasing) and one sub-config per
    part of the frame:
    the sun's shadows (``shadow``), SSAO (``ssao``), the sky lighting volume (``sky``), the light
    propagation volumes (``lpv``), how the main view computes their indirect light (``indirect``),
    the ray-traced reflections and refractions (``rt``) and the schedule (``schedule``). Each
    technique's sub-config has an ``enabled`` flag, e.g. ``RenderConfig(lpv=LPVConfig(enabled=False))``
    renders without the LPV. A setting's name is its dotted path, e.g. ``"indirect.scale"``
    (``changed_settings``, ``Renderer.LIVE_SETTINGS``, ``from_dict``).

    A bare ``RenderConfig()`` is the "lpv" preset: the paper's techniques, every one on. It is not
    the default: ``Renderer(scene, w, h)`` without a config renders ``DEFAULT_QUALITY``
    ("traced-probes"), as every command does. Start from a preset with
    ``RenderConfig.preset(name, **overrides)`` (no name: the default preset)."""

    exposure: float = DEFAULT_EXPOSURE
    """Multiplier applied to radiance (W·m⁻²·sr⁻¹) before Reinhard (see ``DEFAULT_EXPOSURE``)."""
    ambient: str = "none"
    """Indirect term while the GI techniques are absent: "none", or "constant" (the classic flat
    ambient hack, irradiance π·L_sky on every surface — the baseline the GI must beat)."""
    texture_taps: int = 4
    """Trilinear taps per textured G-buffer fragment along its footprint's long axis: anisotropic
    texture filtering in the shader (``glsl/gbuffer.glsl``); 1 = GL's isotropic trilinear, which
    blurs textures seen at grazing angles (courtyard ground FLIP 0.148 -> 0.124 with 4 taps,
    ``benchmarks/bench_aa.py``)."""
    lod_pixel_error: float = 0.5
    """Levels of detail (``serenity.scene.lod``): the rasterised passes draw each mesh of 2048
    triangles or more at the coarsest of its levels whose error, projected at the mesh's nearest
    point, stays within this many pixels (shadow maps: half as many texels); 0 = every mesh whole.
    The ray tracer always traces the full meshes. Half a pixel: a level moves the high-frequency
    light on a surface with it (the blinds' shadows on the breakfast room's chairs), and at 1 pixel
    its FLIP rises by 0.0016 against 0.0009 at 0.5 (``benchmarks/bench_lod.py``)."""
    antialiasing: str = "none"
    """Edge anti-aliasing of the final HDR frame, one pass before the tone map: "none", "fxaa"
    (``serenity.raster.fxaa``: it gains little FLIP against the reference and fills 1-pixel black
    gaps) or "taa" (``serenity.raster.taa``: each frame jittered within the pixel and blended with the
    last frames' resolved image, reprojected; the first frame after a reset is unjittered).
    ``benchmarks/bench_aa.py`` measures them."""
    shadow: ShadowConfig = field(default_factory=ShadowConfig)
    ssao: SSAOConfig = field(default_factory=SSAOConfig)
    sky: SkyConfig = field(default_factory=SkyConfig)
    """The sky lighting irradiance volume (paper §7); ``enabled=False`` turns the sky term off."""
    lpv: LPVConfig = field(default_factory=LPVConfig)
    """Light propagation volumes (paper §8); ``enabled=False`` turns the LPV off. Default: 3 cascades
    of 12³, 8 iterations, the coarsest extended to cross the scene and at most 6 cells across it, far
    light handed over to the finer cascades, clamped face flux, lookup occlusion."""
    indirect: IndirectConfig = field(default_factory=IndirectConfig)
    """The main view's indirect light and SSAO: at half resolution by default, upsampled and blended
    with the last frame's."""
    rt: RayTracingConfig = field(default_factory=RayTracingConfig)
    """Ray-traced reflections and refractions (paper §9); ``enabled=False`` turns them off."""
    schedule: ScheduleConfig = field(default_factory=ScheduleConfig)
    """How the frame's work is scheduled (worker thread and process, priorities, GL waits): the same
    image whatever it says."""

    def __post_init__(self):
        if not (self.exposure > 0):
            raise ConfigError(f"RenderConfig.exposure must be positive, got {self.exposure}")
        if self.ambient not in AMBIENT:
            raise ConfigError(f"RenderConfig.ambient must be 'none' or 'constant', got {self.ambient!r}")
        if not (isinstance(self.texture_taps, int) and 1 <= self.texture_taps <= 16):
            raise ConfigError(f"RenderConfig.texture_taps must be an int in 1..16, got {self.texture_taps!r}")
        if not (isinstance(self.lod_pixel_error, (int, float)) and math.isfinite(self.lod_pixel_error)
                and 0.0 <= self.lod_pixel_error <= 64.0):
            raise ConfigError(f"RenderConfig.lod_pixel_error must be a number in 0..64, got {self.lod_pixel_error!r}")
        if self.antialiasing not in ANTIALIASING:
            raise ConfigError(f"RenderConfig.antialiasing must be 'none', 'fxaa' or 'taa', got {self.antialiasing!r}")
        for name, kind in SUB_CONFIGS.items():
            value = getattr(self, name)
            if not isinstance(value, kind):
                hint = (f" (e.g. {name}={kind.__name__}(enabled=False) to turn it off)"
                        if any(f.name == "enabled" for f in dataclasses.fields(kind)) else "")
                raise ConfigError(f"RenderConfig.{name} must be a {kind.__name__}, got {value!r}{hint}")
        if self.sky.enabled and self.sky.method == "gather" and self.lpv.enabled and self.lpv.diffuse:
            raise ConfigError("RenderConfig: sky.method='gather' already lights the probes with the bounced "
                              "light; turn the LPV's diffuse light off (lpv.diffuse=False or lpv.enabled=False) "
                              "or it counts twice")

    @classmethod
    def preset(cls, name: str | None = None, **overrides) -> RenderConfig:
        """The settings of quality preset ``name`` (one of ``QUALITY_PRESETS``, a former name of one
        with a ``PresetRenamedWarning``, or None for ``DEFAULT_QUALITY``; ``PRESETS`` lists what each sets,
        every field it does not name keeps its default), then ``overrides`` on top, as ``from_dict``
        reads them: a field (``exposure=0.05``), a whole sub-config (``sky=SkyConfig(enabled=False)``
        replaces the preset's) or a dict of some of a sub-config's fields (``indirect={"scale": 1}``
        changes only those). ``RenderConfig.preset(exposure=0.05)`` is the default preset a little
        brighter."""
        name = preset_name(DEFAULT_QUALITY if name is None else name)
        settings = _merge_settings({}, PRESETS[name], None)
        return _apply_settings(cls(), _merge_settings(settings, overrides, None, stacklevel=2))

    @classmethod
    def from_dict(cls, data: Mapping, where: str | None = None, base: RenderConfig | None = None) -> RenderConfig:
        """``base`` (default: ``RenderConfig()``) with the settings of ``data`` (e.g. a TOML table) on
        top, all in one step (so that two settings valid only together may change at once). A key of
        ``data`` is a field (``"exposure"``), a sub-config's name with a table of some of its fields
        (``"indirect": {"scale": 1}``) or a whole sub-config, a dotted path (``"indirect.scale"``), or a
        former name of a setting (``MOVED_SETTINGS``, with a one-line ``SettingMovedWarning``). An
        unknown name or a bad value is a ``ConfigError`` naming it, prefixed with ``where`` (e.g. a file)
        when given."""
        try:
            return _apply_settings(cls() if base is None else base, _merge_settings({}, data, where, stacklevel=2))
        except ConfigError as e:
            if where is None or str(e).startswith(f"{where}: "):
                raise
            raise ConfigError(f"{where}: {e}") from None


_FIELDS = frozenset(f.name for f in dataclasses.fields(RenderConfig))


def _merge_settings(into: dict, data: Mapping, where: str | None, stacklevel: int = 2) -> dict:
    """``into`` (a field → its value, a sub-config's name → a dict of some of its fields or a whole
    sub-config) with ``data``'s settings added (``RenderConfig.from_dict`` says what its keys may be);
    a former name's warning goes to ``stacklevel`` as ``warnings.warn`` would take it in the caller."""
    prefix = f"{where}: " if where else ""
    for key, value in data.items():
        if key in MOVED_SETTINGS:
            key = moved_setting(key, where, stacklevel=stacklevel + 1)
        sub, dot, name = str(key).partition(".")
        if dot:
            if sub not in SUB_CONFIGS:
                raise ConfigError(f"{prefix}RenderConfig has no sub-config {sub!r} (in {key!r}; "
                                  f"sub-configs: {', '.join(SUB_CONFIGS)})")
            _merge_fields(into, sub, {name: value}, prefix)
        elif key in SUB_CONFIGS and isinstance(value, Mapping):
            _merge_fields(into, key, value, prefix)
        elif key in _FIELDS:
            into[key] = value
        else:
            raise ConfigError(f"{prefix}RenderConfig has no setting {key!r}")
    return into


def _merge_fields(into: dict, sub: str, values: Mapping, prefix: str) -> None:
    """Some fields of sub-config ``sub`` into ``into[sub]``: on top of a whole sub-config there, else
    into the dict of its fields."""
    kind = SUB_CONFIGS[sub]
    names = {f.name for f in dataclasses.fields(kind)}
    for name in values:
        if name not in names:
            raise ConfigError(f"{prefix}{kind.__name__} has no setting {name!r} ({sub}.{name})")
    current = into.get(sub)
    if isinstance(current, kind):
        into[sub] = dataclasses.replace(current, **values)
    elif isinstance(current, dict):
        current.update(values)
    else:
        into[sub] = dict(values)


def _apply_settings(base: RenderConfig, settings: dict) -> RenderConfig:
    """``base`` with ``settings`` (``_merge_settings``'s form) in one ``dataclasses.replace``."""
    kw = {k: dataclasses.replace(getattr(base, k), **v) if isinstance(v, dict) else v for k, v in settings.items()}
    return dataclasses.replace(base, **kw)


def _accept_moved_keywords(init):
    """``RenderConfig.__init__`` that also takes the former names of settings (``MOVED_SETTINGS``)
    as keywords, each with a ``SettingMovedWarning``, applied on top of the sub-config it is given
    (or the default one); so ``dataclasses.replace(config, indirect_scale=1)`` works too."""

    @functools.wraps(init)
    def __init__(self, *args, **kw):
        moved = {k: kw.pop(k) for k in [k for k in kw if k in MOVED_SETTINGS]}
        for sub, values in _merge_settings({}, moved, None, stacklevel=2).items():
            kind = SUB_CONFIGS[sub]
            current = kw.get(sub, kind())
            kw[sub] = dataclasses.replace(current, **values) if isinstance(current, kind) else current
        init(self, *args, **kw)

    return __init__


def _moved_attribute(old: str, new: str) -> property:
    """Former field ``old`` of ``RenderConfig``, read from its place now (dotted ``new``) with a
    ``SettingMovedWarning``."""
    sub, name = new.split(".")

    def read(self):
        moved_setting(old, stacklevel=2)
        return getattr(getattr(self, sub), name)

    return property(read, doc=f"Former name of ``{new}`` (read with a ``SettingMovedWarning``).")


RenderConfig.__init__ = _accept_moved_keywords(RenderConfig.__init__)
for _old, _new in MOVED_SETTINGS.items():
    setattr(RenderConfig, _old, _moved_attribute(_old, _new))


def changed_settings(old, new, prefix: str = "") -> list[str]:
    """The settings in which config ``new`` differs from ``old`` (two configs of one dataclass, e.g.
    two ``RenderConfig``): dotted paths into the sub-configs, e.g. ``["exposure", "lpv.glossy"]``."""
    out = []
    for f in dataclasses.fields(old):
        a, b = getattr(old, f.name), getattr(new, f.name)
        if dataclasses.is_dataclass(a) and type(a) is type(b):
            out += changed_settings(a, b, f"{prefix}{f.name}.")
        elif a != b:
            out.append(prefix + f.name)
    return out
