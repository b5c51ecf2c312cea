"""Cascade placement (numpy only): where each LPV cascade's grid lies for a camera.

``fit_cascades(camera_position, view_dir, scene_bounds, config)`` → ``CascadeGrid`` per cascade
that overlaps the scene, finest first; see its docstring. Cell sizes depend only on the config and
the scene, never on the camera, and boxes move in whole cells, so nothing swims.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from serenity.config import LPVConfig


@dataclass(frozen=True)
class CascadeGrid:
    """One cascade's grid: cell (x, y, z) covers origin + cell_size·[x, x+1) × [y, y+1) × [z, z+1)."""

    level: int
    """Cascade index in the config (0 = finest); kept when coarser/finer ones are skipped."""
    origin: tuple[float, float, float]
    """World position of the grid's min corner (m), a multiple of cell_size on each axis."""
    cell_size: float
    """Edge of a cubic cell (m)."""
    resolution: int
    """Cells per axis."""

    @property
    def extent(self) -> float:
        return self.cell_size * self.resolution

    def world_to_grid(self, p) -> np.ndarray:
        """Grid coordinates (cells, float) of world points (…,3)."""
        return (np.asarray(p, np.float64) - np.asarray(self.origin)) / self.cell_size

    def contains(self, p) -> np.ndarray:
        u = self.world_to_grid(p)
        return np.all((u >= 0) & (u < self.resolution), axis=-1)


def fit_cascades(camera_position, view_dir, scene_bounds, config: LPVConfig) -> list[CascadeGrid]:
    """Place the cascades for a camera.

    Extents: the outermost reaches D = min(view_distance, |scene diagonal|) ahead of the camera,
    extent_out = D / (0.5 + forward_shift); cascade c has extent_out / cascade_scale^(C−1−c),
    capped at the scene's largest side plus one cell each way ("whole"). A cascade within a factor
    √cascade_scale of "whole" is grown to "whole" and is the last one (a coarser cascade barely
    coarser than it would cost a full propagation for nothing). That last cascade's cells are at
    least (largest scene side) / ``scene_cells``: propagation is diffusive (a beam turns into side
    lobes within a cell or two, so light covers about √N cells in N iterations, not N), and light
    that must cross a closed room needs the room to be only a few cells across. Its box is then
    larger than the scene (centred on it); the cost is the same.
    Cell sizes depend only on the config and the scene — never on the camera — so nothing swims.
    Placement: the box's min corner is camera + forward_shift·extent·view − extent/2, clipped
    per axis to the scene bounds padded by one cell (centred on the scene along an axis the box
    already spans), then snapped down to a multiple of the cell size: the box moves in whole
    cells, so the same camera cell gives the same grids. Skipped: a cascade whose box misses the
    scene bounds.
    """
    cam = np.asarray(camera_position, np.float64).reshape(3)
    view = np.asarray(view_dir, np.float64).reshape(3)
    view = view / max(float(np.linalg.norm(view)), 1e-12)
    b = np.asarray(scene_bounds, np.float64).reshape(2, 3)
    size = np.maximum(b[1] - b[0], 1e-6)
    reach = min(float(config.view_distance), float(np.linalg.norm(size)))
    outer = reach / (0.5 + config.forward_shift)
    grids: list[CascadeGrid] = []
    for c, res in enumerate(config.resolutions):
        extent = outer / config.cascade_scale ** (config.cascades - 1 - c)
        whole = float(size.max()) * res / (res - 2)  # the scene plus one cell each side
        holds_scene = extent * math.sqrt(config.cascade_scale) >= whole
        if holds_scene:
            extent = whole
        cell = extent / res
        if holds_scene and config.scene_cells > 0:  # light must cross the scene: coarse enough cells
            cell = max(cell, float(size.max()) / config.scene_cells)
            extent = cell * res
        lo, hi = b[0] - cell, b[1] + cell
        want = cam + config.forward_shift * extent * view - extent / 2
        mn = np.where(extent >= hi - lo, (lo + hi - extent) / 2, np.clip(want, lo, np.maximum(lo, hi - extent)))
        origin = np.floor(mn / cell) * cell
        if np.all(origin < b[1]) and np.all(origin + extent > b[0]):
            grids.append(CascadeGrid(c, tuple(float(v) for v in origin), float(cell), int(res)))
        if holds_scene:
            break
    return grids


