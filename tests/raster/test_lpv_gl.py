"""lpv.glsl against the Warp lookups (serenity/kernels/lpv/): same volume, same points, the GLSL
functions in a fullscreen probe pass must give the Warp reference within 1e-3 relative."""

from __future__ import annotations

import numpy as np
import pytest

from serenity.config import LPVConfig
from serenity.kernels import lpv as L
from serenity.raster import context
from serenity.raster.lpv_gl import LPVProbeGL, lookup_defines


def _volume(leak_guard: bool, cascades: int = 3, occlusion: bool = True, planes: bool = True, damping: float = 0.0):
    cfg = LPVConfig(resolution=16, cascades=cascades, iterations=6, early_stop=0.0, view_distance=12.0,
                      leak_guard=leak_guard, lookup_occlusion=occlusion, lookup_planes=planes, self_damping=damping)
    v = L.LightPropagationVolume(cfg, device="cpu")
    bounds = np.array([[-10.0, 0.0, -10.0], [10.0, 6.0, 10.0]])
    v.fit((np.array([0.0, 2.0, -3.0]), np.array([0.2, 0.0, 1.0])), bounds)
    rng = np.random.default_rng(1)
    n = 3000
    v.clear()
    v.inject(rng.uniform(bounds[0], bounds[1], (n, 3)), rng.normal(size=(n, 3)), rng.uniform(0, 1, (n, 3)))
    v.inject_geometry(rng.uniform(bounds[0], bounds[1], (n, 3)), rng.normal(size=(n, 3)), np.full(n, 0.05))
    v.propagate()
    return v, bounds, rng


@pytest.mark.parametrize("leak_guard,cascades,occlusion,planes,damping",
                         [(True, 3, True, True, 0.0), (True, 3, True, False, 0.0), (True, 3, False, True, 0.0),
                          (False, 3, True, True, 0.0), (True, 1, True, True, 0.0), (True, 3, True, True, 2.0),
                          (False, 3, True, True, 1.5)])
def test_glsl_lookups_match_warp(gl_ctx, leak_guard, cascades, occlusion, planes, damping):
    _check_lookups(gl_ctx, leak_guard, cascades, occlusion, planes, damping)


@pytest.mark.parametrize("leak_guard,damping", [(True, 0.0), (False, 0.0), (True, 2.0)])
def test_glsl_exact_filter_matches_warp(gl_ctx, monkeypatch, leak_guard, damping):
    # the shader's own trilinear filter (hardware GL's default, raster/context.EXACT_FILTER), run here too
    monkeypatch.setattr(context, "EXACT_FILTER", True)
    _check_lookups(gl_ctx, leak_guard, 3, True, True, damping)


def _check_lookups(gl_ctx, leak_guard, cascades, occlusion, planes, damping=0.0):
    v, bounds, rng = _volume(leak_guard, cascades, occlusion, planes, damping)
    assert len(v.grids) == cascades
    m = 3000
    q = rng.uniform(bounds[0] - 1, bounds[1] + 1, (m, 3)).astype(np.float32)
    d = rng.normal(size=(m, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    shin = rng.uniform(1, 64, m).astype(np.float32)
    ref_e, ref_g = v.irradiance(q, d), v.glossy(q, d, shin)
    results = []
    # the switches as uniforms (the probe's default) and compiled in, as the renderer's passes have them
    for defines in (None, lookup_defines(v.config)):
        probe = LPVProbeGL(gl_ctx, defines=defines)
        try:
            results += probe.evaluate(v, q, d, shin)
        finally:
            probe.release()
    for ours, ref in zip(results, (ref_e, ref_g, ref_e, ref_g), strict=True):
        assert ref.max() > 0
        # relative to each value, floored at 1e-3 of the largest (values near 0 after the clamp)
        scale = np.maximum(np.abs(ref), 1e-3 * np.abs(ref).max())
        assert (np.abs(ours - ref) / scale).max() < 1e-3
