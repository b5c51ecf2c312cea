"""The interface of a sky volume's lighting method (``SkyConfig.method``): how the probes of a
:class:`~serenity.kernels.skyvolume.SkyVolume` are lit, one subclass per method —

- ``"layers"`` :class:`~serenity.kernels.skylayers.LayersMethod` (paper §7): rays against the
  occlusion quads, one y-layer of probes per update;
- ``"transfer"`` :class:`~serenity.kernels.skytransfer.TransferMethod`: the quads' visibility
  integrated once per probe, every probe re-lit from a new sky by a matrix product;
- ``"gather"`` :class:`~serenity.kernels.skygather.GatherMethod` (the traced probes): rays through
  the kd-tree, lit by the sky and by the light the scene bounces.

The volume owns what every method shares (the grid, the sky map, the coefficients, the layers' cycle,
the lookup: ``serenity.kernels.skylookup``); a method writes the coefficients (P, 27) and says which
y-layers it re-lit (``SkyVolume.mark_lit``).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np
import warp as wp

from serenity.config import SkyConfig


class SkyVolumeMethod(ABC):
    """How a sky volume's probes are lit (module docstring). ``volume``: the
    :class:`~serenity.kernels.skyvolume.SkyVolume` it lights."""

    #: its probes are shadowed by occlusion quads (fitted to a scene that has none:
    #: ``SkyConfig.auto_quads``)
    occlusion_quads: ClassVar[bool] = True
    #: the renderer may run its updates on the volume worker thread beside the GL passes (CPU)
    on_volume_worker: ClassVar[bool] = True

    @classmethod
    def max_axis_probes(cls, config: SkyConfig) -> int:
        """The most probes along one axis of the grid."""
        return 255

    @classmethod
    def lookup_defines(cls, config: SkyConfig) -> dict[str, int]:
        """The switches the shaders' lookup (sky.glsl) is compiled with for this method's volume."""
        return {"SKY_VISIBILITY": 0}

    def __init__(self, volume):
        self.volume = volume
        dev = volume.device
        #: (atlas (Z·T, Y, X·T, 2), offsets (P, 3)) of the probes' visibility (``skylookup``), or None
        self.visibility: tuple[np.ndarray, np.ndarray] | None = None
        #: the same as Warp arrays (empty arrays: the lookup is plain trilinear)
        self.visibility_wp = (wp.zeros((0, 0, 0), dtype=wp.vec2, device=dev), wp.zeros(0, dtype=wp.vec3, device=dev))

    def may_change(self, sun: np.ndarray) -> bool:
        """Whether :meth:`update` could change a probe now; False only when it surely changes none: the
        sky map needs no rebake and every layer is current."""
        v = self.volume
        return bool(np.any(v.layer_versions < 0)) or v.sky_may_rebake(sun) or v.pending_layers > 0

    @abstractmethod
    def update(self, sun: np.ndarray, sky_map, layers: int) -> bool:
        """Bring the probes towards the current sky (``sky_map``: the volume's Warp sky map, ``layers``:
        the caller's layers per update); returns whether any probe changed."""

    @abstractmethod
    def rebuild(self, sun: np.ndarray, sky_map) -> None:
        """Bring every probe up to date now."""
