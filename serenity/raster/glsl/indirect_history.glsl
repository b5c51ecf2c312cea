// Temporal hysteresis of the upsampled indirect light (raster/temporal.py, IndirectConfig.history = a),
// included by the deferred pass (deferred.glsl, UPSAMPLE 2): each pixel's indirect light
// I = albedo * E + G, as upsampled from the low-res passes (upsample.glsl), blended with the light the
// last frame showed at the same surface point,
//   I = a * I_now + (1 - a) * I_before,
// "before" one bilinear fetch (the texture's own filter) of the last frame's I and view depth at the
// point's place in the last frame's view (reproject.glsl), taken only where that filtered depth lies
// within tol of the point's: a tap on another surface or on the sky (depth -1) pulls it away, and then
// (the point hidden or beside an edge then, a disocclusion) the pixel shows this frame's light. One
// fetch, where 4 taps each tested on their own cost 2.5 times as much per pixel.
// The low-res texels stand for G-buffer pixels that slide over the surfaces as the camera moves, and
// the upsampled light slid with them: a moving camera stepped the LPV's light by a few per cent a frame.
// The deferred pass writes I and the pixel's view depth (rgb, a; a = -1 where it shows the sky: the
// target is cleared so) for the next frame to read.
uniform sampler2D u_prev_irr;       // the last frame's I (rgb) and view depth (a), filtered bilinearly
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
    vec2 size = vec2(textureSize(u_prev_irr, 0));
    vec2 q;
    if (!prev_pixel(u_prev_view_proj * vec4(p, 1.0), size, vec2(0.0), q)) return irr;
    if (any(lessThan(q, vec2(-0.5))) || any(greaterThan(q, size - 0.5))) return irr;  // outside the last view
    float zp, tol;
    reproject_depth(p, n, u_prev_camera_pos, u_prev_camera_forward, u_pixel_angle, zp, tol);
    // a still view: its pixel's centre, read by the nearest texel (IndirectHistory.set_uniforms)
    vec4 before = texture(u_prev_irr, (snap_still(q) + 0.5) / size);
    if (abs(before.w - zp) > tol) return irr;
    return before.rgb + u_history_alpha * (irr - before.rgb);  // exactly the light itself when it did not change
}
