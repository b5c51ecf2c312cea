// Temporal hysteresis of the upsampled indirect light (raster/temporal.py, RenderConfig.
// indirect_history = a), at full resolution: each pixel's indirect light I = albedo * E + G,
// upsampled from the low-res passes as the deferred pass would (upsample.glsl), blended with the
// light the last frame showed at the same surface point,
//   I = a * I_now + (1 - a) * I_before,
// "before" bilinear over the 4 last-frame pixels around the point's place in the last frame's view,
// each taken only where it showed the point's surface: its view depth within what the surface's slope
// allows of the point's own depth in the last frame's camera (otherwise the point was hidden or beside
// an edge then, a disocclusion); the weights renormalised, and with under half of the weight left the
// pixel shows this frame's light. The low-res texels stand for G-buffer pixels that slide over the
// surfaces as the camera moves, and the upsampled light slid with them: a moving camera stepped the
// LPV's light by a few per cent a frame. The deferred pass then reads I (upsample.glsl, u_scale = 0).
//   out: rgb = I (W m^-2 sr^-1), a = the pixel's view depth (m; -1: background)
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "upsample.glsl"
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform sampler2D g_albedo;
uniform sampler2D u_prev_irr;       // the last frame's output (as o_irr below)
uniform mat4 u_prev_view_proj;      // the last frame's world -> clip
uniform vec3 u_prev_camera_pos;
uniform vec3 u_prev_camera_forward;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
uniform float u_alpha;              // weight of this frame's light (1: none of the last frame's)
uniform float u_pixel_angle;        // radians a pixel spans (vertically) at the view's centre
uniform bool u_has_prev;
layout(location = 0) out vec4 o_irr;

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 pos = texelFetch(g_position, px, 0);
    if (pos.w == 0.0) {
        o_irr = vec4(0.0, 0.0, 0.0, -1.0);
        return;
    }
    vec3 p = pos.xyz;
    vec3 nrm = texelFetch(g_normal, px, 0).xyz;
    vec3 n = normalize(nrm);
    float z = dot(p - u_camera_pos, u_camera_forward);
    vec3 irr = upsampled_indirect(px, z, nrm, texelFetch(g_albedo, px, 0).rgb);
    o_irr = vec4(irr, z);
    if (!u_has_prev || u_alpha >= 1.0) return;
    vec2 size = vec2(textureSize(g_position, 0));
    vec4 c = u_prev_view_proj * vec4(p, 1.0);
    if (c.w <= 1e-6) return;
    vec2 q = (c.xy / c.w * 0.5 + 0.5) * size - 0.5;  // its pixel then (integers at pixel centres)
    q = mix(q, floor(q + 0.5), lessThan(abs(q - floor(q + 0.5)), vec2(1e-3)));  // a still view: that pixel
    ivec2 i0 = ivec2(floor(q));
    vec2 f = q - vec2(i0);
    vec3 v = p - u_prev_camera_pos;
    float zp = dot(v, u_prev_camera_forward);  // the point's depth in the last frame's camera
    // how far the surface's depth may move over one pixel there: the pixel's footprint over the cosine
    // of the angle between the surface and the view ray, with 2 % of the depth for the rest
    float cosv = max(abs(dot(n, normalize(v))), 0.05);
    float tol = zp * (0.02 + 1.5 * u_pixel_angle * sqrt(max(1.0 - cosv * cosv, 0.0)) / cosv);
    vec3 bi = vec3(0.0);
    float wsum = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 t = i0 + o;
        if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, ivec2(size)))) continue;
        vec4 a = texelFetch(u_prev_irr, t, 0);
        if (a.w < 0.0 || abs(a.w - zp) > tol) continue;  // not this surface then
        float w = bilinear_weight(o, f);
        bi += w * a.rgb;
        wsum += w;
    }
    if (wsum < 0.5) return;
    bi /= wsum;
    o_irr.rgb = bi + u_alpha * (irr - bi);  // exactly the light itself when it did not change
}
#endif
