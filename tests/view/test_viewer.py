"""`serenity view`, for real: a scripted session in a window under Xvfb (the fly camera moves with
the keys and the mouse, the time slider moves the sun, F12 writes a TOML scene, and a screenshot of
the still view matches `serenity render` of that scene), plus the parts without a window."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from serenity.cli import main
from serenity.errors import SerenityError

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def _one_line_error(code, err, *words):
    assert code == 2
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert lines[0].startswith("serenity: error:")
    for w in words:
        assert w in lines[0], lines[0]


# ------------------------------------------------------------------------------- without a window


def test_fly_camera_moves_along_view_and_turns_with_the_mouse():
    from serenity.scene import load
    from serenity.view.controls import FlyCamera

    cam = load("plane").camera
    fly = FlyCamera.from_camera(cam, speed=2.0)
    assert np.allclose(fly.forward, cam.forward, atol=1e-6) or abs(math.degrees(math.asin(cam.forward[1]))) > 89
    p0 = fly.position.copy()
    assert fly.move({"W"}, 0.5)
    assert np.allclose(fly.position - p0, fly.forward * 1.0)
    assert not fly.move(set(), 0.5) and not fly.move({"W", "S"}, 0.5)
    fly.move({"E"}, 1.0)
    assert fly.position[1] == pytest.approx(p0[1] + fly.forward[1] + 2.0)
    yaw = fly.yaw_deg
    fly.look(100, 0)
    assert fly.yaw_deg == pytest.approx((yaw + 100 * fly.sensitivity) % 360)
    fly.look(0, 1e5)
    assert fly.pitch_deg == -89.0
    fly.apply(cam)
    assert np.allclose(cam.forward, fly.forward)


def test_time_of_day_gives_the_noaa_sun():
    from serenity.scene.model import Sun
    from serenity.scene.sun import sun_from_time
    from serenity.view.controls import TimeOfDay

    tod = TimeOfDay(date="2024-06-21", hour=9.5, latitude=38.72, longitude=-9.14, utc_offset=1.0)
    assert tod.text() == "2024-06-21 09:30 +01:00"
    sun = tod.sun(Sun(direction=[0, 1, 0]))
    assert np.allclose(sun.direction, sun_from_time("2024-06-21 09:30 +01:00", 38.72, -9.14).direction)
    tod.hour = 12.0
    assert sun.elevation_deg < tod.sun(sun).elevation_deg


def test_settings_rebuild_only_for_what_render_does_not_read_per_frame():
    from serenity.view.controls import Settings, quality_config

    s = Settings()
    base = s.config()
    for name, value in (("exposure", 0.05), ("ssao", False), ("shadow_filter", "pcf")):
        t = Settings(**{name: value})
        assert not Settings.needs_rebuild(base, t.config()), name
    for name, value in (("lpv", False), ("sky_lighting", False), ("ray_tracing", False), ("quality", "low")):
        assert Settings.needs_rebuild(base, Settings(**{name: value}).config()), name
    assert quality_config("low").shadow.size < quality_config("high").shadow.size
    with pytest.raises(SerenityError, match="--quality"):
        quality_config("ultra")


def test_script_errors_name_the_step(tmp_path):
    from serenity.view.script import load_script

    cases = {
        'step = 3': "step",
        '[[step]]\nframe = 1\nkey = "W"\nmouse = [1, 2]': "exactly one",
        '[[step]]\nframe = -1\nkey = "W"': "frame",
        '[[step]]\nframe = 1\nset = { hour = "noon" }': "hour must be a float",
        '[[step]]\nframe = 1\nset = { colour = 1.0 }': "cannot set 'colour'",
        '[[step]]\nframe = 1\nscreenshot = "a.jpg"': ".png",
        '[[step]]\nframe = 1\nmouse = [1]': "mouse",
        '[[step]]\nframe = 1\npress = "F12"\nhold = 2': "hold only goes with key",
    }
    for i, (text, words) in enumerate(cases.items()):
        p = tmp_path / f"s{i}.toml"
        p.write_text(text)
        with pytest.raises(SerenityError, match=words.replace(".", r"\.").replace("(", r"\(")):
            load_script(str(p))
    ok = tmp_path / "ok.toml"
    ok.write_text('[[step]]\nframe = 2\nkey = "w"\nhold = 3\n[[step]]\nframe = 9\nexit = true\n')
    s = load_script(str(ok))
    assert s.held(4) == {"W"} and s.held(5) == set() and s.last_frame == 9


def test_view_missing_scene_file_is_one_line(capsys):
    code = main(["view", "no/such/scene.toml"])
    _one_line_error(code, capsys.readouterr().err, "no/such/scene.toml", "not found")


def test_view_without_a_display_is_one_line(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    code = main(["view", "plane", "--size", "32x18"])
    _one_line_error(code, capsys.readouterr().err, "cannot open a window", "xvfb-run")


def test_view_unopenable_display_is_one_line(tmp_path):
    pytest.importorskip("glfw")
    env = {**os.environ, "DISPLAY": ":987", "PYTHONPATH": ROOT}
    env.pop("WAYLAND_DISPLAY", None)
    p = subprocess.run([sys.executable, "-m", "serenity", "view", "plane", "--size", "32x18"], env=env,
                       capture_output=True, text=True, timeout=300, cwd=tmp_path)
    _one_line_error(p.returncode, p.stderr, "cannot open a window", ":987")


# ------------------------------------------------------------------------------------- the window

SIZE = (160, 90)
SCRIPT = """
[[step]]
frame = 1
set = { hour = 10.0 }
[[step]]
frame = 2
key = "W"
hold = 3
[[step]]
frame = 6
mouse = [40, 10]
[[step]]
frame = 7
set = { panel = false }
[[step]]
frame = {still}
press = "F12"
[[step]]
frame = {still}
screenshot = "still.png"
[[step]]
frame = {still_plus}
exit = true
"""


def _xvfb_prefix() -> list[str]:
    xvfb = shutil.which("xvfb-run")
    if xvfb:
        return [xvfb, "-a", "-s", "-screen 0 1024x768x24"]
    if os.environ.get("DISPLAY"):
        return []
    pytest.skip("no X server: DISPLAY is unset and xvfb-run is not installed (tools/check_sysdeps.sh installs xvfb)")


@pytest.mark.gl
def test_scripted_viewer_moves_camera_and_sun_and_matches_render(tmp_path):
    pytest.importorskip("moderngl_window")
    pytest.importorskip("imgui_bundle")
    from PIL import Image

    from serenity.scene import load
    from serenity.scene.sun import sun_from_time

    scene = load("courtyard")
    still = 12  # frame 7 on nothing moves; the sky volume's 6-layer sweep after the sun step ends by frame 7
    (tmp_path / "s.toml").write_text(SCRIPT.replace("{still}", str(still)).replace("{still_plus}", str(still + 1)))
    env = {**os.environ, "PYTHONPATH": ROOT}
    cmd = _xvfb_prefix() + [sys.executable, "-m", "serenity", "view", "courtyard", "--size", f"{SIZE[0]}x{SIZE[1]}",
                            "--script", "s.toml", "--trace", "trace.json", "--out-dir", "saved"]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900, cwd=tmp_path)
    if p.returncode != 0 and "cannot open a window" in p.stderr:
        pytest.skip(f"no X server could be had: {p.stderr.strip().splitlines()[-1]}")
    assert p.returncode == 0, p.stderr[-3000:]
    trace = json.loads((tmp_path / "trace.json").read_text())
    assert trace["window_buffer_size"] == list(SIZE)
    f = {fr["frame"]: fr for fr in trace["frames"]}
    assert max(f) == still and not any(fr["read_back"] for fr in trace["frames"] if fr["frame"] != still)

    # the time slider moved the sun to the NOAA position of 10:00 at the scene's place
    want = sun_from_time("2024-06-21 10:00 +01:00", *scene.location).direction
    assert not np.allclose(f[0]["sun_direction"], want, atol=1e-3)
    assert np.allclose(f[1]["sun_direction"], want, atol=1e-9)
    # W held for frames 2-4 moved the camera 3 × speed/30 s along its view direction
    p0, p4 = np.array(f[1]["camera_position"]), np.array(f[4]["camera_position"])
    fwd = np.array(f[1]["camera_forward"])
    assert np.allclose(p4 - p0, fwd * 3.0 * 3 / 30.0, atol=1e-9)
    assert np.allclose(f[5]["camera_position"], p4)  # released
    # the mouse turned it right (yaw +) and down
    f5, f6 = np.array(f[5]["camera_forward"]), np.array(f[6]["camera_forward"])
    assert f6[1] < f5[1] and np.cross(f5, f6)[1] < 0
    # still and converged when saved
    assert f[still]["converged"] and f[still]["sky_stale_layers"] == 0
    assert f[8]["still_frames"] >= 1

    # the still view's screenshot = the F12 PNG = `serenity render` of the F12 TOML
    shot = np.asarray(Image.open(tmp_path / "still.png").convert("RGB")).astype(np.int16)
    saved = tmp_path / "saved" / "courtyard_000"
    f12 = np.asarray(Image.open(str(saved) + ".png").convert("RGB")).astype(np.int16)
    out = tmp_path / "render.png"
    assert main(["render", str(saved) + ".toml", "--size", f"{SIZE[0]}x{SIZE[1]}", "-o", str(out)]) == 0
    ref = np.asarray(Image.open(out).convert("RGB")).astype(np.int16)
    assert shot.shape == ref.shape == (SIZE[1], SIZE[0], 3)
    assert np.array_equal(shot, f12), "the window shows exactly the frame F12 saved"
    diff = np.abs(shot - ref)
    assert diff.mean() < 0.5 and np.percentile(diff, 99) <= 4, (diff.mean(), np.percentile(diff, 99), diff.max())
    # and it is a picture, not a blank window
    assert shot.std() > 10
