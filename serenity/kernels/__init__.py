"""Warp kernels: the compute half of Serenity. Never imports moderngl (see DESIGN.md §2)."""
