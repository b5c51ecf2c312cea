"""An independent sky anchor: our atmosphere's sky and sun against Mitsuba 3's
``sunsky`` emitter (the Hosek–Wilkie 2012 sky and its sun), over sun elevations 2°–90°.

    python benchmarks/bench_sky_anchor.py [--json FILE] [--chart FILE.png] [--turbidity 3]

Our references light scenes with our own atmosphere (``serenity.kernels.atmosphere``), so they only
check the renderer against its own sky model; this compares the model itself with a fitted,
measured-data-based one that no one here wrote. Per sun elevation (azimuth 0):

- ``sky_horizontal``: the sky's irradiance on a horizontal plane, ∫ L cosθ dω, W·m⁻² (RGB), from both
  skies evaluated at the same 128² paraboloid texel directions (ours: the baked sky map; Mitsuba:
  ``emitter.eval`` with the sun off, ``sun_scale = 0``);
- ``sun_horizontal``: the sun's, ours = ``sun_irradiance``·sin(elevation); Mitsuba's by Monte Carlo
  over its sun disc (``sample_direction`` with the sky off, 4000 samples);
- ``diffuse_fraction``: sky / (sky + sun) luminance — unit-free, the figure that says whether the
  shadows get the right share of light;
- ``radiance_shape_error``: each sky's radiance divided by its own horizontal sky irradiance (the
  angular shape, unit-free), then the solid-angle-weighted mean of |ln(ours/Mitsuba)| of the
  luminance over the upper hemisphere (0 = same shape; 0.1 ≈ 10 % apart);
- ``sky_colour``: blue/red ratio of the sky's horizontal irradiance.

Units: Mitsuba's RGB ``sunsky`` is not in our W·m⁻²·sr⁻¹ (its sun at the zenith delivers ~1.5 units
on a horizontal plane, ours ~950 W·m⁻²), so absolute figures are compared through one constant,
``scale`` = our total horizontal luminance / Mitsuba's at a 90° sun; ``*_ratio`` are ours / (scale ×
Mitsuba's), 1 = agreement after that single calibration. Our model has no ground reflection; the
Mitsuba sky is evaluated with ground albedo 0 to match.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import sys

import numpy as np

from serenity.io.results import write_results
from serenity.kernels import atmosphere as A
from serenity.scene.model import direction_from_angles

HERE = os.path.dirname(os.path.abspath(__file__))
ELEVATIONS = (2.0, 5.0, 10.0, 15.0, 20.0, 30.0, 45.0, 60.0, 75.0, 90.0)
MAP = 128
SUN_SAMPLES = 4000
LUM = np.array([0.2126, 0.7152, 0.0722])


def to_mitsuba(d: np.ndarray) -> np.ndarray:
    """Our y-up directions in Mitsuba's ``sunsky`` frame (z up): a +90° rotation about x."""
    d = np.asarray(d, np.float64)
    return np.stack([d[..., 0], -d[..., 2], d[..., 1]], -1)


def mitsuba_sky(sun: np.ndarray, dirs: np.ndarray, turbidity: float):
    """((N, 3) sky radiance along ``dirs``, (3,) sun horizontal irradiance) of Mitsuba's ``sunsky``."""
    from serenity.eval.reference import mitsuba

    mi = mitsuba()
    base = {"type": "sunsky", "sun_direction": to_mitsuba(sun).tolist(), "turbidity": turbidity, "albedo": 0.0}
    sky = mi.load_dict({**base, "sun_scale": 0.0})
    si = mi.SurfaceInteraction3f()
    rad = np.empty((len(dirs), 3))
    for i, d in enumerate(to_mitsuba(dirs)):
        si.wi = mi.Vector3f(*(-d))
        rad[i] = np.array(sky.eval(si))
    sun_only = mi.load_dict({**base, "sky_scale": 0.0})
    it = mi.Interaction3f()
    it.p, it.n, it.t = mi.Point3f(0, 0, 0), mi.Normal3f(0, 0, 1), 0.0
    rng = np.random.default_rng(0)
    acc = np.zeros(3)
    for u in rng.random((SUN_SAMPLES, 2)):
        ds, w = sun_only.sample_direction(it, mi.Point2f(*u))
        acc += np.array(w) * max(float(ds.d[2]), 0.0)
    return rad, acc / SUN_SAMPLES


def measure(turbidity: float):
    dirs = A.sky_map_directions(MAP).reshape(-1, 3)
    omega = A.sky_map_solid_angles(MAP).reshape(-1)
    keep = omega > 0
    dirs, omega = dirs[keep], omega[keep]
    cosw = omega * np.maximum(dirs[:, 1], 0.0)
    rows = []
    for el in ELEVATIONS:
        sun = direction_from_angles(el, 0.0)
        ours = A.bake_sky_map(sun, size=MAP).reshape(-1, 3).astype(np.float64)[keep]
        mi_rad, mi_sun = mitsuba_sky(sun, dirs, turbidity)
        o_sky, m_sky = cosw @ ours, cosw @ mi_rad
        o_sun = A.sun_irradiance(sun) * math.sin(math.radians(el))
        lo, lm = ours @ LUM / (o_sky @ LUM), mi_rad @ LUM / (m_sky @ LUM)
        ok = (lo > 0) & (lm > 0)
        shape = float((omega[ok] * np.abs(np.log(lo[ok] / lm[ok]))).sum() / omega[ok].sum())
        rows.append({"elevation_deg": el,
                     "ours": {"sky_horizontal": o_sky.tolist(), "sun_horizontal": o_sun.tolist()},
                     "mitsuba": {"sky_horizontal": m_sky.tolist(), "sun_horizontal": mi_sun.tolist()},
                     "radiance_shape_error": shape})
    # one calibration constant: total horizontal luminance at the highest sun
    top = rows[-1]
    scale = (float(np.dot(LUM, np.add(top["ours"]["sky_horizontal"], top["ours"]["sun_horizontal"])))
             / float(np.dot(LUM, np.add(top["mitsuba"]["sky_horizontal"], top["mitsuba"]["sun_horizontal"]))))
    for r in rows:
        o, m = r["ours"], r["mitsuba"]
        osky, osun = float(LUM @ o["sky_horizontal"]), float(LUM @ o["sun_horizontal"])
        msky, msun = scale * float(LUM @ m["sky_horizontal"]), scale * float(LUM @ m["sun_horizontal"])
        r["sky_ratio"] = osky / msky
        r["sun_ratio"] = osun / msun if msun > 0 else None
        r["total_ratio"] = (osky + osun) / (msky + msun)
        r["diffuse_fraction"] = {"ours": osky / (osky + osun), "mitsuba": msky / (msky + msun)}
        r["sky_colour"] = {"ours": o["sky_horizontal"][2] / o["sky_horizontal"][0],
                           "mitsuba": m["sky_horizontal"][2] / m["sky_horizontal"][0]}
    return scale, rows


def chart(path: str, runs: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(15, 4.3))
    for t, (_scale, rows) in runs.items():
        el = [r["elevation_deg"] for r in rows]
        ls = {2.0: "--", 3.0: "-"}.get(t, ":")
        ax[0].plot(el, [r["sky_ratio"] for r in rows], "b" + ls, label=f"sky, T={t:g}")
        ax[0].plot(el, [r["sun_ratio"] for r in rows], "r" + ls, label=f"sun, T={t:g}")
        ax[0].plot(el, [r["total_ratio"] for r in rows], "k" + ls, label=f"sun + sky, T={t:g}")
        ax[1].plot(el, [r["diffuse_fraction"]["mitsuba"] for r in rows], "g" + ls, label=f"Mitsuba sunsky T={t:g}")
        if t == 3.0:
            ax[1].plot(el, [r["diffuse_fraction"]["ours"] for r in rows], "k-o", ms=3, label="ours")
            ax[2].plot(el, [r["radiance_shape_error"] for r in rows], "k-o", ms=3, label="|ln ours/Mitsuba|")
    ax[0].axhline(1.0, color="grey", lw=0.8)
    ax[0].set(xlabel="sun elevation (deg)", ylabel="ours / (scale x Mitsuba)", yscale="log",
              title="horizontal irradiance, one calibration at 90 deg")
    ax[1].set(xlabel="sun elevation (deg)", ylabel="sky / (sun + sky)", title="diffuse fraction (unit-free)")
    ax[2].set(xlabel="sun elevation (deg)", ylabel="mean |ln ratio|",
              title="sky radiance shape (each / own horizontal E), T=3")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(fontsize=7)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--json", default=os.path.join(HERE, "results", "sky_anchor.json"))
    ap.add_argument("--chart", default=os.path.join(HERE, "results", "sky_anchor.png"))
    ap.add_argument("--turbidity", type=float, nargs="+", default=[2.0, 3.0, 5.0],
                    help="Hosek-Wilkie turbidities (3 = clear sky, the chart's main line)")
    args = ap.parse_args(argv)
    runs = {}
    for t in args.turbidity:
        runs[t] = measure(t)
        scale, rows = runs[t]
        print(f"turbidity {t:g}: scale {scale:.1f} (our W/m^2 per Mitsuba unit)")
        for r in rows:
            print(f"  sun {r['elevation_deg']:4.0f} deg: sky {r['sky_ratio']:.3f}  sun {r['sun_ratio']:.3f}  "
                  f"total {r['total_ratio']:.3f}  diffuse fraction ours {r['diffuse_fraction']['ours']:.3f} "
                  f"Mitsuba {r['diffuse_fraction']['mitsuba']:.3f}  shape |ln| {r['radiance_shape_error']:.3f}  "
                  f"sky b/r ours {r['sky_colour']['ours']:.2f} Mitsuba {r['sky_colour']['mitsuba']:.2f}",
                  flush=True)
    import mitsuba

    out = {"benchmark": "sky_anchor",
           "machine": {"platform": platform.platform(), "python": sys.version.split()[0]},
           "anchor": f"Mitsuba {mitsuba.__version__} sunsky (Hosek-Wilkie 2012), scalar_rgb, ground albedo 0",
           "settings": {"map_size": MAP, "sun_samples": SUN_SAMPLES, "sun_azimuth_deg": 0.0,
                        "elevations_deg": list(ELEVATIONS), "luminance": LUM.tolist()},
           "runs": [{"turbidity": t, "scale": s, "results": rows} for t, (s, rows) in runs.items()]}
    write_results(args.json, out)
    if args.chart:
        chart(args.chart, runs)
        print(f"wrote {args.chart}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
