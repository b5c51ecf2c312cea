"""RenderConfig and its sub-configs reject what they cannot render with a SerenityError naming the field;
importing the config module loads neither Warp nor moderngl."""

import dataclasses
import subprocess
import sys

import pytest

from serenity.config import (
    IndirectConfig,
    LPVConfig,
    RayTracingConfig,
    RenderConfig,
    ScheduleConfig,
    ShadowConfig,
    SkyConfig,
    SSAOConfig,
    changed_settings,
)
from serenity.errors import SerenityError


@pytest.mark.parametrize("kind, kw, field", [
    (RenderConfig, {"ssao": False}, "RenderConfig.ssao"),
    (RenderConfig, {"shadow": "pcss"}, "RenderConfig.shadow"),
    (RenderConfig, {"lpv": False}, "RenderConfig.lpv"),
    (RenderConfig, {"lpv": {"resolution": 16}}, "RenderConfig.lpv"),
    (RenderConfig, {"sky": 3}, "RenderConfig.sky"),
    (RenderConfig, {"rt": True}, "RenderConfig.rt"),
    (RenderConfig, {"indirect": 2}, "RenderConfig.indirect"),
    (RenderConfig, {"texture_taps": 0}, "RenderConfig.texture_taps"),
    (RenderConfig, {"antialiasing": "msaa"}, "RenderConfig.antialiasing"),
    (RayTracingConfig, {"transmissions": -1}, "RayTracingConfig.transmissions"),
    (RayTracingConfig, {"transmissions": 2.5}, "RayTracingConfig.transmissions"),
    (RayTracingConfig, {"osm_size": 8}, "RayTracingConfig.osm_size"),
    (IndirectConfig, {"scale": 0}, "IndirectConfig.scale"),
    (IndirectConfig, {"scale": 2.0}, "IndirectConfig.scale"),
    (IndirectConfig, {"history": 0.0}, "IndirectConfig.history"),
    (IndirectConfig, {"refine_below": 1.5}, "IndirectConfig.refine_below"),
    (RenderConfig, {"exposure": 0.0}, "RenderConfig.exposure"),
    (ShadowConfig, {"filter_samples": 0}, "ShadowConfig.filter_samples"),
    (ShadowConfig, {"contact_steps": -1}, "ShadowConfig.contact_steps"),
    (ShadowConfig, {"texels_per_pixel": -1.0}, "ShadowConfig.texels_per_pixel"),
    (ShadowConfig, {"texels_per_pixel": float("nan")}, "ShadowConfig.texels_per_pixel"),
    (ShadowConfig, {"contact_pixels": 0.0}, "ShadowConfig.contact_pixels"),
    (ShadowConfig, {"contact_texels": -1.0}, "ShadowConfig.contact_texels"),
    (RayTracingConfig, {"sun_shadows": "pcss"}, "RayTracingConfig.sun_shadows"),
    (ScheduleConfig, {"tracer_nice": 20}, "ScheduleConfig.tracer_nice"),
    (ScheduleConfig, {"tracer_nice": -21}, "ScheduleConfig.tracer_nice"),
    (ScheduleConfig, {"tracer_session": "yes"}, "ScheduleConfig.tracer_session"),
    (ScheduleConfig, {"volume_nice": -1}, "ScheduleConfig.volume_nice"),
    (ScheduleConfig, {"volume_nice": 20}, "ScheduleConfig.volume_nice"),
    (SSAOConfig, {"steps": 0}, "SSAOConfig.steps"),
    (SkyConfig, {"window": "box"}, "SkyConfig.window"),
    (SkyConfig, {"rays_per_probe": 0}, "SkyConfig.rays_per_probe"),
    (SkyConfig, {"layers_per_frame": 0}, "SkyConfig.layers_per_frame"),
    (LPVConfig, {"cascades": 4}, "LPVConfig.cascades"),
    (LPVConfig, {"resolution": (16, 16)}, "LPVConfig.resolution"),
    (LPVConfig, {"forward_shift": 0.5}, "LPVConfig.forward_shift"),
    (LPVConfig, {"glossy_step": 0.0}, "LPVConfig.glossy_step"),
    (LPVConfig, {"rsm_size": 8}, "LPVConfig.rsm_size"),
    (LPVConfig, {"sky_vpl_stride": 0}, "LPVConfig.sky_vpl_stride"),
])
def test_bad_fields_name_themselves(kind, kw, field):
    with pytest.raises(SerenityError, match=field.replace(".", r"\.")):
        kind(**kw)


def test_good_settings_pass():
    cfg = RenderConfig(ssao=SSAOConfig(enabled=False), lpv=LPVConfig(resolution=8), sky=SkyConfig(enabled=False),
                       rt=RayTracingConfig(transmissions=0))
    assert cfg.lpv.enabled and not cfg.sky.enabled
    assert RenderConfig().lpv == LPVConfig() and RenderConfig().sky == SkyConfig()


def test_config_imports_no_warp_or_gl():
    code = ("import sys, serenity.config; "
            "print(sorted(m for m in ('warp', 'moderngl') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_shadow_maps_sized_to_the_image():
    """texels_per_pixel sizes the cascades to the image's longer side, in multiples of 64 texels,
    within 512..size; 0 keeps size whatever the image."""
    cfg = ShadowConfig(size=1024, texels_per_pixel=2.4)
    assert cfg.size_for(320, 180) == 768          # 2.4 x 320
    assert cfg.size_for(180, 320) == 768          # the longer side, either way round
    assert cfg.size_for(330, 180) == 832          # 792 rounded up to a multiple of 64
    assert cfg.size_for(640, 360) == 1024         # 1536, capped at size
    assert cfg.size_for(160, 90) == 512           # at least 512 (384 left the 160×90 courtyard 11 % worse)
    assert ShadowConfig(size=1024).size_for(320, 180) == 1024
    assert RenderConfig.preset("lpv-fast").shadow.size_for(320, 180) == 512   # 1.6 x 320
    assert RenderConfig.preset("lpv-fast").shadow.size_for(640, 360) == 1024
    assert RenderConfig.preset("paper").shadow.size_for(1280, 720) == 2048


def test_presets_change_what_they_name_and_nothing_else():
    """Each quality preset sets exactly the fields PRESETS lists for it (in RenderConfig and in its
    sub-configs); every other field keeps RenderConfig()'s default."""
    import dataclasses

    from serenity.config import PRESETS, QUALITY_PRESETS, SUB_CONFIGS, RenderConfig

    base = RenderConfig()
    assert set(QUALITY_PRESETS) == {"traced-probes", "lpv-fast", "lpv", "paper"}
    for name in QUALITY_PRESETS:
        cfg, named = RenderConfig.preset(name), PRESETS[name]
        for f in dataclasses.fields(RenderConfig):
            ours, default = getattr(cfg, f.name), getattr(base, f.name)
            if f.name in SUB_CONFIGS:
                for g in dataclasses.fields(type(default)):
                    expect = named.get(f.name, {}).get(g.name, getattr(default, g.name))
                    assert getattr(ours, g.name) == expect, (name, f.name, g.name)
            else:
                assert ours == named.get(f.name, default), (name, f.name)
    assert RenderConfig.preset("paper").lpv.resolution == 32 and RenderConfig.preset("paper").indirect.scale == 1
    assert RenderConfig.preset("paper").sky.method == "layers"
    assert RenderConfig.preset("traced-probes", exposure=0.5).exposure == 0.5


def test_unknown_preset_names_the_choices():
    from serenity.config import RenderConfig
    from serenity.errors import SerenityError

    with pytest.raises(SerenityError, match="quality preset must be one of paper, lpv, lpv-fast, traced-probes, "
                                            "got 'ultra'"):
        RenderConfig.preset("ultra")


def test_the_default_preset_and_what_a_bare_config_holds():
    """``RenderConfig.preset()`` is DEFAULT_QUALITY, traced-probes; a bare RenderConfig() is the
    "lpv" preset (its docstring says so), the base every preset's overrides apply to."""
    from serenity.config import DEFAULT_QUALITY, PRESETS

    assert DEFAULT_QUALITY == "traced-probes"
    assert RenderConfig.preset() == RenderConfig.preset(DEFAULT_QUALITY)
    assert RenderConfig.preset(exposure=0.5) == RenderConfig.preset(DEFAULT_QUALITY, exposure=0.5)
    assert RenderConfig() == RenderConfig.preset("lpv") and PRESETS["lpv"] == {}
    assert "lpv" in RenderConfig.__doc__ and DEFAULT_QUALITY in RenderConfig.__doc__
    default = RenderConfig.preset()
    assert not default.lpv.enabled and not default.ssao.enabled and default.sky.method == "gather"


@pytest.mark.parametrize("old, new", [("low", "traced-probes"), ("medium", "lpv-fast"), ("high", "lpv")])
def test_former_preset_names_still_work_with_a_one_line_warning(old, new):
    import warnings

    from serenity.config import PRESET_ALIASES, PresetRenamedWarning, preset_name

    assert PRESET_ALIASES[old] == new
    assert issubclass(PresetRenamedWarning, FutureWarning)  # shown by default, not only under -W
    with pytest.warns(PresetRenamedWarning) as caught:
        cfg = RenderConfig.preset(old, exposure=0.5)
    assert [str(w.message) for w in caught] == [f"quality preset {old!r} is now called {new!r}"]
    assert cfg == RenderConfig.preset(new, exposure=0.5)
    with pytest.warns(PresetRenamedWarning, match=f"^sweep.toml: quality preset '{old}'"):
        assert preset_name(old, "sweep.toml") == new
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the current names warn of nothing
        assert preset_name(new) == new and RenderConfig.preset(new, exposure=0.5) == cfg


def test_sweep_files_and_viewer_scripts_take_former_preset_names(tmp_path):
    """A sweep file's quality list and a viewer script's ``set = { quality = ... }`` accept the former
    names too: each becomes the current name (task keys, output names and the panel use it), with
    a warning that names the file."""
    from serenity.config import PresetRenamedWarning
    from serenity.sweep import load_spec
    from serenity.view.script import load_script

    sweep = tmp_path / "day.toml"
    sweep.write_text('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\nquality = ["low", "lpv", "baseline"]\n')
    with pytest.warns(PresetRenamedWarning, match=r"day\.toml \[sweep\]\.quality: quality preset 'low' is now "
                                                  r"called 'traced-probes'"):
        assert load_spec(str(sweep)).qualities == ("traced-probes", "lpv", "baseline")
    script = tmp_path / "s.toml"
    script.write_text('[[step]]\nframe = 1\nset = { quality = "medium" }\n')
    with pytest.warns(PresetRenamedWarning, match=r"s\.toml.*quality preset 'medium' is now called 'lpv-fast'"):
        assert load_script(str(script)).steps[0].value == {"quality": "lpv-fast"}


def test_changed_settings_names_the_fields_that_differ():
    base = RenderConfig.preset("lpv-fast")
    new = dataclasses.replace(base, exposure=base.exposure * 2,
                              shadow=dataclasses.replace(base.shadow, filter="pcf", size=base.shadow.size + 1))
    assert sorted(changed_settings(base, new)) == ["exposure", "shadow.filter", "shadow.size"]
    assert changed_settings(base, base) == [] and changed_settings(ShadowConfig(), ShadowConfig()) == []
    moved = dataclasses.replace(base, indirect=dataclasses.replace(base.indirect, scale=1),
                                rt=dataclasses.replace(base.rt, reflections=False))
    assert changed_settings(base, moved) == ["indirect.scale", "rt.reflections"]


FORMER_VALUES = {"ray_tracing": False, "reflections": False, "refractions": False, "transmissions": 2,
                 "rt_sun_shadows": "osm", "osm_size": 1024, "indirect_scale": 4, "indirect_history": 0.5,
                 "indirect_refine_below": 0.1, "lowres_tile_balance": False, "rsm_size": 128, "sky_vpl_stride": 8,
                 "sky_layers_per_frame": 2}
"""A valid value other than the default for every former name of a setting."""


@pytest.mark.parametrize("old", sorted(FORMER_VALUES))
def test_former_setting_names_still_work_with_a_one_line_warning(old):
    """A setting that moved into a sub-config is still taken under its former name, by every way a
    config is built from names, and read as an attribute: each time one SettingMovedWarning (a
    FutureWarning, shown by default) whose one line names the dotted path it has now."""
    from serenity.config import MOVED_SETTINGS, SettingMovedWarning

    assert set(FORMER_VALUES) == set(MOVED_SETTINGS)
    new, value = MOVED_SETTINGS[old], FORMER_VALUES[old]
    sub, name = new.split(".")
    want = RenderConfig.from_dict({new: value})
    assert getattr(getattr(want, sub), name) == value and want != RenderConfig()
    assert issubclass(SettingMovedWarning, FutureWarning)
    message = f"setting {old!r} is now called {new!r}"
    with pytest.warns(SettingMovedWarning) as caught:
        assert RenderConfig.from_dict({old: value}, where="render.toml") == want
    assert [str(w.message) for w in caught] == [f"render.toml: {message}"]
    assert caught[0].filename == __file__  # the line that used the name, not the config package's
    for build in (lambda: RenderConfig(**{old: value}), lambda: dataclasses.replace(RenderConfig(), **{old: value}),
                  lambda: RenderConfig.preset("lpv", **{old: value})):
        with pytest.warns(SettingMovedWarning) as caught:
            assert build() == want
        assert [str(w.message) for w in caught] == [message]
    with pytest.warns(SettingMovedWarning, match=f"^{message}$") as caught:
        assert getattr(want, old) == value
    assert caught[0].filename == __file__
    assert old not in {f.name for f in dataclasses.fields(RenderConfig)}


def test_former_names_apply_on_top_of_the_sub_config_given_with_them():
    """A former name given with its sub-config changes only its own field of that sub-config, and a
    preset's other settings of that sub-config stay."""
    from serenity.config import SettingMovedWarning

    with pytest.warns(SettingMovedWarning):
        cfg = RenderConfig(rt=RayTracingConfig(sun_shadows="osm"), transmissions=1)
    assert cfg.rt == RayTracingConfig(sun_shadows="osm", transmissions=1)
    with pytest.warns(SettingMovedWarning):
        paper = RenderConfig.preset("paper", sky_layers_per_frame=3)
    assert paper.sky.method == "layers" and paper.sky.layers_per_frame == 3


def test_from_dict_takes_tables_dotted_paths_and_whole_sub_configs():
    import warnings

    base = RenderConfig.preset("lpv-fast")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the current names warn of nothing
        cfg = RenderConfig.from_dict({"exposure": 0.05, "indirect": {"scale": 1}, "rt.sun_shadows": "osm",
                                      "ssao": SSAOConfig(enabled=False)}, base=base)
    assert cfg == dataclasses.replace(base, exposure=0.05, indirect=IndirectConfig(scale=1, history=0.2),
                                      rt=RayTracingConfig(sun_shadows="osm"), ssao=SSAOConfig(enabled=False))
    assert cfg.shadow == base.shadow and cfg.indirect.tile_balance == base.indirect.tile_balance
    # in one step: the gathered sky volume is valid only with the LPV's diffuse light off
    both = RenderConfig.from_dict({"sky.method": "gather", "lpv": {"diffuse": False}})
    assert both.sky.method == "gather" and not both.lpv.diffuse
    assert RenderConfig.from_dict({}) == RenderConfig() and RenderConfig.from_dict({}, base=base) == base
    assert RenderConfig.preset("lpv", indirect={"scale": 4}).indirect == IndirectConfig(scale=4)


@pytest.mark.parametrize("data, message", [
    ({"indirect_scal": 4}, "RenderConfig has no setting 'indirect_scal'"),
    ({"indirect": {"sale": 4}}, r"IndirectConfig has no setting 'sale' \(indirect\.sale\)"),
    ({"lighting.scale": 4}, "RenderConfig has no sub-config 'lighting'"),
    ({"indirect.scale": 0}, r"IndirectConfig\.scale must be an int in 1\.\.8"),
    ({"rt": False}, r"RenderConfig\.rt must be a RayTracingConfig"),
])
def test_from_dict_names_the_file_and_the_bad_setting(data, message):
    with pytest.raises(SerenityError, match=f"^scene.toml: {message}") as e:
        RenderConfig.from_dict(data, where="scene.toml")
    assert "\n" not in str(e.value)
