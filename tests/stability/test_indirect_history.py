"""The upsampled indirect light's temporal hysteresis (``IndirectConfig.history``,
``raster/temporal.py``): a pixel's indirect light moves a fraction a of the way to this frame's at
the same surface point, and a still view shows the light it would without it."""

from __future__ import annotations

import numpy as np
import pytest

from serenity.eval.stability import pan_camera, preset_config, reprojected
from serenity.frame import Renderer
from serenity.scene import load
from serenity.scene.model import direction_from_angles

pytestmark = pytest.mark.gl
SIZE = (96, 54)


def _pair(history: float):
    """Renderers of lpv-fast (quarter-resolution indirect light) without the LPV's own temporal blend
    and stagger, with and without the history."""
    out = []
    for a in (history, 1.0):
        cfg = preset_config("lpv-fast", {"indirect.history": a, "lpv.temporal_blend": 1.0, "lpv.stagger": False,
                                         "sky.transfer_layers": 0})
        out.append(Renderer(load("courtyard"), *SIZE, config=cfg))
    return out


def test_a_step_of_the_light_is_blended_in_at_the_history_weight(gl_ctx):
    """Camera still, the sun 3° lower from one frame to the next: the indirect light
    (HDR − direct) of the renderer with the history is then, at every surface pixel, the last
    frame's plus a·(this frame's − the last frame's) of the renderer without it; and a still view
    shows what it shows without the history."""
    a = 0.3
    hist, plain = _pair(a)
    try:
        frames = {}
        for name, r in (("hist", hist), ("plain", plain)):
            first = r.render()
            r.render()  # the same light again: nothing to blend
            again = r.render()
            sun = r.scene.sun
            sun.direction = direction_from_angles(sun.elevation_deg - 3.0, sun.azimuth_deg)
            frames[name] = (first, again, r.render())
        (h1, h_again, h2), (p1, p_again, p2) = frames["hist"], frames["plain"]
        surf = np.isfinite(p1.aovs["depth"][..., 0]) & (p1.aovs["rt_mask"][..., 0] == 0)
        ind = {k: (f.hdr - f.aovs["direct"])[surf] for k, f in (("h1", h1), ("h2", h2), ("p1", p1), ("p2", p2))}
        scale = float(np.abs(ind["p2"]).mean())
        np.testing.assert_allclose(h_again.hdr[surf], p_again.hdr[surf], rtol=2e-3, atol=2e-3 * scale)
        want = ind["p1"] + a * (ind["p2"] - ind["p1"])
        assert float(np.abs(ind["h2"] - want).mean()) < 0.01 * scale
        assert float(np.abs(ind["h2"] - ind["p2"]).mean()) > 0.3 * float(np.abs(ind["p2"] - ind["p1"]).mean())
    finally:
        hist.close()
        plain.close()


def test_a_moving_camera_blends_in_the_light_the_last_frame_showed_at_the_same_point(gl_ctx):
    """The camera moved 5 cm sideways and the sun 3° lower from one frame to the next, after still
    frames: where the last frame showed the point a pixel shows (the same surface around it, away from
    edges and ray-traced pixels: ``reprojected``'s mask), the indirect light of the renderer with the
    history is the last frame's there, bilinear, plus a·(this frame's − that) of the renderer without it."""
    a = 0.3
    hist, plain = _pair(a)
    w, h = SIZE
    try:
        frames = {}
        for name, r in (("hist", hist), ("plain", plain)):
            cam, sun = r.scene.camera, r.scene.sun
            r.render()
            first = r.render()
            r.scene.camera = pan_camera(cam, 0.05)
            sun.direction = direction_from_angles(sun.elevation_deg - 3.0, sun.azimuth_deg)
            frames[name] = (first, r.render(), cam.projection_matrix(w / h) @ cam.view_matrix())
        (h1, h2, vp), (p1, p2, _) = frames["hist"], frames["plain"]
        ok = np.isfinite(p2.aovs["depth"][..., 0]) & (p2.aovs["rt_mask"][..., 0] == 0)
        geo = (p1.aovs["position"], p1.aovs["normal"], vp, p2.aovs["position"], p2.aovs["normal"], ok)
        ind1 = h1.hdr - h1.aovs["direct"]
        _, keep = reprojected(ind1.mean(axis=-1), *geo)
        traced, _ = reprojected((p1.aovs["rt_mask"][..., 0] > 0).astype(np.float64), *geo, smooth=np.inf)
        keep &= traced == 0.0
        assert keep.mean() > 0.15  # (about half the view is sky)
        before = np.stack([reprojected(ind1[..., c], *geo, smooth=np.inf)[0] for c in range(3)], axis=-1)[keep]
        now = (h2.hdr - h2.aovs["direct"])[keep]
        plain_now = (p2.hdr - p2.aovs["direct"])[keep]
        scale = float(np.abs(plain_now).mean())
        want = before + a * (plain_now - before)
        assert float(np.abs(now - want).mean()) < 0.01 * scale
        assert float(np.abs(now - plain_now).mean()) > 0.3 * float(np.abs(plain_now - before).mean())
    finally:
        hist.close()
        plain.close()
