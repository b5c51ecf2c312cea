"""Stability cases: where each technique fails, measured against an exact answer or a reference.

Each ``*_case`` function sets up one known failure of one technique, renders or evaluates it with
the technique's mitigation off and on, and returns a :class:`Case`: the error of both against the
exact answer (the metric is named in ``metric``), the milliseconds each took, and small images for
the gallery (exact, without, with, and the error map). ``tests/stability/`` calls them at tiny
sizes and asserts bounds; ``benchmarks/bench_stability.py`` calls them at gallery sizes and writes
the PNG grid + JSON that docs/stability.md shows.

One module per technique, every name importable from here:

- :mod:`.harness`: the :class:`Case` record, :func:`format_error`, the timer and the brute-force
  sky irradiance the exact answers share;
- :mod:`.lpv`: light propagation volumes (thin wall, self-illumination, near field);
- :mod:`.sky_volume`: the sky irradiance volume (gathered probes at a thin wall, SH ringing,
  occlusion quads on terrain);
- :mod:`.shadows`: sun shadows (acne, peter-panning, contact leak, cascade seams, penumbra);
- :mod:`.ray_tracing`: refraction through glass, shadows of geometry seen in a mirror;
- :mod:`.horizon`: the sky and sun at the horizon (a sunset);
- :mod:`.frame_to_frame`: a moving sun and a moving camera on a small scene;
- :mod:`.temporal`: every quality preset frame to frame on the courtyard, and its tables.

Units: irradiance W·m⁻², radiance W·m⁻²·sr⁻¹, lengths m, angles degrees; images (H, W) float.
"""

from serenity.eval.stability.frame_to_frame import (
    camera_path_case,
    camera_path_sequence,
    sun_motion_case,
    sun_motion_sequence,
)
from serenity.eval.stability.harness import UP, Case, format_error
from serenity.eval.stability.horizon import horizon_case, horizon_scene, horizon_sweep
from serenity.eval.stability.lpv import (
    NEAR_FIELD_HALF,
    lpv_near_field,
    lpv_near_field_case,
    lpv_self_illumination,
    lpv_self_illumination_case,
    lpv_thin_wall,
    lpv_thin_wall_case,
    near_field_exact,
)
from serenity.eval.stability.ray_tracing import (
    GLASS_SLAB,
    glass_slab_case,
    glass_slab_rays,
    mirror_shadow_case,
    nested_glass_error,
)
from serenity.eval.stability.shadows import (
    cascade_seam_case,
    cascade_seams,
    contact_leak,
    contact_leak_case,
    exact_ground_visibility,
    penumbra,
    penumbra_case,
    peter_panning,
    peter_panning_case,
    render_sun_visibility,
    shadow_acne_case,
    shadow_scene,
)
from serenity.eval.stability.sky_volume import (
    gather_thin_wall,
    gather_thin_wall_case,
    sky_ringing,
    sky_ringing_case,
    terrain_sky_case,
    terrain_sky_points,
    terrain_sky_visibility,
)
from serenity.eval.stability.temporal import (
    CAMERA_STEP_M,
    DISPLAY_FLOOR,
    MEAN_STEP_BOUND,
    P99_STEP_BOUND,
    SUN_STEP_DEG,
    TEMPORAL_PRESETS,
    TEMPORAL_SWITCHES,
    camera_pan,
    display_luminance,
    frame_step,
    pan_camera,
    preset_config,
    reprojected,
    sun_sweep,
    switch_applies,
    temporal_breakdown_markdown,
    temporal_stability_markdown,
)

__all__ = [
    "CAMERA_STEP_M", "DISPLAY_FLOOR", "GLASS_SLAB", "MEAN_STEP_BOUND", "NEAR_FIELD_HALF", "P99_STEP_BOUND",
    "SUN_STEP_DEG", "TEMPORAL_PRESETS", "TEMPORAL_SWITCHES", "UP", "Case",
    "camera_pan", "camera_path_case", "camera_path_sequence", "cascade_seam_case", "cascade_seams", "contact_leak",
    "contact_leak_case", "display_luminance", "exact_ground_visibility", "format_error", "frame_step",
    "gather_thin_wall", "gather_thin_wall_case", "glass_slab_case", "glass_slab_rays", "horizon_case",
    "horizon_scene", "horizon_sweep", "lpv_near_field", "lpv_near_field_case", "lpv_self_illumination",
    "lpv_self_illumination_case", "lpv_thin_wall", "lpv_thin_wall_case", "mirror_shadow_case", "near_field_exact",
    "nested_glass_error", "pan_camera", "penumbra", "penumbra_case", "peter_panning", "peter_panning_case",
    "preset_config", "render_sun_visibility", "reprojected", "shadow_acne_case", "shadow_scene", "sky_ringing",
    "sky_ringing_case", "sun_motion_case", "sun_motion_sequence", "sun_sweep", "switch_applies",
    "temporal_breakdown_markdown", "temporal_stability_markdown", "terrain_sky_case", "terrain_sky_points",
    "terrain_sky_visibility",
]
