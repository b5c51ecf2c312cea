"""Per-object frustum culling of the scene's draw ranges (G-buffer, shadow maps, RSM).

Each draw range of ``SceneGL`` (one material of one mesh) carries the world box of its triangles,
computed once at upload. A pass culls a range against the six planes of the very matrix it draws
with (Gribb & Hartmann 2001: row 4 ± rows 1–3 of the view-projection, OpenGL's -w <= x, y, z <= w),
so a range is skipped only when every point of its box lies outside one plane: then GL would clip
all of its triangles and they would write nothing, and the images are the same as without
culling. The test is conservative by a margin of 1e-5 of the magnitudes in the plane's sum (the
GPU evaluates the same sum in float32). A light's orthographic box needs no extension towards the
light: the cascades' depth range already spans the whole scene, and a caster outside the box it
is drawn with is clipped by GL anyway.

Ranges that are visible and adjacent in the index buffer are drawn as one call (for the G-buffer
and the RSM only where they share a material, for the shadows' opaque casters always), so a view
that culls nothing makes as many calls as before the split per mesh.
"""

from __future__ import annotations

import numpy as np


def frustum_planes(view_proj: np.ndarray) -> np.ndarray:
    """(6, 4) float64 planes (a, b, c, d), inside where a·x + b·y + c·z + d >= 0, of a world → clip
    matrix as the GPU receives it (rounded to float32)."""
    m = np.asarray(view_proj, np.float32).astype(np.float64)
    return np.stack([m[3] + m[0], m[3] - m[0], m[3] + m[1], m[3] - m[1], m[3] + m[2], m[3] - m[2]])


def boxes_in_frustum(view_proj: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """(R,) bool: whether the boxes [lo, hi] (R, 3) may touch the frustum of ``view_proj``; False
    only for a box wholly outside one of its planes."""
    planes = frustum_planes(view_proj)
    c, e = (lo + hi) * 0.5, (hi - lo) * 0.5
    n, an = planes[:, :3], np.abs(planes[:, :3])
    reach = c @ n.T + e @ an.T + planes[:, 3]               # (R, 6) the box's farthest point inside
    tol = 1e-5 * ((np.abs(c) + e) @ an.T + np.abs(planes[:, 3]))
    return np.all(reach >= -tol, axis=1)


class CulledRanges:
    """A fixed list of draw ranges (``scene_gl.DrawRange``, each with its world box ``lo``/``hi``)
    and the count of those the last :meth:`visible` kept."""

    def __init__(self, ranges):
        self.ranges = list(ranges)
        self.refresh()
        self.mesh = np.array([r.mesh for r in self.ranges], np.int64)
        self.level = np.array([r.level for r in self.ranges], np.int64)
        #: ranges kept by the last ``visible`` (``candidates`` with culling off) ...
        self.drawn = len(self.ranges)
        #: ... of the ranges at the levels of detail it drew (``len(ranges)`` without levels of detail)
        self.candidates = len(self.ranges)

    def refresh(self) -> None:
        """Read the ranges' boxes again (after their meshes moved: ``SceneGL.update_meshes``)."""
        self.lo = np.array([r.lo for r in self.ranges], np.float64).reshape(-1, 3)
        self.hi = np.array([r.hi for r in self.ranges], np.float64).reshape(-1, 3)

    def visible(self, view_proj: np.ndarray | None, merge_materials: bool = False,
                levels: np.ndarray | None = None) -> list:
        """The ranges whose box may touch the frustum of ``view_proj`` (all of them for None), in
        index-buffer order, adjacent ones merged into one range when they share a material (any
        material with ``merge_materials``; the merged range keeps the first one's material). With
        ``levels`` (a level of detail per scene mesh, ``SceneGL.levels``) only the ranges of each
        mesh's level; without, only level 0 (the meshes' own triangles)."""
        if levels is None:
            at_level = self.level == 0
        else:
            at_level = self.level == np.where(self.mesh >= 0, np.asarray(levels)[np.maximum(self.mesh, 0)], 0)
        keep = at_level.copy()
        if view_proj is not None and self.ranges:
            keep &= boxes_in_frustum(view_proj, self.lo, self.hi)
        self.drawn = int(np.count_nonzero(keep))
        self.candidates = int(np.count_nonzero(at_level))
        out = []
        for r, k in zip(self.ranges, keep, strict=True):
            if not k:
                continue
            last = out[-1] if out else None
            if (last is not None and last.first + last.count == r.first
                    and (merge_materials or last.material == r.material)):
                out[-1] = type(r)(last.material, last.first, last.count + r.count)
            else:
                out.append(r)
        return out
