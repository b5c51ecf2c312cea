"""Temporal anti-aliasing (``RenderConfig.antialiasing = "taa"``, ``serenity/raster/taa.py``): a still
view converges to the jittered mean, a moving one keeps its history, disocclusions start afresh,
and the history restarts on a resize, a camera cut and a new config."""

import dataclasses

import numpy as np
import pytest

from serenity.config import LPVConfig, RayTracingConfig, RenderConfig, SkyConfig
from serenity.errors import ConfigError, SerenityError
from serenity.frame import Renderer
from serenity.raster.taa import TAAConfig, jitter_offset
from serenity.scene.model import Camera, Material, Scene

from .scenes import box, plane_scene, quad

#: direct light only: cheap frames, and the only change from frame to frame is the jitter
QUICK = dict(lpv=LPVConfig(enabled=False), sky=SkyConfig(enabled=False), rt=RayTracingConfig(enabled=False))
W, H = 64, 36


def _renderer(scene, aa="taa", w=W, h=H, **config):
    return Renderer(scene, w, h, config=RenderConfig(**QUICK, antialiasing=aa, **config))


def _edges(frame) -> np.ndarray:
    """Pixels with a depth discontinuity (or a coverage change) in their 3x3 neighbourhood."""
    z = frame.aovs["depth"][..., 0]
    z = np.where(np.isfinite(z), z, 1e6)
    out = np.zeros(z.shape, bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            n = np.roll(np.roll(z, dy, 0), dx, 1)
            out |= np.abs(n - z) > 0.05 * np.minimum(n, z)
    out[[0, -1], :] = out[:, [0, -1]] = False
    return out


def _truck(cam: Camera, metres: float) -> Camera:
    right = np.cross(cam.forward, cam.up)
    d = metres * right / np.linalg.norm(right)
    return Camera(position=cam.position + d, target=cam.target + d, up=cam.up, fov_y_deg=cam.fov_y_deg)


def test_config_validation():
    assert RenderConfig(antialiasing="taa").antialiasing == "taa"
    for bad in ("TAA", "msaa", None):
        with pytest.raises(ConfigError, match="RenderConfig.antialiasing") as e:
            RenderConfig(antialiasing=bad)
        assert "\n" not in str(e.value)
    for bad in (dict(alpha=0.0), dict(gamma=-1.0), dict(cycle=0), dict(weights="max")):
        with pytest.raises(SerenityError, match="TAAConfig"):
            TAAConfig(**bad)


def test_first_frame_is_the_plain_frame_and_the_stage_is_timed(gl_ctx):
    """A single frame (``serenity render``) is unjittered and shown as rendered: what "none" gives."""
    scene = plane_scene(with_box=True)
    plain = _renderer(scene, "none").render()
    taa = _renderer(scene)
    first = taa.render()
    assert np.array_equal(first.hdr, plain.hdr)
    second = taa.render()
    assert "anti-aliasing" in second.timings
    assert not np.array_equal(second.hdr, plain.hdr)  # jittered, blended
    assert jitter_offset(0) == (0.0, 0.0) and all(-0.5 <= v < 0.5 for i in range(1, 16) for v in jitter_offset(i))


def test_still_view_converges_to_the_jittered_mean_on_edges(gl_ctx):
    scene = plane_scene(with_box=True)
    plain = _renderer(scene, "none")
    raw = plain.render()
    mean = plain.render_accumulated(8)  # the same 8 sub-pixel positions as TAA's cycle
    edges = _edges(raw) & (np.abs(raw.hdr - mean.hdr).max(-1) > 1e-2 * mean.hdr.max())
    assert edges.sum() > 20
    taa = _renderer(scene)
    frames = [taa.render() for _ in range(8)]
    err = {name: np.abs(img - mean.hdr).mean(-1)[edges].mean()
           for name, img in (("raw", raw.hdr), ("taa", frames[-1].hdr))}
    # the first 8 frames average evenly: only the neighbourhood clip keeps it from the mean itself
    assert err["taa"] < 0.25 * err["raw"], err
    # flat areas stay as they are
    flat = ~_edges(raw)
    flat &= np.abs(raw.hdr - mean.hdr).max(-1) < 1e-4 * mean.hdr.max()
    assert np.allclose(frames[-1].hdr[flat], mean.hdr[flat], rtol=1e-3, atol=1e-3 * mean.hdr.max())
    # an explicit jitter replaces TAA's own (the viewer's and render_accumulated's): nothing doubles
    r = _renderer(scene)
    for _ in range(6):
        f = r.render(jitter=(0.0, 0.0))
    assert np.allclose(f.hdr, raw.hdr, rtol=1e-4, atol=1e-4 * raw.hdr.max())


def test_moving_camera_keeps_its_history(gl_ctx):
    """A static scene under a trucking camera: the resolved image is nearer a supersampled one than
    the raw frame on the edges (the history follows the surfaces)."""
    scene = plane_scene(with_box=True)
    base = scene.camera
    taa = _renderer(scene, w=80, h=45)
    for k in range(16):
        scene.camera = _truck(base, 0.04 * k)
        out = taa.render()
    assert taa.taa_pass.frames == 16  # no reset on the way
    plain = _renderer(scene, "none", w=80, h=45)
    raw = plain.render()
    mean = plain.render_accumulated(16)
    edges = _edges(raw) & (np.abs(raw.hdr - mean.hdr).max(-1) > 1e-2 * mean.hdr.max())
    assert edges.sum() > 20
    e_raw = np.abs(raw.hdr - mean.hdr).mean(-1)[edges].mean()
    e_taa = np.abs(out.hdr - mean.hdr).mean(-1)[edges].mean()
    assert e_taa < 0.6 * e_raw, (e_taa, e_raw)


def _floating_box_scene():
    """A red box floating near the camera over a grey plane: trucking the camera slides it over the
    plane fast (parallax), uncovering plane that it hid in the frame before."""
    scene = plane_scene()
    meshes = [quad("plane", 20.0, 0), box("box", (0.0, 6.0, 6.0), (1.5, 1.5, 1.5), 1)]
    materials = [Material("plane", albedo=(0.5, 0.5, 0.5)), Material("box", albedo=(0.9, 0.05, 0.05))]
    return Scene("floating box", meshes, materials, scene.camera, scene.sun, scene.sky)


def test_disocclusion_shows_no_ghost(gl_ctx):
    """Where the box uncovered the plane since the last frame, the pixel shows this frame's plane,
    not the box's red: the history's depth test rejects it, and the clip removes what an edge's
    pixels held of it (with the clip off, the depth test alone keeps most pixels clean)."""
    scene = _floating_box_scene()
    base = scene.camera
    taa = {"clip": _renderer(scene, w=80, h=45), "no clip": _renderer(scene, w=80, h=45)}
    taa["no clip"].taa_pass.config = TAAConfig(clip=False)
    plain = _renderer(scene, "none", w=80, h=45)
    now = None
    for k in range(7):
        scene.camera = _truck(base, 1.0 * k)
        before, now = now, plain.render()
        out = {name: r.render() for name, r in taa.items()}
    red = lambda f: f.hdr[..., 0] - f.hdr[..., 1]  # noqa: E731 (the box's colour: the plane is grey)
    box_now, box_before = red(now) > 0.3 * red(now).max(), red(before) > 0.3 * red(now).max()
    # the uncovered pixels: the box's last frame, not its this one, nor beside its edges now
    near_edge = _edges(now)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            near_edge |= np.roll(np.roll(box_now, dy, 0), dx, 1)
    uncovered = box_before & ~near_edge
    assert uncovered.sum() >= 10
    contrast = float(np.median(red(before)[box_before]))
    assert contrast > 10 * np.abs(red(now)[uncovered]).max()  # the plane there is grey indeed
    ghost = {name: np.abs(red(f)[uncovered]) / contrast for name, f in out.items()}
    assert np.percentile(ghost["clip"], 95) < 0.05, np.percentile(ghost["clip"], 95)
    assert np.percentile(ghost["no clip"], 75) < 0.05, np.percentile(ghost["no clip"], 75)


def test_history_restarts_on_a_cut_a_new_config_and_a_resize(gl_ctx):
    scene = plane_scene(with_box=True)
    base = scene.camera
    taa = _renderer(scene)
    for k in range(3):
        scene.camera = _truck(base, 0.05 * k)
        taa.render()
    assert taa.taa_pass.frames == 3
    # a cut (a jump of 10 m: a quarter of the scene's extent) shows the new view as rendered
    scene.camera = _truck(base, 10.0)
    cut = taa.render()
    assert taa.taa_pass.frames == 1
    assert np.array_equal(cut.hdr, _renderer(scene, "none").render().hdr)
    taa.render()
    # a new config: the same
    taa.config = dataclasses.replace(taa.config, exposure=taa.config.exposure * 2)
    changed = taa.render()
    assert taa.taa_pass.frames == 1
    plain = Renderer(scene, W, H, config=dataclasses.replace(taa.config, antialiasing="none"))
    assert np.array_equal(changed.hdr, plain.render().hdr)
    # a resize drops the history; the same size keeps it
    p = taa.taa_pass
    taa.render()
    p.resize(W, H)
    assert p.has_history and p.frames == 2
    p.resize(W // 2, H // 2)
    assert not p.has_history and p.frames == 0
    p.resize(W, H)

