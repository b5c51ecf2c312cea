"""Frozen render settings. Units are stated on each attribute; defaults are the paper's where it
gives them. Later features add their own config classes here (SkyConfig, LPVConfig, ...)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from serenity.errors import SerenityError


@dataclass(frozen=True)
class ShadowConfig:
    """Sun shadows: cascaded shadow maps + PCSS (paper §6). See ``serenity/raster/shadow.py``."""

    size: int = 2048
    """Resolution of one cascade (texels per side); the atlas holds 2×2 tiles."""
    cascades: int = 4
    """Number of cascades, 1–4."""
    split_lambda: float = 0.75
    """Practical split scheme blend: 0 uniform, 1 logarithmic."""
    max_distance: float = 200.0
    """Farthest view depth (m) that receives cascaded shadows (also clamped to the scene)."""
    cascade_blend: float = 0.1
    """Fraction of each cascade's depth range cross-faded into the next (hides the seam)."""
    filter: str = "pcss"
    """"hard" (1 tap), "pcf" (fixed radius), or "pcss" (penumbra from the sun's angular size)."""
    pcf_radius: float = 2.0
    """PCF filter radius in texels ("pcf" mode)."""
    blocker_samples: int = 16
    """PCSS blocker-search taps."""
    filter_samples: int = 32
    """PCF / PCSS filter taps."""
    pcss_max_blocker: float = 20.0
    """Farthest blocker (m above the receiver) the PCSS blocker search is sized for."""
    bias: float = 1.0
    """Constant depth bias, in shadow-map texels (converted to depth units in the shader)."""
    normal_offset: float = 1.0
    """Normal offset of the lookup point, in texels, scaled by the slope tan θ (clamped 1–4)."""

    def __post_init__(self):
        if not 16 <= self.size <= 8192:
            raise SerenityError(f"shadow map size must be in 16..8192, got {self.size}")
        if not 1 <= self.cascades <= 4:
            raise SerenityError(f"shadow cascades must be 1..4, got {self.cascades}")
        if self.filter not in ("hard", "pcf", "pcss"):
            raise SerenityError(f"shadow filter must be hard, pcf or pcss, got {self.filter!r}")
        if not (1 <= self.blocker_samples <= 128 and 1 <= self.filter_samples <= 256):
            raise SerenityError("shadow sample counts must be in 1..128 (blocker) and 1..256 (filter)")


@dataclass(frozen=True)
class SSAOConfig:
    """Screen-space ambient occlusion (main view only; multiplies indirect light only)."""

    enabled: bool = True
    radius: float = 1.0
    """Occlusion radius, metres (the ray-traced AO it approximates uses the same)."""
    directions: int = 12
    """Cosine-distributed directions per pixel."""
    steps: int = 4
    """March points per direction."""
    bias: float = 0.03
    """Metres: offset along the normal and depth tolerance (avoids self-occlusion)."""
    thickness: float = 2.0
    """Metres: a march point further behind the depth buffer than this is not blocked."""
    blur_radius: int = 4
    """Bilateral blur half-width in pixels (0 = off)."""

    def __post_init__(self):
        if not (self.radius > 0 and 1 <= self.directions <= 256 and 1 <= self.steps <= 64):
            raise SerenityError("SSAO needs radius > 0, 1..256 directions and 1..64 steps")


@dataclass(frozen=True)
class RenderConfig:
    exposure: float = 0.02
    """Multiplier applied to radiance (W·m⁻²·sr⁻¹) before Reinhard; 0.02 maps a white wall in
    noon sun (≈300) to about 0.86 display luminance."""
    ambient: str = "none"
    """Indirect term while the GI techniques are absent: "none", or "constant" (the classic flat
    ambient hack, irradiance π·L_sky on every surface — the baseline the GI must beat)."""
    shadow: ShadowConfig = field(default_factory=ShadowConfig)
    ssao: SSAOConfig = field(default_factory=SSAOConfig)
    sync_stages: bool = True
    """Wait for the GL queue after each stage so per-stage wall times are exact (costs overlap)."""
    ray_tracing: bool = True
    """Ray-traced reflections and refractions for mirror/metal/glass pixels (paper §9)."""
    transmissions: int = 4
    """Transparent interfaces a refraction ray is bent through before the surface it shows (the
    back face of a glass solid, a second pane, total internal reflection inside a prism); 0 = the
    paper's single refraction, where glass solids show their own back faces."""
    overlap: bool = True
    """Run the CPU ray tracing in a worker thread while the GL work proceeds (paper §10); False
    traces inline first (the serial schedule, for comparison)."""
    osm_size: int = 512
    """Texels per side of each of the 3 overlapped shadow maps of the ray-traced views (paper §9)."""
    sky_lighting: bool = True
    """The sky lighting irradiance volume (paper §7): occluded sky light on every surface; the
    sky dome and the sun's colour from the atmosphere (paper §5, §6) for "atmosphere" skies."""
    sky_settings: object = None
    """A ``serenity.kernels.skyvolume.SkyVolumeConfig`` (None: its defaults)."""
    sky_layers_per_frame: int = 1
    """Probe layers re-integrated per frame while the sun moves (paper: one); the first frame
    builds the whole volume."""
    lpv: bool = True
    """Light propagation volumes: one-bounce diffuse + glossy light from the sun's RSM and the
    sky-lit G-buffer (paper §8)."""
    lpv_settings: object = None
    """A ``serenity.kernels.lpv.LPVConfig`` (None: its defaults — 3 cascades of 16³, 8 iterations, the coarsest
    extended to cross the scene, far light handed over to the finer cascades)."""
    rsm_size: int = 256
    """Texels per side of the sun's reflective shadow map (one VPL per texel)."""
    sky_vpl_stride: int = 4
    """One sky-light VPL per stride×stride block of G-buffer pixels (paper Fig. 11)."""

    def __post_init__(self):
        if not (self.exposure > 0):
            raise SerenityError(f"exposure must be positive, got {self.exposure}")
        if not (isinstance(self.transmissions, int) and 0 <= self.transmissions <= 16):
            raise SerenityError(f"transmissions must be an int in 0..16, got {self.transmissions!r}")
        if not (16 <= self.osm_size <= 8192):
            raise SerenityError(f"osm_size must be in 16..8192, got {self.osm_size}")
        if self.ambient not in ("none", "constant"):
            raise SerenityError(f"ambient must be 'none' or 'constant', got {self.ambient!r}")
        from serenity.kernels.lpv import LPVConfig
        from serenity.kernels.skyvolume import SkyVolumeConfig

        for name, kind, optional in (("shadow", ShadowConfig, False), ("ssao", SSAOConfig, False),
                                     ("sky_settings", SkyVolumeConfig, True), ("lpv_settings", LPVConfig, True)):
            value = getattr(self, name)
            if not (isinstance(value, kind) or (optional and value is None)):
                raise SerenityError(f"{name} must be a {kind.__name__}{' or None' if optional else ''}, "
                                    f"got {value!r} (e.g. ssao=SSAOConfig(enabled=False) to turn SSAO off)")


#: deepest kd-tree the build makes (the traversal's stack holds one entry per level)
KD_MAX_DEPTH = 62


@dataclass(frozen=True)
class KdBuildConfig:
    """The kd-tree's binned SAH build (paper §9; ``serenity/kernels/kdtree_build.py``). Every field is
    part of the tree's disk-cache key. Costs are relative units (only their ratio matters)."""

    traversal_cost: float = 2.0
    """C_trav: cost of one inner-node step, relative to ``intersection_cost``."""
    intersection_cost: float = 1.0
    """C_isect: cost of one ray–triangle test."""
    empty_bonus: float = 0.8
    """Fraction (0..1) of a split's cost removed when one side is empty (empty-space cut-off)."""
    min_empty_fraction: float = 0.0
    """The bonus applies only when the empty side is at least this fraction (0..1) of the node's extent."""
    bins: int = 32
    """SAH bins per axis per node, 4..64 (a node with fewer triangles gets fewer: the next power of 2)."""
    max_depth: int | None = None
    """Depth limit, 0..``KD_MAX_DEPTH``; None = 8 + 1.3·log2(N) for N triangles (pbrt's rule), capped."""

    def __post_init__(self):
        for name in ("traversal_cost", "intersection_cost"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SerenityError(f"KdBuildConfig.{name} must be a finite number > 0, got {value!r}")
        for name in ("empty_bonus", "min_empty_fraction"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and 0.0 <= value < 1.0):
                raise SerenityError(f"KdBuildConfig.{name} must be in [0, 1), got {value!r}")
        if not (isinstance(self.bins, int) and 4 <= self.bins <= 64):
            raise SerenityError(f"KdBuildConfig.bins must be an int in 4..64, got {self.bins!r}")
        if self.max_depth is not None and not (isinstance(self.max_depth, int) and 0 <= self.max_depth <= KD_MAX_DEPTH):
            raise SerenityError(f"KdBuildConfig.max_depth must be None or an int in 0..{KD_MAX_DEPTH}, "
                                f"got {self.max_depth!r}")

    def depth_limit(self, n: int) -> int:
        """The depth limit for a mesh of ``n`` triangles."""
        d = self.max_depth if self.max_depth is not None else int(round(8 + 1.3 * math.log2(max(n, 1))))
        return int(max(0, min(d, KD_MAX_DEPTH)))
