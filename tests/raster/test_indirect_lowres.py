"""The main view's SSAO and indirect light at reduced resolution (raster/indirect.py LowResIndirect,
glsl/upsample.glsl): the joint bilateral upsampling reproduces the full-resolution result where the
light is smooth."""

from __future__ import annotations

import numpy as np
import pytest

from serenity.config import RenderConfig, SSAOConfig
from serenity.frame import Renderer
from serenity.scene import load

pytestmark = pytest.mark.gl
SIZE = (128, 72)


def _indirect(scene_name: str, scale: int) -> tuple[np.ndarray, np.ndarray]:
    """(indirect radiance = beauty − direct, coverage mask) of a still frame, without SSAO (its
    noise pattern depends on the resolution)."""
    r = Renderer(load(scene_name), *SIZE, config=RenderConfig(indirect_scale=scale, ssao=SSAOConfig(enabled=False),
                                                              ray_tracing=False))
    try:
        r.render(read_back=False)
        f = r.render()
    finally:
        r.close()
    return f.hdr - f.aovs["direct"], np.isfinite(f.aovs["depth"][..., 0])


@pytest.mark.parametrize("scale", [2, 4])
def test_upsampled_indirect_matches_full_resolution(gl_ctx, scale):
    """Courtyard, indirect light only: at 1/2 (1/4) resolution the mean |difference| from the
    full-resolution indirect light is <= 4.5 % (10 %) of its mean over the covered pixels, and the
    median pixel is within 0.5 % (2 %): the error sits at edges, not on the smooth surfaces.
    Measured when written: 1.85 % / 0.06 % at 1/2, 4.70 % / 0.66 % at 1/4; with the LPV's
    self-illumination damping (default since round 13: its second sample, 2.5 cells along the
    normal, changes across depth edges) 3.43 % / 0.08 % and 7.86 % / 1.10 %."""
    full, covered = _indirect("courtyard", 1)
    low, _ = _indirect("courtyard", scale)
    y_full, y_low = full.mean(-1)[covered], low.mean(-1)[covered]
    mean_err = np.abs(y_low - y_full).mean() / y_full.mean()
    median_err = np.median(np.abs(y_low - y_full) / np.maximum(y_full, 1e-3 * y_full.mean()))
    print(f"scale {scale}: mean |diff| {mean_err:.2%} of the mean, median per-pixel {median_err:.2%}")
    assert mean_err <= (0.045 if scale == 2 else 0.10)
    assert median_err <= (0.005 if scale == 2 else 0.02)
