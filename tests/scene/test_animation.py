"""Rigid animation of meshes (``serenity.scene.animation``): keyframes, interpolation, repeats,
the scene posed at a time, the TOML ``[[animation]]`` tables and ``--at`` on the command line."""

import math
import subprocess
import sys

import numpy as np
import pytest

from serenity.errors import SceneError
from serenity.scene import build_scene, export_glb, load
from serenity.scene.animation import Animation, Track, axis_angle_quaternion, pose_scene


def _moved(track, time, p, pivot=(0.0, 0.0, 0.0)):
    m = track.matrix(time, np.asarray(pivot, float))
    return (m @ np.append(np.asarray(p, float), 1.0))[:3]


def test_linear_and_step_keyframes():
    t = Track("box", [0.0, 2.0, 4.0], translation=[[0, 0, 0], [2, 0, 0], [2, 4, 0]])
    assert np.allclose(_moved(t, 1.0, (0, 0, 0)), (1, 0, 0))
    assert np.allclose(_moved(t, 3.0, (0, 0, 0)), (2, 2, 0))
    assert np.allclose(_moved(t, -5.0, (0, 0, 0)), (0, 0, 0))   # holds the first keyframe before it ...
    assert np.allclose(_moved(t, 9.0, (0, 0, 0)), (2, 4, 0))    # ... and the last after it
    s = Track("box", [0.0, 2.0], translation=[[0, 0, 0], [2, 0, 0]], interpolation="step")
    assert np.allclose(_moved(s, 1.9, (0, 0, 0)), (0, 0, 0)) and np.allclose(_moved(s, 2.0, (0, 0, 0)), (2, 0, 0))


def test_rotation_slerps_about_the_pivot_and_scale_is_applied_first():
    q = [axis_angle_quaternion((0, 1, 0), 0.0), axis_angle_quaternion((0, 1, 0), 90.0)]
    t = Track("box", [0.0, 1.0], rotation=q, pivot=(1.0, 0.0, 0.0))
    half = _moved(t, 0.5, (2.0, 0.0, 0.0))  # 45 degrees about y through x = 1
    assert np.allclose(half, (1 + math.cos(math.radians(45)), 0, -math.sin(math.radians(45))))
    assert np.allclose(_moved(t, 0.5, (1.0, 0.0, 0.0)), (1, 0, 0))  # the pivot stays
    s = Track("box", [0.0, 1.0], scale=[1.0, 3.0])                    # a uniform scale per keyframe
    assert np.allclose(_moved(s, 1.0, (1.0, 1.0, 0.0), pivot=(0.0, 1.0, 0.0)), (3, 1, 0))


@pytest.mark.parametrize("repeat, at, x", [("once", 5.0, 2.0), ("loop", 5.0, 1.0), ("loop", 3.5, 1.5),
                                           ("pingpong", 5.0, 1.0), ("pingpong", 3.5, 0.5), ("pingpong", 2.5, 1.5)])
def test_repeats(repeat, at, x):
    t = Track("box", [0.0, 2.0], translation=[[0, 0, 0], [2, 0, 0]], repeat=repeat)  # x = t over 2 s
    assert np.isclose(_moved(t, at, (0, 0, 0))[0], x)


def test_posed_scene_moves_only_the_animated_mesh():
    scene = build_scene("cornell")
    turn = [axis_angle_quaternion((0, 0, 1), 0), axis_angle_quaternion((0, 0, 1), 90)]
    scene.animation = Animation([Track("red", [0.0, 1.0], translation=[[0, 0, 0], [0.0, 2.0, 0.0]], rotation=turn)])
    posed = pose_scene(scene, 1.0)
    before = {m.name: m for m in scene.meshes}
    after = {m.name: m for m in posed.meshes}
    assert after["white"] is before["white"] and after["green"] is before["green"]
    red0, red1 = before["red"], after["red"]
    centre = (red0.positions.min(axis=0) + red0.positions.max(axis=0)) / 2
    rel = red0.positions.astype(float) - centre
    expect = centre + (0, 2, 0) + rel @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]).T
    assert np.allclose(red1.positions, expect, atol=1e-5)
    assert np.allclose(red1.normals, red0.normals.astype(float) @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]]).T,
                       atol=1e-5)
    assert pose_scene(build_scene("cornell"), 3.0).meshes[0] is not None  # a still scene: itself


@pytest.mark.parametrize("kw, words", [
    ({"times": [0.0, 0.0]}, "must increase"),
    ({"times": [0.0, 1.0], "translation": [[0, 0, 0]]}, "2 keyframes of 3"),
    ({"times": [0.0, 1.0], "translation": [[0, 0, 0], [math.nan, 0, 0]]}, "NaN"),
    ({"times": [0.0, 1.0], "scale": [1.0, 0.0]}, "scale is zero"),
    ({"times": [0.0], "interpolation": "cubic"}, "linear or step"),
    ({"times": [0.0], "repeat": "forever"}, "repeat must be"),
])
def test_bad_tracks_are_one_line_errors(kw, words):
    with pytest.raises(SceneError, match=words):
        Track("box", **kw)


def _write(tmp_path, animation: str) -> str:
    export_glb(build_scene("cornell"), tmp_path / "c.glb")
    path = tmp_path / "c.toml"
    path.write_text('[scene]\nmesh = "c.glb"\n\n' + animation)
    return str(path)


def test_toml_animation_tables(tmp_path):
    path = _write(tmp_path, '[[animation]]\nmesh = "red"\ntimes = [0.0, 4.0]\n'
                            'translation = [[0.0, 0.0, 0.0], [0.0, 0.0, 2.0]]\nrotation_deg = [0.0, 180.0]\n'
                            'repeat = "pingpong"\n')
    scene = load(path)
    assert scene.animation is not None and scene.animation.mesh_names == {"red"}
    a = {m.name: m for m in pose_scene(scene, 2.0).meshes}["red"].positions
    b = {m.name: m for m in pose_scene(scene, 6.0).meshes}["red"].positions  # pingpong: back at t = 2
    assert np.allclose(a, b, atol=1e-5)
    moved = {m.name: m for m in pose_scene(scene, 4.0).meshes}["red"].positions
    rest = {m.name: m for m in scene.meshes}["red"].positions
    def centre(p):
        return (p.min(axis=0) + p.max(axis=0)) / 2

    # turned half a turn about its own centre and moved 2 m along z
    assert np.allclose(centre(moved), centre(rest) + (0, 0, 2), atol=1e-4)


@pytest.mark.parametrize("body, words", [
    ('[[animation]]\nmesh = "nope"\ntimes = [0.0]\n', "does not have"),
    ('[[animation]]\nmesh = "red"\ntimes = [0.0]\nspin = 3\n', "spin"),
    ('[[animation]]\ntimes = [0.0]\n', "needs mesh and times"),
    ('[[animation]]\nmesh = "red"\ntimes = [0.0, 1.0]\nrotation_deg = [0.0, 1.0]\naxis = [0, 0, 0]\n', "axis"),
])
def test_toml_animation_errors_name_the_file(tmp_path, body, words):
    path = _write(tmp_path, body)
    with pytest.raises(SceneError) as e:
        load(path)
    assert path in str(e.value) and words in str(e.value) and "\n" not in str(e.value)


def test_cli_renders_and_refuses_at(tmp_path):
    path = _write(tmp_path, '[[animation]]\nmesh = "red"\ntimes = [0.0, 1.0]\n'
                            'translation = [[0.0, 0.0, 0.0], [0.0, 0.5, 0.0]]\n')
    run = [sys.executable, "-m", "serenity", "render", path, "--size", "64x36", "--frames", "1",
           "-o", str(tmp_path / "a.png")]
    ok = subprocess.run(run + ["--at", "0.5"], capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr
    bad = subprocess.run(run + ["--at", "nan"], capture_output=True, text=True)
    assert bad.returncode != 0 and "--at must be a finite" in bad.stderr and "Traceback" not in bad.stderr
    still = subprocess.run([sys.executable, "-m", "serenity", "render", "cornell", "--size", "64x36", "--frames", "1",
                            "-o", str(tmp_path / "b.png"), "--at", "1"], capture_output=True, text=True)
    assert still.returncode != 0 and "has no animation" in still.stderr
