// Temporal hysteresis of the upsampled indirect light (raster/temporal.py, RenderConfig.
// indirect_history = a), at full resolution: each pixel's indirect light, upsampled from the low-res
// passes as the deferred pass would (upsample.glsl), blended with the light the last frame showed at
// the same surface point,
//   E = a * E_now + (1 - a) * E_before   (and the glossy light G alike),
// "before" bilinear over the 4 last-frame pixels around the point's place in the last frame's view,
// each taken only where it showed the point's surface (within u_tolerance m of the point's tangent
// plane; otherwise the point was hidden or beside an edge then: a disocclusion) and the weights
// renormalised; with under half of the weight left the pixel shows this frame's light. The low-res
// texels stand for G-buffer pixels that slide over the surfaces as the camera moves, and the
// upsampled light slid with them: a moving camera stepped the LPV's light by a few per cent a frame.
// The deferred pass then reads these targets at u_scale = 1 with this pass's guide.
//   out irr: rgb = E/pi * AO (per unit albedo), a = the pixel's view depth (m; -1: background)
//   out gloss: rgb = G;  out guide: xyz = the G-buffer normal, w = the view depth (-1: background)
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "upsample.glsl"
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform sampler2D u_prev_irr;       // the last frame's output (as o_irr below)
uniform sampler2D u_prev_gloss;
uniform mat4 u_prev_view_proj;      // the last frame's world -> clip
uniform mat4 u_prev_inv_view_proj;
uniform vec3 u_prev_camera_pos;
uniform vec3 u_prev_camera_forward;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
uniform float u_alpha;              // weight of this frame's light (1: none of the last frame's)
uniform float u_tolerance;          // metres off the tangent plane a last-frame pixel may lie
uniform bool u_has_prev;
layout(location = 0) out vec4 o_irr;
layout(location = 1) out vec4 o_gloss;
layout(location = 2) out vec4 o_guide;

// The world point of last frame's pixel q (GL convention) at view depth z.
vec3 prev_point(vec2 q, float z, vec2 size) {
    vec2 ndc = (q + 0.5) / size * 2.0 - 1.0;
    vec4 far = u_prev_inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 d = far.xyz / far.w - u_prev_camera_pos;
    return u_prev_camera_pos + d * (z / dot(d, u_prev_camera_forward));
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 pos = texelFetch(g_position, px, 0);
    if (pos.w == 0.0) {
        o_irr = vec4(0.0, 0.0, 0.0, -1.0);
        o_gloss = vec4(0.0);
        o_guide = vec4(0.0, 0.0, 0.0, -1.0);
        return;
    }
    vec3 p = pos.xyz;
    vec3 nrm = texelFetch(g_normal, px, 0).xyz;
    vec3 n = normalize(nrm);
    float z = dot(p - u_camera_pos, u_camera_forward);
    vec3 irr, gloss;
    upsampled_terms(px, z, nrm, irr, gloss);
    o_guide = vec4(nrm, z);
    o_irr = vec4(irr, z);
    o_gloss = vec4(gloss, 0.0);
    if (!u_has_prev || u_alpha >= 1.0) return;
    vec2 size = vec2(textureSize(g_position, 0));
    vec4 c = u_prev_view_proj * vec4(p, 1.0);
    if (c.w <= 1e-6) return;
    vec2 q = (c.xy / c.w * 0.5 + 0.5) * size - 0.5;  // its pixel then (integers at pixel centres)
    q = mix(q, floor(q + 0.5), lessThan(abs(q - floor(q + 0.5)), vec2(1e-3)));  // a still view: that pixel
    ivec2 i0 = ivec2(floor(q));
    vec2 f = q - vec2(i0);
    vec3 bi = vec3(0.0), bg = vec3(0.0);
    float wsum = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 t = i0 + o;
        if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, ivec2(size)))) continue;
        vec4 a = texelFetch(u_prev_irr, t, 0);
        if (a.w < 0.0) continue;
        if (abs(dot(prev_point(vec2(t), a.w, size) - p, n)) > u_tolerance) continue;  // not this surface then
        float w = bilinear_weight(o, f);
        bi += w * a.rgb;
        bg += w * texelFetch(u_prev_gloss, t, 0).rgb;
        wsum += w;
    }
    if (wsum < 0.5) return;
    bi /= wsum;
    bg /= wsum;
    o_irr.rgb = bi + u_alpha * (irr - bi);  // exactly the light itself when it did not change
    o_gloss.rgb = bg + u_alpha * (gloss - bg);
}
#endif
