"""Quality presets: a few tested combinations of the settings, by name (``PRESETS``), the default
one (``DEFAULT_QUALITY``) and the former names still accepted (``PRESET_ALIASES``).
``RenderConfig.preset`` builds a config from one."""

from __future__ import annotations

import warnings

from serenity.errors import ConfigError

PRESETS: dict[str, dict] = {
    # The paper's pipeline as published (§6–§9): indirect light and SSAO at full resolution, the sky
    # volume re-integrated one probe layer per frame by ray casting, 3 LPV cascades of 32³, 4 shadow
    # cascades of 2048² with PCSS and no contact shadows, the ray-traced views lit with the
    # overlapped shadow maps. The slowest preset, kept to compare with the paper.
    "paper": {"indirect": {"scale": 1}, "sky": {"method": "layers", "layers_per_frame": 1},
              "lpv": {"resolution": 32}, "shadow": {"contact_steps": 0}, "rt": {"sun_shadows": "osm"}},
    # Every technique of the paper, at the settings of a bare RenderConfig(): indirect light and SSAO
    # at half resolution, the sky volume re-lit by visibility transfer (every probe current every
    # frame), 3 LPV cascades of 12³, 4 shadow cascades of 2048² with PCSS and a contact-shadow march.
    "lpv": {},
    # "lpv" at about 60 % of its frame time for a little more error: indirect light and SSAO at
    # quarter resolution (the indirect light is smooth: FLIP moves by under 0.002, the LPV lighting
    # pass gets ~4x cheaper), shadow cascades of 1.6 texels per image pixel (at most 1024²) redrawn
    # in turn without the contact march, 4 PCSS blocker and 8 filter taps, fewer SSAO and glossy-LPV
    # taps, a 64² sky map re-lit one probe layer per frame, LPV cascades updated in turn, a coarser
    # RSM and fewer sky VPLs.
    "lpv-fast": {"indirect": {"scale": 4},
                 "shadow": {"size": 1024, "texels_per_pixel": 1.6, "blocker_samples": 4, "filter_samples": 8,
                            "stagger": True, "contact_steps": 0},
                 "ssao": {"directions": 6, "steps": 2},
                 "sky": {"sky_map_size": 64, "sky_steps": 12, "transfer_layers": 1},
                 "lpv": {"glossy_steps": 4, "stagger": True, "rsm_size": 128, "sky_vpl_stride": 8}},
    # Beyond the paper, and the default: no LPV and no SSAO. The sky volume's probes, fitted to what
    # stands on the ground (~24 000 probes), each trace 512 rays once through the kd-tree and are lit
    # with the sky and every bounce of sun and sky light through the real geometry (``"gather"``),
    # each probe weighed by whether it sees the point it lights. The probes already hold the
    # occlusion SSAO would add (FLIP is better in both test scenes without SSAO), and 128 rays leave
    # the Cornell box's probes blotchy (its light comes from a small sunlit patch). Indirect light at
    # quarter resolution and at full resolution where upsampling finds no like texel (a table's
    # edge), 3 shadow cascades of 2.4 texels per image pixel, a coarse sky map.
    "traced-probes": {"indirect": {"scale": 4, "refine_below": 0.05},
                      "shadow": {"size": 1024, "texels_per_pixel": 2.4, "cascades": 3, "blocker_samples": 4,
                                 "filter_samples": 8, "stagger": True},
                      "ssao": {"enabled": False},
                      "sky": {"sky_map_size": 64, "sky_steps": 8, "transfer_layers": 1, "method": "gather",
                              "fit": "content", "target_probes": 24_000, "gather_rays": 512, "normal_offset": 0.25},
                      "lpv": {"enabled": False}},
}
"""Quality presets: a field of ``RenderConfig`` → its value, or a sub-config's name (``SUB_CONFIGS``:
shadow, ssao, sky, lpv, indirect, rt, schedule) → its fields' values; every field a preset does not
name keeps ``RenderConfig()``'s default. Each is one point of the speed-vs-error frontier
(``benchmarks/bench_frontier.py``)."""

QUALITY_PRESETS = tuple(PRESETS)
DEFAULT_QUALITY = "traced-probes"
"""The preset ``Renderer`` renders without a config, and ``serenity render``, ``view``, ``sweep``
and ``bench`` use unless ``--quality`` says otherwise. On the speed-vs-error frontier it costs about
what ``lpv-fast`` costs (within about 10 % in the test scenes) and is the closest to the
path-traced reference in every scene of the frontier (FLIP 0.043–0.055 in the test scenes against
0.104–0.115 for the LPV presets at 320×180 and 640×360, the breakfast room 0.100 against 0.57;
``benchmarks/bench_frontier.py``, ``frontier.json``). The presets that keep the paper's LPV are a ``--quality`` away."""

PRESET_ALIASES = {"low": "traced-probes", "medium": "lpv-fast", "high": "lpv"}
"""Former preset names, still accepted everywhere a preset name is, with a ``PresetRenamedWarning``."""


class PresetRenamedWarning(FutureWarning):
    """A former quality preset name was used (``PRESET_ALIASES``); the message names the new one.
    A ``FutureWarning``, so that Python shows it by default; the ``serenity`` command prints it as
    one line."""


def preset_name(name: str, where: str | None = None) -> str:
    """The preset ``name`` stands for: itself, or for a former name (``PRESET_ALIASES``) its current
    one, with a one-line ``PresetRenamedWarning`` (prefixed with ``where``, e.g. a file, when given). An
    unknown name is a ``ConfigError`` that lists the presets."""
    if name in PRESET_ALIASES:
        new = PRESET_ALIASES[name]
        prefix = f"{where}: " if where else ""
        warnings.warn(f"{prefix}quality preset {name!r} is now called {new!r}", PresetRenamedWarning,
                      stacklevel=3)
        return new
    if name not in PRESETS:
        prefix = f"{where}: " if where else ""
        raise ConfigError(f"{prefix}quality preset must be one of {', '.join(QUALITY_PRESETS)}, got {name!r}")
    return name

