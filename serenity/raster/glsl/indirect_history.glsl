// Temporal hysteresis of the upsampled indirect light (raster/temporal.py, RenderConfig.
// indirect_history = a), included by the deferred pass (deferred.glsl, UPSAMPLE 2): each pixel's
// indirect light I = albedo * E + G, as upsampled from the low-res passes (upsample.glsl), blended
// with the light the last frame showed at the same surface point,
//   I = a * I_now + (1 - a) * I_before,
// "before" bilinear over the 4 last-frame pixels around the point's place in the last frame's view,
// each taken only where it showed the point's surface (reproject.glsl: otherwise the point was hidden
// or beside an edge then, a disocclusion); the weights renormalised, and with under half of the weight
// left the pixel shows this frame's light. The low-res texels stand for G-buffer pixels that slide
// over the surfaces as the camera moves, and the upsampled light slid with them: a moving camera
// stepped the LPV's light by a few per cent a frame. The deferred pass writes I and the pixel's view depth
// (rgb, a; a = -1 where it shows the sky: the target is cleared so) for the next frame to read.
uniform sampler2D u_prev_irr;       // the last frame's I (rgb) and view depth (a)
uniform mat4 u_prev_view_proj;      // the last frame's world -> clip
uniform vec3 u_prev_camera_pos;
uniform vec3 u_prev_camera_forward;
uniform float u_history_alpha;      // weight of this frame's light (1: none of the last frame's)
uniform float u_pixel_angle;        // radians a pixel spans (vertically) at the view's centre
uniform bool u_has_prev;

#include "reproject.glsl"

// I at surface point p (unit normal n) from this frame's upsampled light ``irr``
vec3 history_blend(vec3 p, vec3 n, vec3 irr) {
    if (!u_has_prev || u_history_alpha >= 1.0) return irr;
    vec2 q;
    vec4 sum = reproject_bilinear(u_prev_irr, u_prev_view_proj, u_prev_camera_pos, u_prev_camera_forward,
                                  u_pixel_angle, p, n, vec2(0.0), q);
    if (sum.w < 0.5) return irr;
    vec3 bi = sum.rgb / sum.w;
    return bi + u_history_alpha * (irr - bi);  // exactly the light itself when it did not change
}
