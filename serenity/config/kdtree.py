"""The kd-tree's build: ``KdBuildConfig`` (paper §9)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from serenity.errors import ConfigError

#: deepest kd-tree the build makes (the traversal's stack holds one entry per level)
KD_MAX_DEPTH = 62


@dataclass(frozen=True)
class KdBuildConfig:
    """The kd-tree's binned SAH build (paper §9; ``serenity/kernels/kdtree_build.py``). Every field is
    part of the tree's disk-cache key. Costs are relative units (only their ratio matters)."""

    traversal_cost: float = 3.0
    """C_trav: cost of one inner-node step, relative to ``intersection_cost``. 3: the CPU's packets
    test a leaf's triangles 8 at a time, so more triangles per leaf cost little more; against 2 the
    benchmark's incoherent rays trace 1.06x as fast (paired), camera rays 0.98x, on a tree of 301k
    nodes instead of 500k; 3.5 and 4 read 1.09x / 0.93x."""
    intersection_cost: float = 1.0
    """C_isect: cost of one ray–triangle test."""
    empty_bonus: float = 0.8
    """Fraction (0..1) of a split's cost removed when one side is empty (empty-space cut-off)."""
    min_empty_fraction: float = 0.1
    """The bonus applies only when the empty side is at least this fraction (0..1) of the node's extent.
    0.1 rather than 0: thin empty slabs cost a traversal step each and save little; with 0.1 the
    benchmark's rays take 12 % fewer steps and 17 % fewer triangle tests and coherent rays trace
    16-22 % faster per CPU-second."""
    bins: int = 32
    """SAH bins per axis per node, 4..64 (a node with fewer triangles gets fewer: the next power of 2)."""
    max_depth: int | None = None
    """Depth limit, 0..``KD_MAX_DEPTH``; None = 8 + 1.3·log2(N) for N triangles (pbrt's rule), capped."""

    def __post_init__(self):
        for name in ("traversal_cost", "intersection_cost"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"KdBuildConfig.{name} must be a finite number > 0, got {value!r}")
        for name in ("empty_bonus", "min_empty_fraction"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < 1.0):
                raise ConfigError(f"KdBuildConfig.{name} must be in [0, 1), got {value!r}")
        if not (isinstance(self.bins, int) and 4 <= self.bins <= 64):
            raise ConfigError(f"KdBuildConfig.bins must be an int in 4..64, got {self.bins!r}")
        if self.max_depth is not None and not (isinstance(self.max_depth, int) and 0 <= self.max_depth <= KD_MAX_DEPTH):
            raise ConfigError(f"KdBuildConfig.max_depth must be None or an int in 0..{KD_MAX_DEPTH}, "
                                f"got {self.max_depth!r}")

    def depth_limit(self, n: int) -> int:
        """The depth limit for a mesh of ``n`` triangles."""
        d = self.max_depth if self.max_depth is not None else int(round(8 + 1.3 * math.log2(max(n, 1))))
        return int(max(0, min(d, KD_MAX_DEPTH)))
