"""Fit occlusion quads to a scene's meshes automatically (beyond the paper: it placed them by hand).

Input: a :class:`serenity.scene.model.Scene` (its merged triangles, metres). Output:
:class:`QuadFit` — a list of :class:`serenity.scene.model.OcclusionQuad` and its quality.

Method (pure numpy):
1. Faces are grouped into **planes**: greedily, largest face first, a plane takes every
   unassigned face whose normal is within ``angle_deg`` of its normal (either orientation: quads
   are two-sided) and whose centroid lies within ``plane_tol`` (default 1% of the scene's size)
   of it.
2. Each plane's faces are split into **connected pieces** (faces sharing a vertex position), so
   two coplanar walls far apart do not become one rectangle over the gap.
3. Each piece gets the **minimum-area oriented rectangle** of its vertices in the plane (rotating
   calipers over the 2-D convex hull's edge directions; a vertical plane keeps world-up as its
   ``up`` when that costs < 1% area). Pieces whose rectangle is smaller than ``min_size`` (default
   5% of the scene's largest extent) on either side are dropped: small props do not block sky light.
4. The **ground** — upward-facing faces within ``plane_tol`` of the scene's lowest level — is not
   fitted: below the horizon the sky volume uses its ground model.

Quality (``QuadFit``):
    coverage: fraction of the (non-ground) mesh area that lies in a kept piece (1 = every
        surface is represented; props and curved parts lower it);
    fill: mesh area of the kept pieces / total quad area (1 = the rectangles are exactly the
        surfaces; < 1 = the rectangles block sky light where there is nothing, e.g. arches,
        irregular outlines, terrain);
    per_quad_fill: the same per quad.
A terrain-like height field fails gracefully: many small non-coplanar pieces, low coverage.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from serenity.scene.model import OcclusionQuad


@dataclass
class QuadFit:
    quads: list = field(default_factory=list)
    coverage: float = 0.0
    fill: float = 0.0
    per_quad_fill: list[float] = field(default_factory=list)
    planes: int = 0
    pieces: int = 0

    def summary(self) -> str:
        return (f"{len(self.quads)} quads from {self.pieces} pieces on {self.planes} planes: "
                f"coverage {self.coverage:.1%} of the mesh area, fill {self.fill:.1%} of the quad area")


def _components(faces: np.ndarray, vertex_keys: np.ndarray) -> np.ndarray:
    """Connected components (label per face) of faces sharing a vertex key."""
    n = len(faces)
    parent = np.arange(n)

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    first: dict[int, int] = {}
    for fi in range(n):
        for k in vertex_keys[faces[fi]]:
            k = int(k)
            if k in first:
                ra, rb = find(fi), find(first[k])
                if ra != rb:
                    parent[ra] = rb
            else:
                first[k] = fi
    return np.array([find(i) for i in range(n)])


def _cross2(a, b) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _hull_2d(pts: np.ndarray) -> np.ndarray:
    """Convex hull (Andrew's monotone chain), counter-clockwise."""
    p = np.unique(np.round(pts, 9), axis=0)
    if len(p) < 3:
        return p
    p = p[np.lexsort((p[:, 1], p[:, 0]))]

    def half(points):
        h = []
        for q in points:
            while len(h) >= 2 and _cross2(h[-1] - h[-2], q - h[-2]) <= 0:
                h.pop()
            h.append(q)
        return h

    lower, upper = half(p), half(p[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _min_rect(pts2: np.ndarray, prefer_axis: np.ndarray | None):
    """(centre (2,), axis u (2,), half lengths (hu, hv)) of the min-area rectangle of 2-D points."""
    hull = _hull_2d(pts2)
    cands = []
    if len(hull) >= 2:
        e = np.roll(hull, -1, axis=0) - hull
        ang = np.arctan2(e[:, 1], e[:, 0]) % (np.pi / 2)
        cands = list(np.unique(np.round(ang, 9)))
    if prefer_axis is not None:
        cands.append(float(np.arctan2(prefer_axis[1], prefer_axis[0]) % (np.pi / 2)))
    if not cands:
        cands = [0.0]
    best = None
    for a in cands:
        u = np.array([np.cos(a), np.sin(a)])
        v = np.array([-u[1], u[0]])
        pu, pv = pts2 @ u, pts2 @ v
        area = (pu.max() - pu.min()) * (pv.max() - pv.min())
        rec = (area, a, u, v, pu, pv)
        if best is None or area < best[0] - 1e-12:
            best = rec
    if prefer_axis is not None:  # keep world-up when it costs < 1% area
        a = cands[-1]
        u = np.array([np.cos(a), np.sin(a)])
        v = np.array([-u[1], u[0]])
        pu, pv = pts2 @ u, pts2 @ v
        area = (pu.max() - pu.min()) * (pv.max() - pv.min())
        if area <= best[0] * 1.01 + 1e-12:
            best = (area, a, u, v, pu, pv)
    _, _, u, v, pu, pv = best
    centre = u * (pu.max() + pu.min()) / 2 + v * (pv.max() + pv.min()) / 2
    return centre, u, v, (pu.max() - pu.min()) / 2, (pv.max() - pv.min()) / 2


def fit_occlusion_quads(scene, angle_deg: float = 10.0, plane_tol: float | None = None,
                        min_size: float | None = None) -> QuadFit:
    """Fit occlusion quads to ``scene``'s meshes (see the module docstring)."""
    pos, _, _, faces, _ = scene.merged()
    p = pos.astype(np.float64)
    lo, hi = scene.bounds
    size = float(np.max(hi - lo))
    plane_tol = 0.01 * size if plane_tol is None else float(plane_tol)
    min_size = 0.05 * size if min_size is None else float(min_size)
    a, b, c = p[faces[:, 0]], p[faces[:, 1]], p[faces[:, 2]]
    cr = np.cross(b - a, c - a)
    area2 = np.linalg.norm(cr, axis=1)
    keep = area2 > 1e-12
    normal = np.where(keep[:, None], cr / np.maximum(area2, 1e-30)[:, None], 0.0)
    area = area2 / 2
    centroid = (a + b + c) / 3
    ground = (normal[:, 1] > np.cos(np.radians(angle_deg))) & (centroid[:, 1] - lo[1] < plane_tol)
    cand = keep & ~ground
    total = float(area[cand].sum())
    keys = np.unique(np.round(p / max(plane_tol * 1e-3, 1e-9)).astype(np.int64), axis=0, return_inverse=True)[1]
    keys = keys.reshape(-1)
    cos_tol = np.cos(np.radians(angle_deg))
    unassigned = cand.copy()
    order = np.argsort(-area)
    fit = QuadFit()
    covered = 0.0
    quad_area = 0.0
    for f in order:
        if not unassigned[f]:
            continue
        n = normal[f]
        d = float(n @ centroid[f])
        members = unassigned & (np.abs(normal @ n) >= cos_tol) & (np.abs(centroid @ n - d) <= plane_tol)
        unassigned &= ~members
        fit.planes += 1
        idx = np.nonzero(members)[0]
        labels = _components(faces[idx], keys)
        # plane basis: for near-vertical planes, e2 = world up projected
        up = np.array([0.0, 1.0, 0.0])
        e2 = up - n * (up @ n)
        vertical = np.linalg.norm(e2) > 0.5
        if not vertical:
            e2 = np.array([0.0, 0.0, -1.0]) - n * (-n[2])
        e2 /= np.linalg.norm(e2)
        e1 = np.cross(e2, n)
        for lab in np.unique(labels):
            fi = idx[labels == lab]
            fit.pieces += 1
            verts = p[np.unique(faces[fi])]
            rel = verts - n * ((verts @ n) - d)[:, None]
            pts2 = np.stack([rel @ e1, rel @ e2], axis=1)
            centre2, u2, v2, hu, hv = _min_rect(pts2, np.array([0.0, 1.0]) if vertical else None)
            if min(2 * hu, 2 * hv) < min_size:
                continue
            u3 = u2[0] * e1 + u2[1] * e2
            v3 = v2[0] * e1 + v2[1] * e2
            centre3 = n * d + centre2[0] * e1 + centre2[1] * e2
            # the axis closer to world up becomes the quad's "up"
            if abs(u3[1]) > abs(v3[1]):
                up3, right3, hup, hright = u3, v3, hu, hv
            else:
                up3, right3, hup, hright = v3, u3, hv, hu
            piece_area = float(area[fi].sum())
            qa = 4 * hup * hright
            fit.quads.append(OcclusionQuad(centre3, up3, right3, max(hup, 1e-6), max(hright, 1e-6)))
            fit.per_quad_fill.append(piece_area / qa if qa > 0 else 0.0)
            covered += piece_area
            quad_area += qa
    fit.coverage = covered / total if total > 0 else 0.0
    fit.fill = covered / quad_area if quad_area > 0 else 0.0
    return fit
