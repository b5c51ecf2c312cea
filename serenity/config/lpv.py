"""Light propagation volumes (paper §8): ``LPVConfig``."""

from __future__ import annotations

from dataclasses import dataclass

from serenity.config.image import MAX_IMAGE_SIZE
from serenity.errors import ConfigError

#: cascades the LPV kernels and ``lpv.glsl`` take at most
LPV_MAX_CASCADES = 3


@dataclass(frozen=True)
class LPVConfig:
    """Light propagation volumes (paper §8): one-bounce diffuse + glossy light from the sun's RSM and
    the sky-lit G-buffer, propagated in nested grids around the camera. Frozen: kernels are
    specialised on it. See ``serenity/kernels/lpv/`` (the package docstring has the maths)."""

    enabled: bool = True
    """Render the LPV's indirect light (False: no RSM, no injection, no LPV lighting pass)."""
    diffuse: bool = True
    """Add the LPV's diffuse light (albedo/π · E). False: the lighting passes skip its lookup (the
    volume is still injected and propagated while ``glossy`` needs it)."""
    glossy: bool = True
    """Add the LPV's glossy light (k_s · L along the reflected direction). False: the lighting passes
    skip the glossy march. With ``diffuse`` also False the LPV lighting passes are not drawn."""
    resolution: int | tuple[int, ...] = 12
    """Cells per axis of each cascade's cubic grid; an int for all cascades or one per cascade.
    12³, not the paper's 32³: at 32³ cells are finer than the propagation can cross in a frame's
    budget; over 7 views of the courtyard and the Cornell box (``benchmarks/experiments/bench_lpv_views.py``)
    12³ has a lower mean FLIP and relMSE than 16³ in both scenes, for about half the update."""
    cascades: int = 3
    """Nested grids around the camera (1..3), finest first."""
    iterations: int | tuple[int, ...] = 8
    """Propagation iterations (light travels one cell per iteration); an int for all cascades or one
    per cascade, finest first."""
    cross_scene: bool = True
    """The coarsest fitted cascade runs at least as many iterations as it has cells across the scene's
    largest side (capped at its resolution), so light can reach from one end of the scene to the other."""
    scene_cells: float = 6.0
    """The cascade that holds the whole scene has cells of at least (largest scene side) / scene_cells
    (0 = off): light crosses a closed room only if it is a few cells across (``fit_cascades``)."""
    handover: bool = True
    """Cascaded reach (``kernels/lpv`` docstring, "Hand-over"): each cascade also accumulates the light
    of its iterations past the reach of the next finer one, and that far light is added into the
    finer cascades, so a fine cascade's lookups see light from beyond its own N cells."""
    early_stop: float = 0.01
    """Stop a cascade when an iteration adds less than this fraction of its accumulated |DC| (0 = never)."""
    geometry_volume: bool = True
    """Fuzzy occlusion from surfels during propagation (compiled in/out)."""
    clamp_faces: bool = True
    """Propagation clamps each face's flux at 0 (Φ_f = Δω_f·max(0, I(ω_f))): the L1 lobes' negative back
    tails no longer carry negative light to the cells behind them (``kernels/lpv`` docstring, "Clamped
    faces"; compiled in/out)."""
    accumulate_injected: bool = True
    """The looked-up grid holds the injected VPL lobes as well as the propagated light (False: only
    the propagated light, so a VPL is first seen one cell away; within its own cell it is near field,
    which an L1 lobe at the cell centre gets badly wrong)."""
    rsm_size: int = 256
    """Texels per side of the sun's reflective shadow map, whose texels are the sun's VPLs (one per texel)."""
    sky_vpl_stride: int = 4
    """One sky-light VPL per stride×stride block of G-buffer pixels (paper Fig. 11)."""
    injection_offset: float = 0.5
    """VPLs are moved this many cells along their normal before picking their cell (Kaplanyan)."""
    lookup_offset: float = 0.5
    """Lookup points are moved this many cells along the receiver normal (less self-lighting/leaks)."""
    leak_guard: bool = True
    """Irradiance lookups weight each of the 8 trilinear cells by how far its centre lies in front of
    the receiving surface: stops light behind a wall thinner than a cell leaking onto its dark side
    through the interpolation. Costs 8 unfiltered fetches instead of 1 filtered (compiled in/out)."""
    lookup_occlusion: bool = True
    """With the leak guard and the geometry volume: a lookup also drops the trilinear cells that lie
    across a blocking face of the geometry volume from the cell just in front of the surface (the light
    above a sunlit roof does not reach the top of the wall below its ceiling; compiled in/out)."""
    lookup_planes: bool = True
    """With the lookup occlusion: the geometry volume also records where its blockers lie inside their
    cells (the surfels' mean offset along each axis), and a surface on the far side of a blocker that
    shares its cell takes its home cell across it (a wall row just under a ceiling that lies in a
    cell's lower half no longer reads the light above the roof; compiled in/out)."""
    self_damping: float = 2.5
    """Self-illumination damping (``kernels/lpv`` docstring, "Self-illumination"; 0 = off): an irradiance
    lookup's SH is scaled by (DC self_damping cells further along the normal / DC where it looks up)^
    ``self_damping_power``, clamped to [0, 1] (Kaplanyan & Dachsbacher 2010: light whose intensity falls
    off along the normal flows away from the surface, most of it the surface's own). With it a lit
    plane gets 0.02-0.05 of its exitance back instead of 0.33-0.41, the open ground is within 5 % of
    the reference instead of 12 % too bright, and the Cornell box's indirect light beats no LPV on
    relMSE and FLIP; the courtyard's FLIP rises by ~0.01 (``benchmarks/bench_lpv_room.py``)."""
    self_damping_power: float = 2.0
    """The exponent of ``self_damping``'s ratio."""
    coverage_blocking: bool = False
    """With the geometry volume: propagation through a face is also attenuated by the projected coverage
    of its surfels (Σ A·n²/s² along the axis, either side): a two-sided wall thinner than a cell blocks
    all of the light, not the 2/3 its L1 blocking lobe can (``kernels/lpv``, "Coverage blocking"). Off:
    it takes the thin-wall leak from 0.095 to 0.006 of the lit side, but the Cornell box's ceiling
    gets most of its LPV light through the ceiling from the sunlit roof, and without that leak only
    0.17× the reference's."""
    stagger: bool = False
    """Re-inject and propagate one cascade per update, in turn, instead of all of them (each then
    lags the camera and the light by at most ``cascades`` updates; a cascade that did not change
    is skipped, and a still scene converges to what updating all at once gives). The finer
    cascades' hand-over from a coarser one is rebuilt every update from its last propagation."""
    temporal_blend: float = 0.15
    """Fraction of the way from the light the lookups read in the last frame to the newest propagation
    that each frame moves them (1 = switch at once): a re-injected or staggered cascade is blended in
    over a few frames instead of switched, so that the VPLs' sampling of a moving sun does not pop
    (``LightPropagationVolume.update``'s ``blend``; ``docs/stability.md``)."""
    view_distance: float = 64.0
    """Metres the outermost cascade reaches along the view direction (capped by the scene size)."""
    cascade_scale: float = 2.0
    """Extent ratio between consecutive cascades."""
    forward_shift: float = 0.25
    """Each box is pushed along the view direction by this fraction of its extent."""
    blend_cells: float = 2.0
    """Width of the cascade blend band, in the cascade's cells (0: hard switch)."""
    edge_margin: float = 0.5
    """Cells at a (non-last) cascade's border given zero weight (no light from outside reaches them)."""
    glossy_steps: int = 8
    """Samples along the reflected direction for glossy lookups."""
    glossy_step: float = 1.0
    """Spacing of glossy samples, in cells of the finest active cascade."""

    def __post_init__(self):
        if not (1 <= self.cascades <= LPV_MAX_CASCADES):
            raise ConfigError(f"LPVConfig.cascades must be in 1..{LPV_MAX_CASCADES}, got {self.cascades}")
        res = self.resolutions
        if len(res) != self.cascades or any(r < 2 or r > 256 for r in res):
            raise ConfigError(f"LPVConfig.resolution must be one int in 2..256 or one per cascade, "
                              f"got {self.resolution!r}")
        its = self.iteration_counts
        if len(its) != self.cascades or any(i < 0 for i in its):
            raise ConfigError(f"LPVConfig.iterations must be one int >= 0 or one per cascade, got {self.iterations!r}")
        if not (isinstance(self.rsm_size, int) and 16 <= self.rsm_size <= MAX_IMAGE_SIZE):
            raise ConfigError(f"LPVConfig.rsm_size must be an int in 16..{MAX_IMAGE_SIZE}, got {self.rsm_size!r}")
        if not (isinstance(self.sky_vpl_stride, int) and 1 <= self.sky_vpl_stride <= 64):
            raise ConfigError(f"LPVConfig.sky_vpl_stride must be an int in 1..64, got {self.sky_vpl_stride!r}")
        if not (self.early_stop >= 0):
            raise ConfigError(f"LPVConfig.early_stop must be >= 0, got {self.early_stop}")
        if not self.view_distance > 0:
            raise ConfigError(f"LPVConfig.view_distance must be positive, got {self.view_distance}")
        if not self.cascade_scale >= 1:
            raise ConfigError(f"LPVConfig.cascade_scale must be >= 1, got {self.cascade_scale}")
        if not 0 <= self.forward_shift < 0.5:
            raise ConfigError(f"LPVConfig.forward_shift must be in [0, 0.5), got {self.forward_shift}")
        if not self.blend_cells >= 0:
            raise ConfigError(f"LPVConfig.blend_cells must be >= 0, got {self.blend_cells}")
        if not self.edge_margin >= 0:
            raise ConfigError(f"LPVConfig.edge_margin must be >= 0, got {self.edge_margin}")
        if not self.glossy_steps >= 1:
            raise ConfigError(f"LPVConfig.glossy_steps must be >= 1, got {self.glossy_steps}")
        if not self.glossy_step > 0:
            raise ConfigError(f"LPVConfig.glossy_step must be positive, got {self.glossy_step}")
        if not 0.0 < self.temporal_blend <= 1.0:
            raise ConfigError(f"LPVConfig.temporal_blend must be in (0, 1], got {self.temporal_blend}")

    @property
    def iteration_counts(self) -> tuple[int, ...]:
        if isinstance(self.iterations, int):
            return (int(self.iterations),) * self.cascades
        return tuple(int(i) for i in self.iterations)

    @property
    def resolutions(self) -> tuple[int, ...]:
        if isinstance(self.resolution, int):
            return (int(self.resolution),) * self.cascades
        return tuple(int(r) for r in self.resolution)
