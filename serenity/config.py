"""Frozen render settings. Units are stated on each attribute; defaults are the paper's where it
gives them. Later features add their own config classes here (SkyConfig, LPVConfig, ...)."""

from __future__ import annotations

from dataclasses import dataclass, field

from serenity.errors import SerenityError


@dataclass(frozen=True)
class ShadowConfig:
    size: int = 2048
    """Shadow map resolution (texels per side)."""
    bias: float = 1.5
    """Constant depth bias, in shadow-map texels (converted to depth units in the shader)."""
    normal_offset: float = 1.0
    """Normal offset of the lookup point, in shadow-map texels, scaled by the slope (clamped 1–4)."""


@dataclass(frozen=True)
class RenderConfig:
    exposure: float = 0.02
    """Multiplier applied to radiance (W·m⁻²·sr⁻¹) before Reinhard; 0.02 maps a white wall in
    noon sun (≈300) to about 0.86 display luminance."""
    ambient: str = "none"
    """Indirect term while the GI techniques are absent: "none", or "constant" (the classic flat
    ambient hack, irradiance π·L_sky on every surface — the baseline the GI must beat)."""
    shadow: ShadowConfig = field(default_factory=ShadowConfig)
    sync_stages: bool = True
    """Wait for the GL queue after each stage so per-stage wall times are exact (costs overlap)."""

    def __post_init__(self):
        if not (self.exposure > 0):
            raise SerenityError(f"exposure must be positive, got {self.exposure}")
        if self.ambient not in ("none", "constant"):
            raise SerenityError(f"ambient must be 'none' or 'constant', got {self.ambient!r}")
        if self.shadow.size < 16 or self.shadow.size > 16384:
            raise SerenityError(f"shadow map size must be in 16..16384, got {self.shadow.size}")
