"""moderngl passes: the rasterised half of Serenity. Never imports a kernel module (docs/architecture.md, Layers)."""
