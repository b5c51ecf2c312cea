"""Warp kernels: the compute half of Serenity. Never imports moderngl nor raster/ (docs/architecture.md, Layers)."""
