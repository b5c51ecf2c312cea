"""Sky and sun near and below the horizon: the sun elevation sweeping from +5° to −10° must give no
NaN, no negative radiance and no jump larger than the reference's own change between two steps —
twilight fades, it does not pop to black."""

from __future__ import annotations

import math

import numpy as np
import pytest

from serenity.kernels import atmosphere as A
from serenity.kernels.sampling import fibonacci_sphere
from serenity.scene.model import direction_from_angles

SWEEP = np.round(np.arange(5.0, -10.0 - 1e-9, -1.0), 3)


def test_sun_fades_over_its_disc_instead_of_popping_at_the_horizon():
    """Exact answer: the sun's irradiance is E₀·T·(fraction of its 0.53° disc above the horizon) — a
    circular segment: continuous, ½·E₀·T(horizon) at sunset, 0 once the disc has set. Before the fix
    it dropped from the horizon's 16.6 W/m² (red) to 0 as the centre crossed 0° (a pop on every wall
    facing the sunset, 14× the largest 0.01° step of the sun just above the horizon). Bound: in
    0.01° steps from +1° to −1°, no step while the disc sets exceeds 1.1× the largest step above it
    (where only the transmittance changes; measured 1.13 vs 1.15 W/m²)."""
    r = A.SUN_ANGULAR_DIAMETER_DEG / 2
    els = np.arange(1.0, -1.0 - 1e-9, -0.01)
    e = np.array([A.sun_irradiance(direction_from_angles(el, 270.0))[0] for el in els])
    assert np.all(np.isfinite(e)) and e.min() >= 0
    frac = np.array([A.sun_disc_fraction(direction_from_angles(el, 270.0)) for el in els])
    assert frac[els > r + 1e-9].min() == 1.0 and frac[els < -r - 1e-9].max() == 0.0
    assert np.all(e[els < -r - 1e-9] == 0.0)
    horizon = A.SOLAR_IRRADIANCE[0] * A.sun_transmittance([-1.0, 0.0, 0.0])[0]
    assert A.sun_irradiance(direction_from_angles(0.0, 270.0))[0] == pytest.approx(0.5 * horizon, rel=1e-9)
    step = np.abs(np.diff(e))
    setting = els[1:] <= r
    assert step[setting].max() <= 1.1 * step[~setting].max(), f"{step[setting].max():.3f} W/m² in 0.01°"


def test_sky_sweep_is_finite_non_negative_and_follows_the_reference(device):
    """Sky map (64², the renderer's bake at a small size) at each 1° step from +5° to −10°: finite,
    ≥ 0, and its horizontal irradiance E_h tracks the numerical reference's (sky_radiance_reference
    over 256 upper-hemisphere Fibonacci directions): per step, |ΔE_h(ours) − ΔE_h(ref)| ≤ 0.1·|ΔE_h(ref)|
    + 1e-3 W/m² (measured ≤ 2 % of the reference step: both fade smoothly, no pop), and
    |E_h − E_ref| ≤ 2 % of E_ref + 1e-3 at every step."""
    d = fibonacci_sphere(512)
    d = d[d[:, 1] > 0]
    ours, ref = [], []
    for el in SWEEP:
        sun = direction_from_angles(float(el), 250.0)
        m = A.bake_sky_map(sun, size=64, device=device)
        assert np.all(np.isfinite(m)) and m.min() >= 0.0, f"elevation {el}"
        ours.append(A.horizontal_irradiance(m))
        r = A.sky_radiance_reference(d, sun, view_steps=64, sun_steps=32)
        ref.append((r * d[:, 1:2]).sum(0) * 2 * math.pi / len(d))
    ours, ref = np.array(ours), np.array(ref)
    assert np.all(np.abs(ours - ref) <= 0.02 * ref + 1e-3)
    d_ours, d_ref = np.diff(ours, axis=0), np.diff(ref, axis=0)
    excess = np.abs(d_ours - d_ref) - 0.1 * np.abs(d_ref)
    assert excess.max() <= 1e-3, f"worst step excess {excess.max():.4f} W/m²"
    assert np.all(d_ref <= 1e-6)  # the reference itself only darkens as the sun sets


@pytest.mark.gl
def test_rendered_sunset_has_no_pop(gl_ctx):
    """A block's west wall facing the setting sun (``horizon_sweep``), sun from +1° to −1.5° in 0.25°
    steps: mean rendered radiance vs the exact ρ/π·(E_sun·cos + E_sky) of the open wall from this
    step's sun and sky. No NaN, no negative pixel. Step excess = (|Δours| − |Δexact|) over the
    larger exact value. Measured: 0.43 with the default sky-map cache (rebaked only every 0.5° of
    sun motion: in twilight the sky dims ~35 % per 0.5°, so the held map pops when it is rebaked —
    a known weakness, bounded here at 0.5), 0.02 when rebaked every 0.1° (rebuild_angle_deg=0.1,
    bounded at 0.05; the sky volume at 6×3×6 probes, 64 rays, to keep the test small). The sun
    term of the exact answer is the model's own (its disc fraction is checked above), so this
    measures the renderer's sky and lighting path, not the sun's fade."""
    from serenity.eval.stability import horizon_sweep

    els = np.arange(1.0, -1.51, -0.25)
    res = horizon_sweep(els, size=(32, 18), probes=(6, 3, 6), rays=64)
    assert res["finite"] and res["min_radiance"] >= 0.0
    assert res["max_excess_step"] <= 0.5, res["steps"]
    fine = horizon_sweep(els, size=(32, 18), rebuild_angle_deg=0.1, probes=(6, 3, 6), rays=64)
    print(f"step excess: cached 0.5 deg {res['max_excess_step']:.3f}, 0.1 deg {fine['max_excess_step']:.3f}")
    assert fine["finite"] and fine["min_radiance"] >= 0.0
    assert fine["max_excess_step"] <= 0.05, fine["steps"]
