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
from serenity.config import DEFAULT_EXPOSURE
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
    # the slider starts where the built-in scenes' sun is
    from serenity.scene import load

    scene = load("courtyard")
    assert np.allclose(TimeOfDay.for_scene(scene).sun(scene.sun).direction, scene.sun.direction, atol=1e-9)


def test_settings_rebuild_only_for_what_render_does_not_read_per_frame():
    from serenity.config import DEFAULT_QUALITY
    from serenity.frame import Renderer
    from serenity.view.controls import Settings, quality_config

    q = "lpv-fast"  # a preset with every technique (the default, traced-probes, has no SSAO and no LPV)
    s = Settings(quality=q)
    base = s.config()
    for name, value in (("exposure", 0.05), ("ssao", False), ("shadow_filter", "pcf"), ("lpv_diffuse", False),
                        ("lpv_glossy", False), ("reflections", False), ("refractions", False), ("taa", False)):
        t = Settings(quality=q, **{name: value})
        assert not Renderer.needs_rebuild(base, t.config()), name
    for name, value in (("sky_lighting", False), ("quality", "traced-probes")):
        assert Renderer.needs_rebuild(base, Settings(**{"quality": q, name: value}).config()), name
    # one term of a pair switches live; both off turns the technique off, which needs a rebuild
    lpv = Settings(quality=q, lpv_glossy=False).config().lpv
    assert lpv.enabled and lpv.diffuse and not lpv.glossy
    off = Settings(quality=q, lpv_diffuse=False, lpv_glossy=False).config()
    assert not off.lpv.enabled and Renderer.needs_rebuild(base, off)
    rt = Settings(quality=q, refractions=False).config()
    assert rt.rt.enabled and rt.rt.reflections and not rt.rt.refractions
    off = Settings(quality=q, reflections=False, refractions=False).config()
    assert not off.rt.enabled and Renderer.needs_rebuild(base, off)
    assert quality_config(DEFAULT_QUALITY) == Settings().config(), "the viewer starts at serenity render's quality"
    with pytest.raises(SerenityError, match="quality preset"):
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


def test_view_bad_options_are_one_line(tmp_path, capsys):
    for args, words in ((["--script", str(tmp_path / "none.toml")], ("none.toml", "not found")),
                        (["--exit-after", "0"], ("--exit-after",)),
                        (["--screenshot", "a.jpg"], (".png",)),
                        (["--exposure", "-1"], ("exposure",))):
        code = main(["view", "plane", "--size", "32x18", *args])
        _one_line_error(code, capsys.readouterr().err, *words)


def test_view_without_a_display_is_one_line(monkeypatch, capsys):
    pytest.importorskip("glfw")  # without it the one line names the missing package instead
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
set = { hour = 10.0, taa = false }
[[step]]
frame = 2
key = "W"
hold = 3
[[step]]
frame = 6
mouse = [40, 10]
[[step]]
frame = 7
set = { panel = false, ssao = false }
[[step]]
frame = 8
set = { lpv_diffuse = false, lpv_glossy = false, ssao = true }
[[step]]
frame = 9
set = { lpv_diffuse = true, lpv_glossy = true }
[[step]]
frame = {still}
press = "F12"
[[step]]
frame = {still}
screenshot = "still.png"
{views}
"""
TAA = 6
VIEW_STEPS = ("albedo", "normal", "direct", "ao", "rt mask", "sky light", "lpv indirect", "lpv cascades")


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
    still = 12  # from frame 10 nothing changes (the sky volume is current again by then)
    views = "".join(f'[[step]]\nframe = {still + 1 + i}\nset = {{ view = "{v}" }}\n'
                    f'[[step]]\nframe = {still + 1 + i}\nscreenshot = "view_{i}.png"\n'
                    for i, v in enumerate(VIEW_STEPS))
    # then temporal anti-aliasing on the still final view: TAA samples from frame taa0 on, converged
    # TAA frames later; a screenshot and F12 of the converged view; one step forward resets it
    taa0 = still + 1 + len(VIEW_STEPS)
    done = taa0 + TAA
    views += (f'[[step]]\nframe = {taa0}\nset = {{ view = "final", taa = true }}\n'
              f'[[step]]\nframe = {done}\nscreenshot = "taa.png"\n[[step]]\nframe = {done}\npress = "F12"\n'
              f'[[step]]\nframe = {done + 1}\nkey = "W"\n[[step]]\nframe = {done + 2}\nexit = true\n')
    (tmp_path / "s.toml").write_text(SCRIPT.replace("{still}", str(still)).replace("{views}", views))
    env = {**os.environ, "PYTHONPATH": ROOT}
    # lpv-fast: the live switches under test (SSAO, the LPV) are not in the default preset, traced-probes
    cmd = _xvfb_prefix() + [sys.executable, "-m", "serenity", "view", "courtyard", "--size", f"{SIZE[0]}x{SIZE[1]}",
                            "--quality", "lpv-fast", "--script", "s.toml", "--trace", "trace.json",
                            "--out-dir", "saved", "--taa", str(TAA)]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900, cwd=tmp_path)
    if p.returncode != 0 and "cannot open a window" in p.stderr:
        pytest.skip(f"no X server could be had: {p.stderr.strip().splitlines()[-1]}")
    assert p.returncode == 0, p.stderr[-3000:]
    trace = json.loads((tmp_path / "trace.json").read_text())
    assert trace["window_buffer_size"] == list(SIZE)
    f = {fr["frame"]: fr for fr in trace["frames"]}
    assert max(f) == done + 1
    assert not any(fr["read_back"] for fr in trace["frames"] if fr["frame"] not in (still, done))

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
    # SSAO switched live, the LPV off and on again by rebuilding the renderer (its GL objects released)
    assert [f[i]["ssao"] for i in (6, 7, 8)] == [True, False, True]
    assert [f[i]["renderer_builds"] for i in (7, 8, 9, still)] == [1, 2, 3, 3]
    assert f[still]["still_frames"] == still - 9

    # the still view's screenshot = the F12 PNG = `serenity render` of the F12 TOML
    shot = np.asarray(Image.open(tmp_path / "still.png").convert("RGB")).astype(np.int16)
    saved = tmp_path / "saved" / "courtyard_000"
    f12 = np.asarray(Image.open(str(saved) + ".png").convert("RGB")).astype(np.int16)
    out = tmp_path / "render.png"
    assert main(["render", str(saved) + ".toml", "--size", f"{SIZE[0]}x{SIZE[1]}", "--quality", "lpv-fast",
                 "-o", str(out)]) == 0
    ref = np.asarray(Image.open(out).convert("RGB")).astype(np.int16)
    assert shot.shape == ref.shape == (SIZE[1], SIZE[0], 3)
    assert np.array_equal(shot, f12), "the window shows exactly the frame F12 saved"
    diff = np.abs(shot - ref)
    assert diff.mean() < 0.5 and np.percentile(diff, 99) <= 4, (diff.mean(), np.percentile(diff, 99), diff.max())
    # and it is a picture, not a blank window
    assert shot.std() > 10

    # each AOV view shows what `serenity render` writes in that EXR layer (same still camera)
    from serenity.colour import linear_to_srgb, reinhard_srgb
    from serenity.io.exr import read_exr

    layers = read_exr(str(saved) + ".exr")
    shots = {v: np.asarray(Image.open(tmp_path / f"view_{i}.png").convert("RGB")).astype(np.int16)
             for i, v in enumerate(VIEW_STEPS)}
    expect = {
        "albedo": np.round(linear_to_srgb(layers["albedo"]) * 255),
        "normal": np.round(np.clip(0.5 + 0.5 * layers["normal"], 0, 1) * 255),
        "direct": reinhard_srgb(layers["direct"], DEFAULT_EXPOSURE),
        "ao": np.repeat(np.round(np.clip(layers["ao"], 0, 1) * 255), 3, axis=-1),
        "rt mask": np.repeat(layers["rt_mask"] * 255, 3, axis=-1),
    }
    for v, e in expect.items():
        d = np.abs(shots[v] - e.astype(np.int16))
        assert d.max() <= 1, (v, d.max(), d.mean())
    assert shots["rt mask"].max() == 255, "the courtyard's water is ray traced"
    for v in ("sky light", "lpv indirect"):
        assert shots[v].mean() > 5 and np.abs(shots[v] - shot).mean() > 5, v
    lines = np.any(shots["lpv cascades"] != shot, axis=-1)
    assert 0 < lines.mean() < 0.2, "the cascades' edges are drawn over the unchanged frame"

    # TAA: the still view's samples count up to TAA, converged only then; moving starts afresh
    assert [f[i]["taa_samples"] for i in range(taa0 - 1, done + 2)] == [0] + list(range(1, TAA + 1)) + [TAA, 1]
    assert [f[i]["converged"] for i in (taa0, done - 2, done - 1, done, done + 1)] == [False, False, True, True, False]
    # the converged view is Renderer.render_accumulated(TAA) of the same camera (F12's TOML), not one frame
    from serenity.config import RenderConfig
    from serenity.frame import Renderer

    taa_shot = np.asarray(Image.open(tmp_path / "taa.png").convert("RGB")).astype(np.int16)
    saved = str(tmp_path / "saved" / "courtyard_001")
    # F12 saves the mean (tone-mapped on the host; the window tone-maps in GL: one 8-bit step apart at most)
    saved_png = np.asarray(Image.open(saved + ".png").convert("RGB")).astype(np.int16)
    assert np.abs(saved_png - taa_shot).max() <= 1 and np.mean(saved_png != taa_shot) < 1e-3, "F12 saves the mean"
    r = Renderer(load(saved + ".toml"), *SIZE, config=RenderConfig.preset("lpv-fast"))
    try:
        acc, one = r.render_accumulated(TAA).ldr.astype(np.int16), r.render().ldr.astype(np.int16)
    finally:
        r.close()
    assert np.abs(taa_shot - acc).max() <= 1
    assert np.percentile(np.abs(taa_shot - one).max(-1), 99) > 8, "the edges are anti-aliased"


REF_SCRIPT = """
[[step]]
frame = 0
set = { taa = false }   # compared below with F12's frame: one unjittered frame, as R saw it
[[step]]
frame = 1
press = "R"
[[step]]
frame = 2
wait = "reference"
[[step]]
frame = 2
screenshot = "split.png"
[[step]]
frame = 3
set = { view = "flip error" }
[[step]]
frame = 3
press = "F12"
[[step]]
frame = 3
screenshot = "flip.png"
[[step]]
frame = 4
exit = true
"""


@pytest.mark.gl
@pytest.mark.slow
def test_scripted_reference_split_view_and_numbers(tmp_path):
    """R path-traces the view in the background; the split view shows our frame left of the line and
    the reference right of it, and the panel's FLIP / relMSE are those of `serenity compare`."""
    pytest.importorskip("moderngl_window")
    pytest.importorskip("mitsuba")
    from PIL import Image

    from serenity.colour import reinhard_srgb
    from serenity.eval.metrics import compare, flip_png
    from serenity.eval.reference import render_reference
    from serenity.io.exr import read_exr
    from serenity.scene import load
    from serenity.view.reference_job import chunk_plan

    w, h, spp = 64, 36, 4
    (tmp_path / "s.toml").write_text(REF_SCRIPT)
    env = {**os.environ, "PYTHONPATH": ROOT, "SERENITY_CACHE": str(tmp_path / "cache")}
    cmd = _xvfb_prefix() + [sys.executable, "-m", "serenity", "view", "courtyard", "--size", f"{w}x{h}", "--no-panel",
                            "--spp", str(spp), "--script", "s.toml", "--trace", "trace.json", "--out-dir", "saved"]
    p = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=1200, cwd=tmp_path)
    if p.returncode != 0 and "cannot open a window" in p.stderr:
        pytest.skip(f"no X server could be had: {p.stderr.strip().splitlines()[-1]}")
    assert p.returncode == 0, p.stderr[-3000:]
    frames = json.loads((tmp_path / "trace.json").read_text())["frames"]
    got = frames[-1]["comparison"]
    assert got is not None and frames[2]["view"] == "reference split"

    # the same reference again, from the cache the viewer's worker filled (same scene, seeds, chunks)
    os.environ["SERENITY_CACHE"] = str(tmp_path / "cache")
    try:
        ours = read_exr(str(tmp_path / "saved" / "courtyard_000.exr"))["beauty"]
        scene = load(str(tmp_path / "saved" / "courtyard_000.toml"))
        ref = sum(render_reference(scene, w, h, spp=n, seed=s, progress=False).astype(np.float64) * n
                  for n, s in chunk_plan(spp, 8)) / spp
    finally:
        os.environ.pop("SERENITY_CACHE")
    m = compare(ours, ref.astype(np.float32))
    assert got["flip"] == pytest.approx(m["flip"], abs=1e-6) and got["rel_mse"] == pytest.approx(m["rel_mse"], rel=1e-5)

    split = np.asarray(Image.open(tmp_path / "split.png").convert("RGB")).astype(int)
    left = reinhard_srgb(ours, DEFAULT_EXPOSURE).astype(int)
    right = reinhard_srgb(ref.astype(np.float32), DEFAULT_EXPOSURE).astype(int)
    x = w // 2
    assert np.abs(split[:, : x - 2] - left[:, : x - 2]).max() <= 1
    assert np.abs(split[:, x + 2:] - right[:, x + 2:]).max() <= 1
    flip = np.asarray(Image.open(tmp_path / "flip.png").convert("RGB")).astype(int)
    assert np.abs(flip - flip_png(m["flip_map"]).astype(int)).max() <= 1


DRIVE = r"""
set -e
"$PY" -m serenity view plane --size 96x54 --no-panel --script ready.toml --exit-after 100000 --trace trace.json &
pid=$!
for i in $(seq 1 600); do [ -f ready.png ] && break; sleep 0.5; done
[ -f ready.png ] || { kill $pid; echo "viewer never got to frame 3" >&2; exit 3; }
wid=$(xdotool search --sync --name "Serenity")
xdotool windowfocus --sync "$wid"
xdotool keydown w; sleep 3; xdotool keyup w
sleep 1
xdotool mousemove --window "$wid" 48 27 mousedown 3; sleep 0.5
xdotool mousemove_relative --sync 30 0; sleep 1.5; xdotool mouseup 3
sleep 1
xdotool key Escape
wait $pid
"""


@pytest.mark.gl
@pytest.mark.slow
def test_real_x_input_moves_the_camera_and_escape_quits(tmp_path):
    """Key and mouse events from the X server (xdotool), through GLFW's callbacks, not the script."""
    pytest.importorskip("moderngl_window")
    if not shutil.which("xdotool") or not shutil.which("xvfb-run"):
        pytest.skip("needs xvfb-run and xdotool (tools/check_sysdeps.sh installs them)")
    (tmp_path / "ready.toml").write_text('[[step]]\nframe = 3\nscreenshot = "ready.png"\n')
    (tmp_path / "drive.sh").write_text(DRIVE)
    env = {**os.environ, "PYTHONPATH": ROOT, "PY": sys.executable}
    p = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 640x480x24", "sh", "drive.sh"], env=env,
                       capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    frames = json.loads((tmp_path / "trace.json").read_text())["frames"]
    first, last = frames[3], frames[-1]
    moved = np.array(last["camera_position"]) - np.array(first["camera_position"])
    assert np.dot(moved, first["camera_forward"]) > 0.05, moved
    # a rightward drag turned the view right: forward rotated clockwise seen from above
    assert np.cross(first["camera_forward"], last["camera_forward"])[1] < -1e-3


# What a window manager sends when the title bar's close button is clicked: a WM_PROTOCOLS client
# message carrying WM_DELETE_WINDOW (ICCCM 4.2.8.1). Xvfb runs no window manager, so it is sent
# here with Xlib (through ctypes: libX11 is what GLFW itself loads).
WM_CLOSE = r"""
import ctypes, sys
x = ctypes.cdll.LoadLibrary("libX11.so.6")
class ClientMessage(ctypes.Structure):
    _fields_ = [("type", ctypes.c_int), ("serial", ctypes.c_ulong), ("send_event", ctypes.c_int),
                ("display", ctypes.c_void_p), ("window", ctypes.c_ulong), ("message_type", ctypes.c_ulong),
                ("format", ctypes.c_int), ("data", ctypes.c_long * 5)]
class XEvent(ctypes.Union):
    _fields_ = [("xclient", ClientMessage), ("pad", ctypes.c_long * 24)]
x.XOpenDisplay.restype = ctypes.c_void_p
x.XOpenDisplay.argtypes = [ctypes.c_char_p]
x.XInternAtom.restype = ctypes.c_ulong
x.XInternAtom.argtypes = [ctypes.c_void_p, ctypes.c_char_p, ctypes.c_int]
x.XSendEvent.argtypes = [ctypes.c_void_p, ctypes.c_ulong, ctypes.c_int, ctypes.c_long, ctypes.POINTER(XEvent)]
x.XFlush.argtypes = x.XCloseDisplay.argtypes = [ctypes.c_void_p]
dpy = x.XOpenDisplay(None)
if not dpy:
    sys.exit("cannot open the display")
ev = XEvent()
ev.xclient.type, ev.xclient.window, ev.xclient.format = 33, int(sys.argv[1]), 32  # 33 = ClientMessage
ev.xclient.message_type = x.XInternAtom(dpy, b"WM_PROTOCOLS", 0)
ev.xclient.data[0] = x.XInternAtom(dpy, b"WM_DELETE_WINDOW", 0)
x.XSendEvent(dpy, int(sys.argv[1]), 0, 0, ctypes.byref(ev))
x.XFlush(dpy)
x.XCloseDisplay(dpy)
"""

CLOSE = r"""
"$PY" -m serenity view plane --size 64x36 --no-panel --script ready.toml --exit-after 100000 &
pid=$!
for i in $(seq 1 600); do [ -f ready.png ] && break; sleep 0.5; done
[ -f ready.png ] || { kill $pid; echo "viewer never got to frame 3" >&2; exit 3; }
wid=$(xdotool search --sync --name "Serenity")
"$PY" wm_close.py "$wid"
wait $pid
"""


@pytest.mark.gl
def test_closing_the_window_ends_with_one_line(tmp_path):
    """The window manager's close (title-bar X) ends the session: exit status 0, one line saying so,
    no traceback."""
    pytest.importorskip("moderngl_window")
    if not shutil.which("xdotool") or not shutil.which("xvfb-run"):
        pytest.skip("needs xvfb-run and xdotool (tools/check_sysdeps.sh installs them)")
    (tmp_path / "ready.toml").write_text('[[step]]\nframe = 3\nscreenshot = "ready.png"\n')
    (tmp_path / "wm_close.py").write_text(WM_CLOSE)
    (tmp_path / "close.sh").write_text(CLOSE)
    env = {**os.environ, "PYTHONPATH": ROOT, "PY": sys.executable}
    p = subprocess.run(["xvfb-run", "-a", "-s", "-screen 0 640x480x24", "sh", "close.sh"], env=env,
                       capture_output=True, text=True, timeout=600, cwd=tmp_path)
    assert p.returncode == 0, p.stderr[-3000:]
    assert "Traceback" not in p.stderr and not p.stderr.strip(), p.stderr[-3000:]
    out = [ln for ln in p.stdout.splitlines() if ln.strip() and not ln.startswith("wrote ")]
    assert len(out) == 1 and out[0].startswith("serenity view: window closed after"), p.stdout
