"""moderngl passes: the rasterised half of Serenity. Never imports a kernel module (DESIGN.md §2)."""
