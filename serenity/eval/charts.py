"""Speed-vs-accuracy charts (docs/architecture.md, "Accuracy"): x = frame or stage time in milliseconds (log scale),
y = error against the reference (lower is better), one colour per technique, every point labelled,
the Pareto front (no other point is both faster and more accurate) drawn as a step line, and the
paper's settings ringed.

    points = [{"technique": "LPV", "label": "32³, 8 it", "ms": 12.0, "error": 0.08, "paper": True}, ...]
    save_speed_accuracy_chart(points, "chart.png", error_name="relMSE (indirect)")
"""

from __future__ import annotations

import math
import os

from serenity.errors import SerenityError
from serenity.optional import pyplot


def _validate(points: list[dict]) -> list[dict]:
    out = []
    for i, p in enumerate(points):
        try:
            q = {"technique": str(p["technique"]), "label": str(p.get("label", "")), "ms": float(p["ms"]),
                 "error": float(p["error"]), "paper": bool(p.get("paper", False))}
        except (KeyError, TypeError, ValueError) as exc:
            raise SerenityError(f"chart point {i} needs technique, ms and error ({exc})") from None
        if not (q["ms"] > 0 and math.isfinite(q["ms"]) and math.isfinite(q["error"])):
            raise SerenityError(f"chart point {i} ({q['label']!r}): ms must be > 0 and error finite")
        out.append(q)
    if not out:
        raise SerenityError("a chart needs at least one point")
    return out


def pareto_front(points: list[dict]) -> list[int]:
    """Indices of the points no other point dominates (≤ ms and ≤ error, one strictly), by rising ms."""
    order = sorted(range(len(points)), key=lambda i: (points[i]["ms"], points[i]["error"]))
    front, best = [], math.inf
    for i in order:
        if points[i]["error"] < best:
            front.append(i)
            best = points[i]["error"]
    return front


LABEL_OFFSET = (6, 5)
"""Where a point's label starts, points right of and above it."""


def speed_accuracy_figure(points: list[dict], error_name: str = "error", title: str | None = None):
    """A matplotlib Figure of the chart (Agg backend; the caller saves or closes it)."""
    plt = pyplot("speed-vs-accuracy charts")
    pts = _validate(points)
    techniques = list(dict.fromkeys(p["technique"] for p in pts))
    cmap = plt.get_cmap("tab10")
    colour = {t: cmap(k % 10) for k, t in enumerate(techniques)}
    fig, ax = plt.subplots(figsize=(7.5, 4.8), dpi=120)
    front = pareto_front(pts)
    fx = [pts[i]["ms"] for i in front]
    fy = [pts[i]["error"] for i in front]
    ax.step(fx, fy, where="post", color="0.55", lw=1.2, ls="--", zorder=1, label="Pareto front")
    for t in techniques:
        sel = [p for p in pts if p["technique"] == t]
        ax.scatter([p["ms"] for p in sel], [p["error"] for p in sel], color=colour[t], s=36, zorder=3, label=t)
    on_front = set(front)
    labels = []
    for i, p in enumerate(pts):
        if i in on_front:
            ax.scatter([p["ms"]], [p["error"]], facecolors="none", edgecolors="0.2", s=90, lw=1.0, zorder=4)
        if p["paper"]:
            ax.scatter([p["ms"]], [p["error"]], marker="*", color="gold", edgecolors="black", s=260, lw=0.8,
                       zorder=5)
        if p["label"]:
            labels.append(ax.annotate(p["label"], (p["ms"], p["error"]), textcoords="offset points",
                                      xytext=LABEL_OFFSET, fontsize=7.5, color=colour[p["technique"]], zorder=6))
    if any(p["paper"] for p in pts):
        ax.scatter([], [], marker="*", color="gold", edgecolors="black", s=160, label="paper's settings")
    ax.set_xscale("log")
    ax.set_xlabel("time (ms, log scale)")
    ax.set_ylabel(f"{error_name} (lower is better)")
    ymax = max(p["error"] for p in pts)
    ax.set_ylim(bottom=min(0.0, min(p["error"] for p in pts)), top=ymax * 1.15 if ymax > 0 else 1.0)
    lo, hi = min(p["ms"] for p in pts), max(p["ms"] for p in pts)
    ax.set_xlim(lo / 1.6, hi * 2.2)
    ax.grid(True, which="both", alpha=0.25)
    ax.legend(fontsize=8, loc="best")
    if title:
        ax.set_title(title)
    fig.tight_layout()
    _separate_labels(fig, labels)
    return fig


def _separate_labels(fig, labels: list) -> None:
    """Move point labels up, one line at a time, until none overlaps a label placed before it (the
    lowest first): two points close in time and error otherwise print their names over each other.
    Where the stack rises above the axes, the axes grow upwards and the labels are placed again."""
    if not labels:
        return
    ax = labels[0].axes
    for _ in range(3):
        for a in labels:
            a.xyann = LABEL_OFFSET
        fig.canvas.draw()
        renderer = fig.canvas.get_renderer()
        placed = []
        for a in sorted(labels, key=lambda a: a.get_window_extent(renderer).y0):
            for _ in range(len(labels)):
                box = a.get_window_extent(renderer)
                if not any(box.overlaps(b) for b in placed):
                    break
                dx, dy = a.xyann
                a.xyann = (dx, dy + box.height * 72.0 / fig.dpi + 1.0)
            placed.append(a.get_window_extent(renderer))
        frame = ax.get_window_extent(renderer)
        top = max(b.y1 for b in placed)
        if top <= frame.y1:
            return
        lo, hi = ax.get_ylim()  # linear y: grow the range so that the stack's top fits, with a margin
        ax.set_ylim(lo, lo + (hi - lo) * ((top - frame.y0) / frame.height) * 1.05)


def save_speed_accuracy_chart(points: list[dict], path: str, error_name: str = "error",
                              title: str | None = None) -> str:
    """Write the chart of ``points`` as a PNG to ``path``; returns ``path``."""
    return save_figure(speed_accuracy_figure(points, error_name, title), path)


def save_figure(fig, path: str) -> str:
    """Write a matplotlib figure as a PNG to ``path`` (creating its folder), then close it; a path
    that cannot be written is a ``SerenityError`` naming it. Returns ``path``."""
    plt = pyplot("charts")
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    try:
        fig.savefig(path)
    except OSError as exc:
        raise SerenityError(f"{path}: cannot write chart ({exc})") from exc
    finally:
        plt.close(fig)
    return path
