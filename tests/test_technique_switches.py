"""The per-term switches the viewer's panel exposes, on the Renderer itself: ``LPVConfig.diffuse`` /
``.glossy`` and ``RayTracingConfig.reflections`` / ``.refractions``. Each switch, changed live on one
Renderer (as the viewer does), removes exactly its own contribution and leaves every other pixel as
it was, to float rounding (1e-4 relative, 1e-5 of the image's maximum absolute: llvmpipe compiles
the switched shader differently, and the composite's bilinear fetch at texel centres mixes in ~1e-5
of the neighbours, which a frame without the composite does not)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from serenity.config import RenderConfig
from serenity.frame import Renderer
from serenity.raster.raycast import TOTAL_INTERNAL_REFLECTION, TRACE_REFLECTION, TRACE_REFRACTION, RayCastingBuffer
from serenity.scene import load

W, H = 96, 54


@pytest.fixture(scope="module")
def courtyard(gl_ctx):
    """The courtyard (glass, a mirror, water) at full-resolution indirect light, so that a term's
    pixels are exactly the pixels that show it (no upsampling spreads it to neighbours)."""
    r = Renderer(load("courtyard"), W, H, config=RenderConfig.preset("lpv-fast", indirect={"scale": 1}))
    base = r.config
    r.render()  # builds the volumes; from here on nothing changes between frames

    def render(**subs):  # a sub-config's name -> the fields of it to change, e.g. lpv={"glossy": False}
        r.config = dataclasses.replace(base, **{k: dataclasses.replace(getattr(base, k), **v) for k, v in subs.items()})
        try:
            return r.render()
        finally:
            r.config = base

    render.full = r.render()
    render.materials = r.scene.materials
    yield render
    r.close()


@pytest.fixture(scope="module")
def gl_ctx():
    from serenity.raster.context import get_context

    return get_context()


def _changed(a, b) -> np.ndarray:
    """(H, W) bool: pixels where ``a`` and ``b`` differ by more than float rounding."""
    return np.any(np.abs(a.hdr - b.hdr) > 1e-4 * np.abs(b.hdr) + 1e-5 * np.abs(b.hdr).max(), axis=-1)


def _material_mask(frame, materials, keep) -> np.ndarray:
    idx = frame.aovs["material"][..., 0].astype(int)
    ok = np.array([keep(m) for m in materials] + [False])  # index -1 (background) → the last entry
    return ok[idx]


def test_the_default_frame_repeats_bit_for_bit(courtyard):
    assert np.array_equal(courtyard().hdr, courtyard.full.hdr)


def test_lpv_glossy_off_changes_only_glossy_pixels_and_their_reflections(courtyard):
    full = courtyard.full
    off = courtyard(lpv={"glossy": False})
    changed = _changed(off, full)
    # indirect.glsl marches the glossy LPV only where k_s >= 0.1 (water, glass, the mirror here)
    glossy = _material_mask(full, courtyard.materials, lambda m: m.specular >= 0.1)
    traced = full.aovs["rt_mask"][..., 0] > 0  # reflections/refractions may show a glossy surface
    assert changed[glossy].mean() > 0.5, "the glossy pixels lose their glossy LPV light"
    assert not (changed & ~glossy & ~traced).any(), "a matte pixel changed"
    assert "lpv lighting" in off.timings


def test_lpv_terms_add_up_and_both_off_skip_the_pass(courtyard):
    full = courtyard.full.hdr.astype(np.float64)
    no_gloss = courtyard(lpv={"glossy": False}).hdr
    no_diff = courtyard(lpv={"diffuse": False}).hdr
    neither = courtyard(lpv={"diffuse": False, "glossy": False})
    assert "lpv lighting" not in neither.timings and "rt lpv lighting" not in neither.timings
    diffuse, glossy, both = full - no_diff, full - no_gloss, full - neither.hdr
    assert np.abs(diffuse).max() > 0 and np.abs(glossy).max() > 0
    # each switch removed exactly its own term: the two removals sum to the LPV's whole light
    assert np.allclose(diffuse + glossy, both, rtol=1e-4, atol=1e-4 * full.max())
    # the diffuse term lights (nearly) every covered pixel
    covered = np.isfinite(courtyard.full.aovs["depth"][..., 0])
    assert np.any(np.abs(diffuse) > 0, axis=-1)[covered].mean() > 0.9


def test_lpv_self_damping_is_compiled_in_when_on(courtyard):
    """``LPVConfig.self_damping`` is compiled into the LPV lighting passes only when on (lpv.glsl's
    LPV_DAMPING; fixed when the renderer is built, like the LPV's other lookup settings; on by
    default since round 13): the damped default renderer's LPV light is at most the undamped
    one's (never brighter), and the two differ."""
    base = RenderConfig.preset("lpv-fast", indirect={"scale": 1})
    assert base.lpv.self_damping > 0
    r = Renderer(load("courtyard"), W, H, config=dataclasses.replace(
        base, lpv=dataclasses.replace(base.lpv, self_damping=0.0)))
    try:
        r.render()
        undamped = r.render().hdr
    finally:
        r.close()
    damped = courtyard.full.hdr
    assert np.abs(damped - undamped).max() > 0
    assert np.all(damped <= undamped * (1 + 1e-4) + 1e-4 * undamped.max())


def test_reflections_off_changes_only_reflecting_pixels(courtyard):
    full = courtyard.full
    off = courtyard(rt={"reflections": False})
    neither = courtyard(rt={"reflections": False, "refractions": False})
    changed = _changed(off, full)
    traced = full.aovs["rt_mask"][..., 0] > 0
    assert changed.any() and not (changed & ~traced).any()
    # nothing traced at all = the rasterised frame: only the traced pixels differ, and "ray casting buffer"
    # is all that is left of the ray tracing
    assert neither.rays == 0 and neither.aovs["rt_mask"].max() == 0
    assert "cpu ray tracing" not in neither.timings and "composite" not in neither.timings
    assert not (_changed(neither, full) & ~traced).any()
    # a mirror without its reflection shows its rasterised surface, as with nothing traced
    mirror = _material_mask(full, courtyard.materials, lambda m: m.reflectivity > 0 and m.transparency == 0)
    assert mirror.sum() > 10
    assert np.allclose(off.hdr[mirror], neither.hdr[mirror], rtol=1e-5, atol=1e-6)
    assert not np.allclose(full.hdr[mirror], neither.hdr[mirror], rtol=1e-2)
    # glass keeps its refraction: its pixels stay traced
    glass = _material_mask(full, courtyard.materials, lambda m: m.transparency > 0)
    assert (off.aovs["rt_mask"][..., 0][glass] > 0).all()


def test_refractions_off_changes_only_glass_pixels(courtyard):
    full = courtyard.full
    off = courtyard(rt={"refractions": False})
    changed = _changed(off, full)
    glass = _material_mask(full, courtyard.materials, lambda m: m.transparency > 0)
    assert glass.sum() > 10
    assert changed[glass].mean() > 0.5 and not (changed & ~glass).any()
    # the Fresnel reflection stays: glass pixels are still traced, and still differ from nothing traced
    assert np.array_equal(off.aovs["rt_mask"], full.aovs["rt_mask"])
    neither = courtyard(rt={"reflections": False, "refractions": False})
    assert not np.allclose(off.hdr[glass], neither.hdr[glass], rtol=1e-3)


def test_select_drops_the_switched_off_rays():
    n = 4
    flags = np.array([TRACE_REFLECTION, TRACE_REFLECTION | TRACE_REFRACTION,
                      TRACE_REFLECTION | TOTAL_INTERNAL_REFLECTION, TRACE_REFLECTION | TRACE_REFRACTION], np.int32)
    refract = np.array([[0, 0, 0], [0, -1, 0], [0, 0, 0], [0, -1, 0]], np.float32)
    rcb = RayCastingBuffer(4, 1, np.arange(n, dtype=np.int32), np.zeros((n, 3)), np.ones((n, 3)), refract,
                           np.zeros(n), np.zeros(n), flags, np.zeros((n, 3)), np.zeros(n, np.int32))
    assert rcb.select() is rcb
    no_refl = rcb.select(reflections=False)
    assert no_refl.pixels.tolist() == [1, 3] and not no_refl.reflection_rays().any()
    assert no_refl.refraction_rays().all()
    no_refr = rcb.select(refractions=False)
    assert no_refr.pixels.tolist() == [0, 1, 2, 3] and not no_refr.refraction_rays().any()
    assert rcb.select(False, False).count == 0
