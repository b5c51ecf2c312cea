"""The G-buffer's layout, shared by the GL passes (``raster/``) and the CPU ray tracer
(``kernels/raytrace.py``), which may not import each other.

Every target is RGBA per pixel (``raster/glsl/gbuffer.glsl``): albedo.rgb (linear); normal.xyz
(world, unit) + specular k_s in w; position.xyz (world, m) + coverage in w (1 = surface, 0 = sky);
material = (shininess, reflectivity, transparency, ior). The ray tracer's G-buffers add, per ray,
ray_dir.xyz and eye.xyz: the direction and origin of the ray's last segment (0 = not traced).
"""

from __future__ import annotations

GBUFFER_TARGETS = ("albedo", "normal", "position", "material")
"""The rasterised G-buffer's colour targets, in attachment order."""
RT_GBUFFER_KEYS = (*GBUFFER_TARGETS, "ray_dir", "eye")
"""The arrays of a ray-traced G-buffer, in the order ``trace_gbuffer`` writes them."""
