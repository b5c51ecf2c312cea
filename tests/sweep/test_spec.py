"""Sweep files: parsing, expansion into keyed tasks, and their one-line errors (no cluster needed)."""

from __future__ import annotations

import os

import pytest

from serenity.config import DEFAULT_QUALITY, QUALITY_PRESETS, RenderConfig
from serenity.errors import SerenityError
from serenity.sweep import expand, load_spec, quality_config, spec_from_dict
from serenity.sweep.runner import atomic_write
from serenity.sweep.spec import tomllib


def _write(tmp_path, text: str, name: str = "s.toml") -> str:
    p = tmp_path / name
    p.write_text(text)
    return str(p)


BASE = """
[sweep]
scenes = ["plane", "my.toml"]
sizes = ["32x18", "64x36"]
quality = ["lpv-fast", "baseline"]
produce = ["compare"]
[time]
start = "2024-06-21 06:00 +01:00"
end = "2024-06-21 07:00 +01:00"
step_minutes = 20
[reference]
spp = 8
"""


def test_time_range_is_inclusive_and_compare_implies_frame_and_reference(tmp_path):
    spec = load_spec(_write(tmp_path, BASE))
    assert spec.times == ("2024-06-21 06:00 +01:00", "2024-06-21 06:20 +01:00", "2024-06-21 06:40 +01:00",
                          "2024-06-21 07:00 +01:00")
    assert spec.produce == ("frame", "reference", "compare")
    # a file scene is resolved against the sweep file's folder; a built-in name stays a name
    assert spec.scenes == ("plane", str(tmp_path / "my.toml"))
    tasks = expand(spec)
    kinds = [t.kind for t in tasks]
    points = 2 * 2 * 4  # scenes x sizes x times
    # one reference per (scene, size, time), shared by both qualities; a frame and a comparison per quality
    assert kinds.count("reference") == points
    assert kinds.count("frame") == kinds.count("compare") == 2 * points
    assert len({t.key for t in tasks}) == len(tasks)
    assert kinds == sorted(kinds, key=["reference", "frame", "compare"].index)
    refs = {t.key for t in tasks if t.kind == "reference"}
    frames = {t.key for t in tasks if t.kind == "frame"}
    for t in tasks:
        if t.kind == "compare":
            assert t.deps[0] in frames and t.deps[1] in refs


def test_task_keys_are_stable_and_follow_scene_file_content(tmp_path):
    scene = tmp_path / "my.toml"
    scene.write_text("# one version\n")
    path = _write(tmp_path, BASE)
    keys = [t.key for t in expand(load_spec(path))]
    assert keys == [t.key for t in expand(load_spec(path))]
    h1 = load_spec(path).hash
    scene.write_text("# another version\n")
    keys2 = [t.key for t in expand(load_spec(path))]
    changed = {a for a, b in zip(keys, keys2, strict=True) if a != b}
    # exactly the tasks of the edited file changed (all of them); the built-in scene's did not
    assert changed == {k for k in keys if "-my-" in k} and len(changed) == len(keys) // 2
    assert load_spec(path).hash != h1
    # where the results go does not change what the sweep is
    moved = spec_from_dict({**tomllib.loads(BASE), "sweep": {**tomllib.loads(BASE)["sweep"], "out": "elsewhere"}},
                           path)
    assert moved.hash == load_spec(path).hash and moved.out == str(tmp_path / "elsewhere")


def test_no_time_table_keeps_the_scene_sun(tmp_path):
    spec = load_spec(_write(tmp_path, '[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n'))
    assert spec.times == (None,) and spec.produce == ("frame",) and spec.qualities == (DEFAULT_QUALITY,)
    (task,) = expand(spec)
    assert task.kind == "frame" and task.inputs["time"] is None


@pytest.mark.parametrize("text, message", [
    ('[sweep]\nsizes = ["8x8"]\n', "[sweep]: needs scenes"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8by8"]\n', "[sweep].sizes: size must look like 320x180, got '8by8'"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["9000x8"]\n', "[sweep].sizes: size must be within 1..8192 pixels"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\nproduce = ["movie"]\n', "[sweep].produce: unknown product 'movie'"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\nquality = ["ultra"]\n',
     "[sweep].quality: unknown quality 'ultra' (known: paper, lpv, lpv-fast, traced-probes, baseline)"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\ncolour = 1\n', "[sweep]: unknown key 'colour'"),
    ('[sweep]\nscenes = []\nsizes = ["8x8"]\n', "[sweep].scenes: must not be empty"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[time]\nstart = "2024-06-21 06:00"\n', "[time]: needs start, end"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[time]\nstart = "2024-06-21 08:00"\nend = "2024-06-21 07:00"\n'
     'step_minutes = 5\n', "is before start"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[time]\nstart = "2024-06-31 08:00"\nend = "2024-07-01 07:00"\n'
     'step_minutes = 5\n', "[time].start: time '2024-06-31 08:00': day 31 does not exist"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[time]\nstart = "2024-06-21 06:00"\nend = "2024-06-21 07:00"\n'
     'step_minutes = 0\n', "[time].step_minutes: must be a number"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[reference]\nspp = 0\n', "[reference].spp: must be an integer"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[reference]\ncomponent = "all"\n', "[reference].component"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[render]\nexposure = -1\n', "[render].exposure"),
    ('[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n[camera]\nfov = 3\n', "unknown table [camera]"),
    ('[sweep\n', "not valid TOML"),
])
def test_bad_sweep_files_give_one_line_errors_naming_file_and_field(tmp_path, text, message):
    path = _write(tmp_path, text)
    with pytest.raises(SerenityError) as e:
        load_spec(path)
    msg = str(e.value)
    assert message in msg and msg.startswith(path) and "\n" not in msg


def test_missing_sweep_file(tmp_path):
    with pytest.raises(SerenityError, match="sweep file not found"):
        load_spec(str(tmp_path / "nope.toml"))


def test_qualities_are_the_presets_and_the_baseline():
    for name in QUALITY_PRESETS:
        assert quality_config(name) == RenderConfig.preset(name)
    base = quality_config("baseline")
    assert (base.ambient, base.lpv.enabled, base.sky.enabled) == ("constant", False, False)
    assert base.shadow == RenderConfig.preset(DEFAULT_QUALITY).shadow


def test_atomic_write_keeps_the_old_file_when_the_writer_fails(tmp_path):
    path = str(tmp_path / "sub" / "x.txt")
    atomic_write(path, lambda p: open(p, "w").write("first"))
    assert open(path).read() == "first"

    def broken(p):
        with open(p, "w") as f:
            f.write("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError):
        atomic_write(path, broken)
    assert open(path).read() == "first"
    assert os.listdir(tmp_path / "sub") == ["x.txt"]  # no temporary left behind


def test_without_dask_the_command_names_the_extra(tmp_path, capsys, monkeypatch):
    import sys

    from serenity.cli import main

    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    path = _write(tmp_path, '[sweep]\nscenes = ["plane"]\nsizes = ["8x8"]\n')
    assert main(["sweep", path, "--out", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err == ("serenity: error: a sweep on Dask needs the optional package Dask (dask[distributed]): "
                   "pip install 'serenity[eval]'\n")


def test_a_changed_preset_means_new_frame_keys_but_the_same_references(tmp_path, monkeypatch):
    from dataclasses import replace

    import serenity.sweep.spec as spec_module

    spec = load_spec(_write(tmp_path, BASE))
    before = {t.key: t.kind for t in expand(spec)}
    real = spec_module.quality_config
    monkeypatch.setattr(spec_module, "quality_config",
                        lambda q: replace(real(q), exposure=0.5) if q == "lpv-fast" else real(q))
    after = {t.key: t.kind for t in expand(spec)}
    gone = set(before) - set(after)
    assert {before[k] for k in gone} == {"frame", "compare"}
    assert all("-lpv_fast-" in k for k in gone)  # the key spells - as _
    assert {k for k, kind in before.items() if kind == "reference"} <= set(after)
