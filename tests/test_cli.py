"""The `serenity` command: it renders what it says, and bad input ends in one line, not a traceback."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from serenity.cli import main


def _run(args, capsys):
    code = main(args)
    out, err = capsys.readouterr()
    return code, out, err


def test_render_writes_png_and_multilayer_exr(tmp_path, capsys):
    from PIL import Image

    from serenity.io.exr import read_exr

    png = tmp_path / "out" / "plane.png"
    js = tmp_path / "out" / "plane.json"
    code, out, err = _run(["render", "plane", "--size", "48x32", "-o", str(png), "--frames", "1", "--json", str(js)],
                          capsys)
    assert code == 0, err
    rec = json.loads(js.read_text())  # what it printed, as data
    assert rec["size"] == [48, 32] and rec["scene"] == "plane" and rec["frame_ms"] > 0
    assert "g-buffer" in rec["stages_ms"] and "beauty" in rec["layers"] and rec["nonfinite_pixels"] == 0
    assert "warning" not in err
    assert Image.open(png).size == (48, 32)
    layers = read_exr(str(png.with_suffix(".exr")))
    assert {"beauty", "albedo", "normal", "depth", "direct"} <= set(layers)
    assert layers["beauty"].shape == (32, 48, 3)
    assert np.all(np.isfinite(layers["beauty"]))
    for stage in ("g-buffer", "direct lighting", "total"):
        assert stage in out


def test_render_warns_of_nonfinite_pixels(tmp_path, capsys, monkeypatch):
    # a frame whose HDR image holds NaN (the tone map counts them on the GL side): the command says
    # so on stderr instead of writing a silently wrong image
    from serenity.frame import Renderer

    real = Renderer.render

    def render(self, *a, **k):
        frame = real(self, *a, **k)
        frame.hdr[0, 0] = np.nan
        frame.nonfinite_pixels = 1
        return frame

    monkeypatch.setattr(Renderer, "render", render)
    png = tmp_path / "p.png"
    code, _, err = _run(["render", "plane", "--size", "24x16", "-o", str(png), "--frames", "1"], capsys)
    assert code == 0
    assert "warning: 1 of 384 pixels are NaN or infinite" in err


def test_every_command_renders_the_renderers_default_preset(tmp_path, capsys, monkeypatch):
    """``serenity render`` with no --quality renders exactly the config ``Renderer(scene, w, h)``
    gets without one, and closes its Renderer; bench, view and sweep default to the same preset."""
    from serenity.cli import build_parser
    from serenity.config import DEFAULT_QUALITY
    from serenity.frame import Renderer
    from serenity.scene import load
    from serenity.sweep import spec_from_dict

    seen, closed = [], []
    real_init, real_close = Renderer.__init__, Renderer.close

    def init(self, *a, **k):
        real_init(self, *a, **k)
        seen.append(self.config)

    def close(self):
        closed.append(self)
        real_close(self)

    monkeypatch.setattr(Renderer, "__init__", init)
    monkeypatch.setattr(Renderer, "close", close)
    code, out, err = _run(["render", "plane", "--size", "16x16", "--frames", "1", "-o", str(tmp_path / "p.png")],
                          capsys)
    assert code == 0, err
    assert f"quality {DEFAULT_QUALITY};" in out
    assert len(seen) == 1 and len(closed) == 1
    with Renderer(load("plane"), 16, 16) as r:
        assert r.config == seen[0]
    parser = build_parser()
    for command in ("render", "bench", "view"):
        assert parser.parse_args([command]).quality == DEFAULT_QUALITY, command
    assert spec_from_dict({"sweep": {"scenes": ["plane"], "sizes": ["8x8"]}}).qualities == (DEFAULT_QUALITY,)


def test_a_former_quality_name_works_and_says_its_new_name_in_one_line(capsys):
    from serenity.cli import build_parser, main

    with pytest.warns(FutureWarning, match="quality preset 'high' is now called 'lpv'"):
        assert build_parser().parse_args(["bench", "--quality", "high"]).quality == "lpv"
    # through main: one line on stderr, then the command goes on (here to a one-line error of its own)
    code = main(["render", "no_such_scene", "--quality", "medium", "--size", "8x8"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 2, err
    assert err[0] == "serenity: warning: quality preset 'medium' is now called 'lpv-fast'"
    assert err[1].startswith("serenity: error:") and "no_such_scene" in err[1]


def _one_line_error(code, err, *words):
    assert code == 2
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("serenity: error:")
    assert "Traceback" not in err
    for w in words:
        assert w.lower() in lines[0].lower(), lines[0]


def test_missing_file(tmp_path, capsys):
    path = tmp_path / "nope.glb"
    code, _, err = _run(["render", str(path), "--size", "16x16"], capsys)
    _one_line_error(code, err, "nope.glb")


def test_corrupt_mesh(tmp_path, capsys):
    path = tmp_path / "broken.glb"
    path.write_bytes(b"glTF\x02\x00\x00\x00garbage-that-is-not-a-gltf" * 3)
    code, _, err = _run(["render", str(path), "--size", "16x16"], capsys)
    _one_line_error(code, err, "broken.glb")


def test_nan_vertices(tmp_path, capsys):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv nan 1 0\nv 0 1 1\nf 1 2 3\nf 1 2 4\n")
    code, _, err = _run(["render", str(path), "--size", "16x16"], capsys)
    _one_line_error(code, err, "nan")


def test_empty_scene(tmp_path, capsys):
    path = tmp_path / "empty.obj"
    path.write_text("# nothing here\nv 0 0 0\n")
    code, _, err = _run(["render", str(path), "--size", "16x16"], capsys)
    _one_line_error(code, err, "empty.obj")


@pytest.mark.parametrize("when", ["2026-13-01 12:00", "2026-02-30 12:00", "2026-06-01 25:00", "noon"])
def test_impossible_time(when, capsys):
    code, _, err = _run(["render", "plane", "--size", "16x16", "--time", when], capsys)
    _one_line_error(code, err)


def test_bad_size(capsys):
    code, _, err = _run(["render", "plane", "--size", "big"], capsys)
    _one_line_error(code, err, "size")


def test_unknown_scene_name(capsys):
    code, _, err = _run(["render", "no-such-scene", "--size", "16x16"], capsys)
    _one_line_error(code, err, "no-such-scene")


def test_scenes_lists_builtins(capsys):
    code, out, _ = _run(["scenes"], capsys)
    assert code == 0
    for name in ("courtyard", "cornell"):
        assert name in out


def test_console_script_exit_status(tmp_path):
    """The installed entry point (a real process): error → status 2, one line, no traceback."""
    r = subprocess.run([sys.executable, "-m", "serenity", "render", str(tmp_path / "missing.obj")],
                       capture_output=True, text=True, timeout=120, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    assert r.returncode == 2
    assert "Traceback" not in r.stderr
    assert "missing.obj" in r.stderr


def test_every_command_module_is_registered():
    """Each module of serenity/commands (but the shared helpers) is in cli.COMMANDS, with register()."""
    import pkgutil

    import serenity.commands
    from serenity.cli import COMMANDS

    names = {m.name for m in pkgutil.iter_modules(serenity.commands.__path__)} - {"common"}
    assert names == {c.__name__.rsplit(".", 1)[1] for c in COMMANDS}
    assert all(callable(c.register) for c in COMMANDS)


def test_help_is_light_and_lists_commands_whose_extras_are_missing():
    """``serenity --help`` with the eval extra's packages missing still lists reference and compare,
    and loads neither Warp, OpenGL, trimesh nor numpy (a command imports what it runs when it runs)."""
    code = ("import sys\n"
            "for m in ('mitsuba', 'flip_evaluator', 'matplotlib'): sys.modules[m] = None\n"
            "from serenity.cli import main\n"
            "try:\n    main(['--help'])\nexcept SystemExit:\n    pass\n"
            "print('LOADED', sorted(m for m in ('warp', 'moderngl', 'trimesh', 'numpy') if m in sys.modules))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    for command in ("render", "scenes", "bench", "reference", "compare"):
        assert command in r.stdout
    assert "LOADED []" in r.stdout


def test_missing_optional_package_names_the_extra(tmp_path, capsys, monkeypatch):
    from serenity.io.exr import write_exr

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    monkeypatch.setitem(sys.modules, "mitsuba", None)  # import mitsuba -> ImportError
    code, _, err = _run(["reference", "plane", "--size", "8x8", "-q", "-o", str(tmp_path / "ref.exr")], capsys)
    _one_line_error(code, err, "mitsuba", "pip install 'serenity[eval]'")

    monkeypatch.setitem(sys.modules, "flip_evaluator", None)
    img = str(tmp_path / "img.exr")
    write_exr(img, {"beauty": np.ones((4, 4, 3), np.float32)})
    code, _, err = _run(["compare", img, img], capsys)
    _one_line_error(code, err, "flip-evaluator", "pip install 'serenity[eval]'")


def test_render_on_a_missing_gpu_is_one_line(tmp_path):
    """`serenity render --device cuda:0` where there is no such device (a real process, so Warp's native
    output counts too): status 2 and exactly one line on stderr, naming the device and what exists."""
    from serenity.device import available_devices

    if "cuda:0" in available_devices():
        pytest.skip("this machine has cuda:0")
    env = {k: v for k, v in os.environ.items() if k != "SERENITY_DEVICE"}
    r = subprocess.run([sys.executable, "-m", "serenity", "render", "plane", "--device", "cuda:0", "--size", "16x16",
                        "-o", str(tmp_path / "x.png")], capture_output=True, text=True, timeout=120,
                       env={**env, "PYTHONUNBUFFERED": "1"})
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode == 2, r.stderr
    assert len(lines) == 1, r.stderr
    assert lines[0].startswith("serenity: error:") and "cuda:0" in lines[0] and "cpu" in lines[0]
    assert not (tmp_path / "x.png").exists()
