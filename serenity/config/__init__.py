"""Frozen render settings, one typed tree: ``RenderConfig`` holds a ``ShadowConfig``, an
``SSAOConfig``, a ``SkyConfig``, an ``LPVConfig``, an ``IndirectConfig``, a ``RayTracingConfig`` and
a ``ScheduleConfig`` (``SUB_CONFIGS``), one module each here. Units are stated on each attribute;
defaults are the paper's where it gives them, and where they differ the attribute says why. Every
invalid value raises a ``ConfigError`` (a ``SerenityError``) whose message starts with ``Class.field``.
A setting is named by its dotted path, e.g. ``"indirect.scale"``; the former names of the settings
that moved into a sub-config still work, with a ``SettingMovedWarning`` (``MOVED_SETTINGS``).

Quality presets (``PRESETS``, ``RenderConfig.preset``) name a few tested combinations of these
settings; ``DEFAULT_QUALITY`` ("traced-probes") is what ``Renderer`` renders without a config and
what every ``serenity`` command uses unless ``--quality`` says otherwise. A bare ``RenderConfig()``
holds the "lpv" preset's settings, the base every preset's overrides apply to.

Plain Python only: importing this package imports neither Warp nor moderngl, so the kernels and
the GL passes both read their settings from here. The kd-tree's build settings
(``KdBuildConfig``) are here too, outside ``RenderConfig``: they are the scene's, not the frame's.
"""

from serenity.config.image import DEFAULT_EXPOSURE, MAX_IMAGE_SIZE, check_image_size
from serenity.config.indirect import IndirectConfig
from serenity.config.kdtree import KD_MAX_DEPTH, KdBuildConfig
from serenity.config.lpv import LPV_MAX_CASCADES, LPVConfig
from serenity.config.moved import MOVED_SETTINGS, SettingMovedWarning, moved_setting
from serenity.config.presets import (
    DEFAULT_QUALITY,
    PRESET_ALIASES,
    PRESETS,
    QUALITY_PRESETS,
    PresetRenamedWarning,
    preset_name,
)
from serenity.config.ray_tracing import RT_SUN_SHADOWS, RayTracingConfig
from serenity.config.render import SUB_CONFIGS, RenderConfig, changed_settings
from serenity.config.schedule import ScheduleConfig
from serenity.config.shadow import ShadowConfig
from serenity.config.sky import (
    SH_WINDOWS,
    SKY_FITS,
    SKY_MAP_SIZE,
    SKY_METHODS,
    SKY_SEQUENCES,
    SKY_TRANSFER_MAX_BANDS,
    SKY_VIEW_TABLE_MIN,
    SkyConfig,
)
from serenity.config.ssao import SSAOConfig

__all__ = [
    "DEFAULT_EXPOSURE", "DEFAULT_QUALITY", "KD_MAX_DEPTH", "LPV_MAX_CASCADES", "MAX_IMAGE_SIZE", "MOVED_SETTINGS",
    "PRESETS", "PRESET_ALIASES", "QUALITY_PRESETS", "RT_SUN_SHADOWS", "SH_WINDOWS", "SKY_FITS", "SKY_MAP_SIZE",
    "SKY_METHODS", "SKY_SEQUENCES", "SKY_TRANSFER_MAX_BANDS", "SKY_VIEW_TABLE_MIN", "SUB_CONFIGS",
    "IndirectConfig", "KdBuildConfig", "LPVConfig", "PresetRenamedWarning", "RayTracingConfig", "RenderConfig",
    "SSAOConfig", "ScheduleConfig", "SettingMovedWarning", "ShadowConfig", "SkyConfig", "changed_settings",
    "check_image_size", "moved_setting", "preset_name",
]
