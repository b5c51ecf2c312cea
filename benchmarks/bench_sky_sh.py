"""Why the sky volume's L2 SH irradiance misses R&H's ~1 %, and what windowing costs.

    python benchmarks/bench_sky_sh.py [--json FILE] [--device cpu]

For an unoccluded probe under the default sky (sky map of the atmosphere model + a uniform ground of
albedo 0.2 below the horizon, exactly as ``bench_sky.py``'s ``sh_irradiance_mean_rel_error``), the
irradiance E(n) of 1000 normals from the L2 SH is compared with the brute-force cosine integral of the
same map, at sun elevations 90/45/10/2° (azimuth 135°). Figures: mean |E_sh − E| / E

- ``by_window``: for each window of ``serenity.kernels.sh`` (none, Hanning and Lanczos at W = 4/4.75/8,
  the non-negative one) — a window scales bands 1–2 down, so it blurs an irradiance that the
  projection already fits best in L2: on an unoccluded probe it can only add error (the cost of
  windowing; its benefit is less ringing behind hard occluders and a bright sun, not measured here);
- ``by_normal``: the unwindowed error for up-facing (n.y > 0.5), vertical and down-facing normals;
- ``ground_exact_check``: the same with the ground's irradiance in closed form, π·L_g·(1 − n.y)/2 —
  identical to the SH result, because a uniform lower hemisphere's irradiance is linear in n (bands
  0–1), so L2 holds it exactly: the whole error is the sky's own, from the circumsolar peak;
- ``l4``: the error when the sky is projected to band 4 (band 3's clamped-cosine weight Â₃ is 0, so
  L4 is the next order that changes irradiance; Â₄ = −π/24), i.e. what 18 stored coefficients per
  channel (bands 0, 1, 2 and 4: 2× the volume's memory and per-pixel lookups) would buy;
- ``sky_peak``: max/mean radiance of the sky map (how peaked the light is).
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys

import numpy as np

try:
    from scipy.special import sph_harm_y
except ImportError:  # scipy < 1.15: the older name, with (m, n) and the angles swapped
    from scipy.special import sph_harm

    def sph_harm_y(n, m, theta, phi):
        return sph_harm(m, n, phi, theta)

from serenity.device import resolve_device
from serenity.io.results import write_results
from serenity.kernels import atmosphere as A
from serenity.kernels import sh as S
from serenity.kernels.sampling import fibonacci_sphere
from serenity.scene.model import direction_from_angles

HERE = os.path.dirname(os.path.abspath(__file__))
ELEVATIONS = (90.0, 45.0, 10.0, 2.0)
GROUND_ALBEDO = 0.2
MAP = 256
WINDOWS = (("none", 4.0), ("hanning", 4.0), ("hanning", 4.75), ("hanning", 8.0), ("lanczos", 4.0),
           ("lanczos", 8.0), ("nonneg", 4.0))


def a_hat(l: int) -> float:
    """Clamped-cosine convolution weight of band l (R&H 2001 eq. 8; 0 for odd l > 1)."""
    if l == 0:
        return math.pi
    if l == 1:
        return 2.0 * math.pi / 3.0
    if l % 2:
        return 0.0
    return (2.0 * math.pi * (-1) ** (l // 2 - 1) / ((l + 2) * (l - 1))
            * math.factorial(l) / (2 ** l * math.factorial(l // 2) ** 2))


def real_sh(l_max: int, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """((N, (l_max+1)²) orthonormal real SH of unit directions d (y = polar axis), (K,) band of each)."""
    theta = np.arccos(np.clip(d[:, 1], -1, 1))
    phi = np.arctan2(d[:, 2], d[:, 0])
    cols, bands = [], []
    for l in range(l_max + 1):
        for m in range(-l, l + 1):
            y = sph_harm_y(l, abs(m), theta, phi)
            cols.append(y.real if m == 0 else math.sqrt(2) * (y.real if m > 0 else y.imag))
            bands.append(l)
    return np.stack(cols, -1), np.asarray(bands)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(HERE, "results", "sky_sh.json"))
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args(argv)
    device = resolve_device(args.device)

    normals = fibonacci_sphere(1000)
    below = fibonacci_sphere(100000)
    below = below[below[:, 1] < 0]
    d = A.sky_map_directions(MAP).reshape(-1, 3).astype(np.float64)
    w = A.sky_map_solid_angles(MAP).reshape(-1).astype(np.float64)
    keep = w > 0
    d, w = d[keep], w[keep]
    up, down = normals[:, 1] > 0.5, normals[:, 1] < -0.5
    vert = ~up & ~down
    y4_d, bands = real_sh(4, d)
    y4_n, _ = real_sh(4, normals)
    scale4 = np.array([a_hat(int(b)) for b in bands])

    per_el = {}
    for el in ELEVATIONS:
        m = A.bake_sky_map(direction_from_angles(el, 135.0), device=device).reshape(-1, 3).astype(np.float64)[keep]
        ground = GROUND_ALBEDO / math.pi * A.horizontal_irradiance(
            A.bake_sky_map(direction_from_angles(el, 135.0), device=device))
        ground_e = ground[None] * math.pi * (1 - normals[:, 1:2]) / 2
        brute = (np.maximum(normals @ d.T, 0) * w) @ m + ground_e
        lsky = (S.sh_basis(d) * w[:, None]).T @ m
        lsh = lsky + (S.sh_basis(below).sum(0) * (2 * math.pi / len(below)))[:, None] * ground
        rel = {}
        for win, size in WINDOWS:
            e = S.eval_irradiance(S.irradiance_coefficients(lsh, win, size), normals)
            rel[f"{win}" if win in ("none", "nonneg") else f"{win} W={size:g}"] = float(
                (np.abs(e - brute) / brute).mean())
        e2 = S.eval_irradiance(S.irradiance_coefficients(lsh), normals)
        r2 = np.abs(e2 - brute) / brute
        eg = S.eval_irradiance(S.irradiance_coefficients(lsky), normals) + ground_e
        e4 = (y4_n * scale4) @ ((y4_d * w[:, None]).T @ m) + ground_e
        per_el[str(el)] = {
            "by_window": rel,
            "by_normal": {"up-facing": float(r2[up].mean()), "vertical": float(r2[vert].mean()),
                          "down-facing": float(r2[down].mean())},
            "worst": float(r2.max()),
            "ground_exact_check": float((np.abs(eg - brute) / brute).mean()),
            "l4": float((np.abs(e4 - brute) / brute).mean()),
            "sky_peak": float(m.mean(-1).max() / m.mean()),
        }
        print(f"sun {el:4.0f} deg: L2 {rel['none']:.4f} (up {r2[up].mean():.4f}, vertical {r2[vert].mean():.4f}, "
              f"down {r2[down].mean():.4f}), ground exact {per_el[str(el)]['ground_exact_check']:.4f}, "
              f"L4 {per_el[str(el)]['l4']:.4f}, sky max/mean {per_el[str(el)]['sky_peak']:.1f}; windows "
              + ", ".join(f"{k} {v:.4f}" for k, v in rel.items() if k != "none"), flush=True)

    def mean(f):
        return float(np.mean([f(v) for v in per_el.values()]))

    out = {
        "benchmark": "sky_sh",
        "machine": {"platform": platform.platform(), "python": sys.version.split()[0]},
        "settings": {"sky_map_size": MAP, "normals": len(normals), "ground_albedo": GROUND_ALBEDO,
                     "sun_azimuth_deg": 135.0, "elevations_deg": list(ELEVATIONS)},
        "l2_mean_rel_error": mean(lambda v: v["by_window"]["none"]),
        "l2_by_window_mean_rel_error": {k: mean(lambda v, k=k: v["by_window"][k])
                                        for k in next(iter(per_el.values()))["by_window"]},
        "l2_ground_exact_mean_rel_error": mean(lambda v: v["ground_exact_check"]),
        "l4_mean_rel_error": mean(lambda v: v["l4"]),
        "by_elevation": per_el,
    }
    print(f"mean over elevations: L2 {out['l2_mean_rel_error']:.4f}, L4 {out['l4_mean_rel_error']:.4f}; "
          + ", ".join(f"{k} {v:.4f}" for k, v in out["l2_by_window_mean_rel_error"].items()))
    write_results(args.json, out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
