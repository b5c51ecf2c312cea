"""Staggered shadow tiles fade in (``ShadowConfig.stagger``, ``ShadowPass.render``): a tile after the
first is redrawn into its cascade's other atlas slot, and lookups take its version before at a
weight that falls by 1/(count − 1) a frame; once the sun stands still the image is the one of tiles
drawn for it."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from serenity.config import LPVConfig, RenderConfig, SkyConfig, SSAOConfig
from serenity.frame import Renderer
from serenity.raster.shadow import STAGGER_PAD, fit_shadow_cascades

from ..raster.scenes import plane_scene

pytestmark = pytest.mark.gl
BASE = RenderConfig(lpv=LPVConfig(enabled=False), ssao=SSAOConfig(enabled=False), sky=SkyConfig(enabled=False))


def _turn(sun0: np.ndarray, degrees: float) -> np.ndarray:
    """The sun turned about the vertical by ``degrees``."""
    a = math.radians(degrees)
    c, s = math.cos(a), math.sin(a)
    return np.array([c * sun0[0] + s * sun0[2], sun0[1], -s * sun0[0] + c * sun0[2]])


def test_a_redrawn_tile_keeps_its_version_before_and_its_weight_falls_each_frame(gl_ctx):
    """4 cascades, the sun turning 0.9° a frame: the first tile is redrawn in place every frame; each
    other tile, when redrawn, moves to its other slot of the 3 × 3 atlas, and its version before (the
    slot it left, the light matrix it was drawn with) has weight 2/3 that frame, 1/3 the next, none
    after; with the sun still, every tile ends up drawn for it and nothing fades."""
    scene = plane_scene(zenith_deg=50.0, azimuth_deg=40.0, with_box=True)
    r = Renderer(scene, 160, 90, config=replace(BASE, shadow=replace(BASE.shadow, stagger=True)))
    sp, cfg = r.shadow_pass, BASE.shadow
    sun0 = np.array(scene.sun.direction)

    def fit():
        return fit_shadow_cascades(scene.camera, 160 / 90, scene.sun.direction, scene.bounds, 4, sp.size,
                                   cfg.split_lambda, cfg.max_distance, pad=STAGGER_PAD)

    maps = sp.render(fit(), stagger=True)
    assert sp.tiles == 3 and sp.depth.width == 3 * sp.size
    assert [c.slot for c in maps.cascades] == [0, 1, 2, 3] and all(c.previous is None for c in maps.cascades)
    fading: dict[int, list[float]] = {}
    for k in range(1, 10):
        scene.sun.direction = _turn(sun0, 0.9 * k)
        before = {i: (c.slot, c.view_proj) for i, c in enumerate(maps.cascades)}
        maps = sp.render(fit(), stagger=True)
        assert sp.redrawn == 2
        assert maps.cascades[0].slot == 0 and maps.cascades[0].previous is None
        for i, c in enumerate(maps.cascades[1:], start=1):
            assert c.slot in (i, 3 + i)
            if c.slot != before[i][0]:  # redrawn this frame: the version before is the one shown last frame
                assert c.previous.slot == before[i][0] and np.array_equal(c.previous.view_proj, before[i][1])
                fading[i] = []
            if c.previous is not None:
                fading.setdefault(i, []).append(c.previous_weight)
                assert c.previous.slot != c.slot
    assert set(fading) == {1, 2, 3}
    for weights in fading.values():
        assert weights[:2] == pytest.approx([2 / 3, 1 / 3][:len(weights)])
        assert len(weights) <= 2
    for _ in range(6):  # still: the stale tiles are redrawn for this sun, then nothing fades
        maps = sp.render(fit(), stagger=True)
    assert sp.redrawn == 0 and all(c.previous is None for c in maps.cascades)
    r.close()


def test_once_the_sun_stands_still_the_image_is_that_of_tiles_drawn_for_it(gl_ctx):
    """After the sun moved (tiles fading) and then stood still for a few frames, the image is the one a
    new renderer draws at that sun (its tiles all drawn for it, in the first slots)."""
    scene = plane_scene(zenith_deg=50.0, azimuth_deg=40.0, with_box=True)
    cfg = replace(BASE, shadow=replace(BASE.shadow, stagger=True))
    r = Renderer(scene, 160, 90, config=cfg)
    sun0 = np.array(scene.sun.direction)
    moving = []
    for k in range(5):
        scene.sun.direction = _turn(sun0, 0.9 * k)
        moving.append(r.render().aovs["direct"])
    for _ in range(4):
        still = r.render().aovs["direct"]
    fresh = Renderer(scene, 160, 90, config=cfg)
    ref = fresh.render().aovs["direct"]
    np.testing.assert_allclose(still, ref, rtol=1e-5, atol=1e-5 * float(ref.max()))
    assert not np.allclose(moving[-1], ref, rtol=1e-5, atol=1e-5 * float(ref.max()))  # lagging, fading
    r.close()
    fresh.close()
