"""The frontier: our whole frame against a path tracer plus a denoiser, at equal error.

For one scene and image size, the peer is Mitsuba 3 (``scalar_rgb`` ``path``, unlimited depth) at
1, 2, 4, … spp, raw and denoised with OIDN (:mod:`serenity.eval.denoise`). It renders
progressively (:meth:`PathTracerPeer.progressive`): the image at each count adds a chunk of
samples to the one before it, and its time is the sum of the chunks' ``mi.render`` wall times
(plus the OIDN call for denoised points). Each peer curve is a list of (milliseconds, error)
points in rising spp. Ours is a frame time and an error.

The equal-error speed-up (:func:`equal_error_speedup`) is the peer's time to reach our error ÷ our
frame time. The time to reach it (:func:`time_to_reach`) is found on the first segment of the curve
whose end is at or below our error, interpolated linearly in log(ms) against log(error) (error
falls about as a power of the sample count, and time grows about linearly with it, so both are
near-straight lines in log-log). When the curve's first point (1 spp) is already at or below our
error there is nothing to interpolate: we are "dominated" (the peer's 1-spp time ÷ ours is then
an upper bound of the speed-up). When no point reaches our error, the speed-up is "not reached"
and the last point's time ÷ ours is a lower bound.

    r = equal_error_speedup([(210, 0.10), (330, 0.08)], our_ms=125.0, our_error=0.13)
    r["status"]  # "dominated"; r["bound"] = 210/125 (upper bound of the speed-up)

Several curves (raw, + OIDN at each quality) are merged by :func:`combine` (the peer's fastest way
to our error), and :func:`strongest` picks which of our configs stands best.

:func:`frontier_figure` draws the chart: one row per scene and size, FLIP and relMSE side by side,
x = ms per frame, y = error, both log.
"""

from __future__ import annotations

import math
import time

import numpy as np

from serenity.errors import SerenityError
from serenity.eval.charts import save_figure
from serenity.eval.reference import load_mitsuba_scene, mitsuba, with_effective_sun

GOAL_SPEEDUP = 10.0
"""The speed-up at equal FLIP the approximation must reach to be worth running instead of the peer."""
PEER_SEED_BASE = 2**31
"""Mitsuba seeds of the peer renders: far from the reference's chunk seeds (0 … spp/chunk)."""


# ------------------------------------------------------------------------------------ interpolation


def _curve(points) -> tuple[np.ndarray, np.ndarray]:
    try:
        p = np.asarray([(float(ms), float(err)) for ms, err in points], np.float64)
    except (TypeError, ValueError) as exc:
        raise SerenityError(f"a peer curve must be (ms, error) pairs ({exc})") from None
    if len(p) == 0:
        raise SerenityError("a peer curve needs at least one (ms, error) point")
    if not (np.all(np.isfinite(p)) and np.all(p > 0)):
        raise SerenityError("peer curve times and errors must be finite and > 0 (log-log interpolation)")
    return p[:, 0], p[:, 1]


def time_to_reach(points, target: float) -> dict:
    """When the curve (list of (ms, error) in rising spp) first reaches ``target`` error.

    Returns {"status": "reached" | "dominated" | "not_reached", "ms": float | None}: "reached" with
    the log-log interpolated time on the first segment whose end is ≤ target; "dominated" when the
    first point already is (ms = its time); "not_reached" when none is (ms = None)."""
    ms, err = _curve(points)
    target = float(target)
    if not (target > 0 and math.isfinite(target)):
        raise SerenityError(f"target error must be finite and > 0, got {target}")
    hit = np.nonzero(err <= target)[0]
    if len(hit) == 0:
        return {"status": "not_reached", "ms": None}
    i = int(hit[0])
    if i == 0:
        return {"status": "dominated", "ms": float(ms[0])}
    le0, le1 = math.log(err[i - 1]), math.log(err[i])
    lt0, lt1 = math.log(ms[i - 1]), math.log(ms[i])
    f = (math.log(target) - le0) / (le1 - le0)  # le1 ≤ log(target) < le0, so 0 < f ≤ 1
    return {"status": "reached", "ms": float(math.exp(lt0 + f * (lt1 - lt0)))}


def equal_error_speedup(points, our_ms: float, our_error: float) -> dict:
    """The peer's time to reach ``our_error`` ÷ ``our_ms`` (see the module doc).

    Returns {"status", "peer_ms", "speedup", "bound"}: for "reached", ``speedup`` = peer_ms/our_ms;
    for "dominated", ``speedup`` is None and ``bound`` = (1-spp time)/our_ms, an upper bound; for
    "not_reached", ``speedup`` is None and ``bound`` = (last point's time)/our_ms, a lower bound."""
    if not (our_ms > 0 and math.isfinite(our_ms)):
        raise SerenityError(f"our frame time must be finite and > 0, got {our_ms}")
    r = time_to_reach(points, our_error)
    ms, _ = _curve(points)
    if r["status"] == "reached":
        return {"status": "reached", "peer_ms": r["ms"], "speedup": r["ms"] / our_ms, "bound": None}
    bound_ms = float(ms[0]) if r["status"] == "dominated" else float(ms[-1])
    return {"status": r["status"], "peer_ms": r["ms"], "speedup": None, "bound": bound_ms / our_ms}


def combine(results: dict) -> dict:
    """The peer's standing over several curves (name → :func:`equal_error_speedup` result, same frame
    time): its fastest way to our error. "dominated" when any curve's first point already reaches it,
    else "reached" when any curve does, else "not_reached". ``peer_ms`` = the fastest time known to
    reach our error (a dominated curve's 1-spp time, a reached curve's interpolated time), and
    ``bound``/``speedup`` = that ÷ our time, an upper bound when dominated; when nothing reaches it,
    ``bound`` = the fastest curve's last time ÷ ours, a lower bound. Adds ``curve``: the name it came from."""
    if not results:
        raise SerenityError("combine needs at least one curve's result")
    items = list(results.items())
    reaching = [(name, r) for name, r in items if r["status"] in ("dominated", "reached")]
    if not reaching:
        name, r = min(items, key=lambda it: it[1]["bound"])
        return {**r, "curve": name}
    name, r = min(reaching, key=lambda it: it[1]["peer_ms"])
    ratio = r["speedup"] if r["status"] == "reached" else r["bound"]
    if any(x["status"] == "dominated" for _, x in items):
        return {"status": "dominated", "peer_ms": r["peer_ms"], "speedup": None, "bound": ratio, "curve": name}
    return {"status": "reached", "peer_ms": r["peer_ms"], "speedup": ratio, "bound": None, "curve": name}


def strongest(results: dict) -> tuple[str, dict]:
    """(name, result) of the entry of ``results`` (name → :func:`combine` or :func:`equal_error_speedup`
    result, one per config of ours) that stands best against the peer: any that is not dominated before
    those that are, then the largest speed-up (a not-reached lower bound counts as its bound)."""
    if not results:
        raise SerenityError("strongest needs at least one result")

    def key(item):
        r = item[1]
        return (r["status"] != "dominated", r["speedup"] if r["speedup"] is not None else r["bound"])

    return max(results.items(), key=key)


def describe(r: dict) -> str:
    """A short human reading of an :func:`equal_error_speedup` result: "3.2×", "dominated (≤ 1.7×)",
    "> 40× (not reached)"."""
    if r["status"] == "reached":
        return f"{r['speedup']:.2g}×" if r["speedup"] < 10 else f"{r['speedup']:.0f}×"
    if r["status"] == "dominated":
        return f"dominated (≤ {r['bound']:.2g}×)"
    return f"> {r['bound']:.2g}× (not reached)"


def goal_met(r: dict, goal: float = GOAL_SPEEDUP) -> bool:
    """True when the speed-up is at least ``goal`` (a lower bound of at least ``goal`` counts)."""
    if r["status"] == "reached":
        return r["speedup"] >= goal
    return r["status"] == "not_reached" and r["bound"] >= goal


# ------------------------------------------------------------------------------------------ the peer


def timed(fn, repeat_below_s: float = 1.0):
    """(result of the first call, median wall seconds): calls faster than ``repeat_below_s`` run 3 times."""
    t0 = time.perf_counter()
    out = fn()
    times = [time.perf_counter() - t0]
    if times[0] < repeat_below_s:
        for _ in range(2):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
    return out, float(np.median(times))


class PathTracerPeer:
    """Mitsuba 3 ``path`` (unlimited depth) on a Scene, timed: ``render(spp)`` → (image, seconds), and
    :meth:`progressive` for a rising list of sample counts.

    The scene is exported once (as :func:`serenity.eval.reference.render_reference` does, with our
    renderer's sun); loading is not timed, like our renderer's upload. One warm-up render runs first."""

    def __init__(self, scene, width: int, height: int, warmup: bool = True):
        self.mi = mitsuba()
        self.width, self.height = int(width), int(height)
        self.mscene = load_mitsuba_scene(with_effective_sun(scene), self.width, self.height, -1)
        if warmup:
            self.render(1, seed=PEER_SEED_BASE - 1)

    def render(self, spp: int, seed: int | None = None) -> tuple[np.ndarray, float]:
        """(H, W, 3) float32 linear radiance at ``spp`` samples per pixel, and the wall seconds of the render."""
        if int(spp) < 1:
            raise SerenityError(f"spp must be >= 1, got {spp}")
        seed = PEER_SEED_BASE + int(spp) if seed is None else int(seed)
        t0 = time.perf_counter()
        img = self.mi.render(self.mscene, spp=int(spp), seed=seed)
        img = np.array(img, dtype=np.float32)[..., :3]
        dt = time.perf_counter() - t0
        return np.nan_to_num(img, nan=0.0, posinf=0.0, neginf=0.0), dt

    def progressive(self, spp_list, repeat_below_s: float = 1.0):
        """Yield (spp, image, seconds) for each of the rising ``spp_list``, as a progressive path tracer
        gets them: the samples between one count and the next are rendered as one chunk (its own
        seed) and averaged in, and the time is the sum of the chunks' render times (each the median
        of 3 when faster than ``repeat_below_s``). 1…64 spp costs 64 spp, not 127."""
        spp_list = [int(n) for n in spp_list]
        if not spp_list or spp_list[0] < 1 or any(b <= a for a, b in zip(spp_list, spp_list[1:], strict=False)):
            raise SerenityError(f"spp counts must rise from >= 1, got {spp_list}")
        acc = np.zeros((self.height, self.width, 3), np.float64)
        done, seconds = 0, 0.0
        for n in spp_list:
            chunk = n - done
            (img, _), dt = timed(lambda chunk=chunk, n=n: self.render(chunk, seed=PEER_SEED_BASE + n), repeat_below_s)
            acc += img.astype(np.float64) * chunk
            done, seconds = n, seconds + dt
            yield n, (acc / n).astype(np.float32), seconds


# ------------------------------------------------------------------------------------------- chart

_PEER_STYLE = {
    "raw": dict(color="0.45", marker="o", ls="--"),
    "fast": dict(color="tab:green", marker="v", ls="-"),
    "balanced": dict(color="tab:blue", marker="s", ls="-"),
    "high": dict(color="tab:purple", marker="D", ls="-"),
    "cycles": dict(color="0.2", marker="o", ls=":"),
    "cycles+oidn-fast": dict(color="tab:orange", marker="v", ls="-."),
    "cycles+oidn-accurate": dict(color="tab:olive", marker="s", ls="-."),
}
_OUR_MARKERS = ("*", "P", "X", "h", "p", "d")
REACH_LABEL = "fastest peer point at our error or better (dotted: from ours)"
MOVING_LABEL = "Serenity, camera moving (hollow: same marker as the still frame)"


def _peer_label(curve: str) -> str:
    if curve.startswith("cycles"):  # serenity.eval.cycles.CURVES
        return "Cycles raw" if curve == "cycles" else f"Cycles + its OIDN ({curve.rsplit('-', 1)[-1]} prefilter)"
    return "Mitsuba raw" if curve == "raw" else f"Mitsuba + OIDN ({curve})"


CHART_METRICS = (("flip", "FLIP"), ("rel_mse", "relMSE"))


def frontier_figure(panels: list[dict], goal: float = GOAL_SPEEDUP, metrics=CHART_METRICS):
    """A matplotlib Figure: one row per panel (scene, size), one column per metric (key, axis name).

    Each panel: {"title": str, "peer": {curve: [{"spp", "ms", <metric>...}, ...]},
    "ours": [{"name", "ms", <metric>..., optional "moving": {"ms", <metric>...}}], "speedup": {<metric>: result}
    (optional :func:`combine` / :func:`equal_error_speedup` results of the headline config, in the titles),
    "headline": our config's name the speed-ups are for}. The raw curve's points carry their spp;
    every other mark is identified by the shared legend (no labels that could overlap the data)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    if not panels:
        raise SerenityError("a frontier chart needs at least one panel")
    rows = len(panels)
    fig, axes = plt.subplots(rows, len(metrics), figsize=(6.25 * len(metrics), 3.9 * rows + 1.0), dpi=110,
                             squeeze=False)
    handles: dict[str, object] = {}
    our_names = list(dict.fromkeys(o["name"] for p in panels for o in p["ours"]))
    for row, panel in enumerate(panels):
        for col, (metric, name) in enumerate(metrics):
            ax = axes[row][col]
            xs, ys = [], []
            for curve, pts in panel["peer"].items():
                style = _PEER_STYLE.get(curve, dict(color="tab:brown", marker="^", ls="-"))
                x = [p["ms"] for p in pts]
                y = [p[metric] for p in pts]
                xs += x
                ys += y
                (h,) = ax.plot(x, y, ms=5, lw=1.3, label=_peer_label(curve), **style)
                handles.setdefault(_peer_label(curve), h)
                if curve == "raw":
                    for q in pts:
                        ax.annotate(str(q["spp"]), (q["ms"], q[metric]), textcoords="offset points", xytext=(0, 7),
                                    ha="center", fontsize=7, color="0.35")
            for o in panel["ours"]:
                k = our_names.index(o["name"])
                h = ax.scatter([o["ms"]], [o[metric]], marker=_OUR_MARKERS[k % len(_OUR_MARKERS)], s=120, alpha=0.85,
                               color="tab:red", edgecolors="black", lw=0.6, zorder=5, label=f"Serenity: {o['name']}")
                handles.setdefault(f"Serenity: {o['name']}", h)
                xs.append(o["ms"])
                ys.append(o[metric])
                if (m := o.get("moving")) is not None:  # the same config with the camera moving: hollow
                    h = ax.scatter([m["ms"]], [m[metric]], marker=_OUR_MARKERS[k % len(_OUR_MARKERS)], s=120,
                                   facecolors="none", edgecolors="tab:red", lw=1.2, zorder=5, label=MOVING_LABEL)
                    handles.setdefault(MOVING_LABEL, h)
                    xs.append(m["ms"])
                    ys.append(m[metric])
            r = (panel.get("speedup") or {}).get(metric)
            head = next((o for o in panel["ours"] if o["name"] == panel.get("headline")), None)
            if r is not None and head is not None and r["peer_ms"] is not None:
                ax.plot([head["ms"], r["peer_ms"]], [head[metric]] * 2, color="tab:red", ls=":", lw=1.2, zorder=4)
                h = ax.scatter([r["peer_ms"]], [head[metric]], marker="x", s=70, color="tab:red", zorder=6,
                               label=REACH_LABEL)
                handles.setdefault(REACH_LABEL, h)
            ax.set_xscale("log")
            ax.set_yscale("log")
            for axis in (ax.xaxis, ax.yaxis):
                axis.set_major_locator(LogLocator(base=10, subs=(1.0, 2.0, 5.0)))
                axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
                axis.set_minor_formatter(NullFormatter())
            ax.set_xlim(min(xs) / 1.7, max(xs) * 1.7)
            ax.set_ylim(min(ys) / 1.35, max(ys) * 1.5)
            ax.grid(True, which="both", alpha=0.25)
            ax.set_xlabel("milliseconds per frame (log)")
            ax.set_ylabel(f"{name} (log, lower is better)", fontsize=9)
            extra = ""
            if r is not None:
                who = f" ({panel['headline']})" if len(our_names) > 1 and panel.get("headline") else ""
                extra = f" — equal {name.split(' ')[0].split(',')[0]}{who}: {describe(r)}"
            ax.set_title(f"{panel['title']}{extra}", fontsize=9.5)
    fig.legend(list(handles.values()), list(handles.keys()), loc="lower center", ncol=min(4, len(handles)),
               fontsize=8.5, frameon=False,
               title=f"raw points labelled with their spp (denoised points: the same spp, left to right); "
                     f"goal: ≥ {goal:g}× at equal FLIP", title_fontsize=8.5)
    legend_rows = math.ceil(len(handles) / min(4, len(handles)))
    fig.tight_layout(rect=(0, (0.35 + 0.22 * legend_rows) / (3.9 * rows + 1.0), 1, 1))
    return fig


def save_frontier_chart(panels: list[dict], path: str, goal: float = GOAL_SPEEDUP, metrics=CHART_METRICS) -> str:
    """Write :func:`frontier_figure` as a PNG to ``path``; returns ``path``."""
    return save_figure(frontier_figure(panels, goal, metrics), path)
