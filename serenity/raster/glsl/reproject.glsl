// Reprojection into the last frame's view, shared by the indirect light's history
// (indirect_history.glsl: q, zp and tol, and one bilinear fetch instead of the taps below) and the
// temporal anti-aliasing (taa.glsl). A last-frame image stores rgb and the view depth of the surface
// each pixel showed (a; < 0: no surface, the sky).
//   q   = surface point p projected with the last frame's world -> clip (integers at pixel centres),
//         plus ``shift`` pixels (TAA: this frame's jitter, so that q is the pixel centre's, not the
//         jittered sample's), snapped to the pixel within 1e-3 of one (a still view)
//   zp  = p's depth in the last frame's camera
//   tol = how far the surface's depth may move over one pixel there: the pixel's footprint over the
//         cosine of the angle between the surface (unit normal n) and the view ray, with 2 % of the
//         depth for the rest
// The 4 last-frame pixels around q are taken, bilinearly weighted, where their depth lies within tol
// of zp (elsewhere p was hidden or beside an edge then: a disocclusion), and where they lie in the image.
#ifndef SERENITY_REPROJECT_GLSL
#define SERENITY_REPROJECT_GLSL
#include "lowres.glsl"

// The last frame's pixel coordinate q (integers at pixel centres) of its clip position c, plus
// ``shift`` pixels; false (q far outside) where c lies behind its camera.
bool prev_pixel(vec4 c, vec2 size, vec2 shift, out vec2 q) {
    q = vec2(-1e9);
    if (c.w <= 1e-6) return false;
    q = (c.xy / c.w * 0.5 + 0.5) * size - 0.5 + shift;
    return true;
}

// Sum of weight * rgb (xyz) and of the weights (w) of the 4 last-frame pixels around q, bilinearly
// weighted, that lie in the image and showed the sky (``sky``) or else a surface at a view depth
// within tol of zp.
vec4 prev_taps(sampler2D prev, vec2 q, bool sky, float zp, float tol) {
    ivec2 size = textureSize(prev, 0);
    ivec2 i0 = ivec2(floor(q));
    vec2 f = q - vec2(i0);
    vec4 sum = vec4(0.0);
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 t = i0 + o;
        if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, size))) continue;
        vec4 a = texelFetch(prev, t, 0);
        if (sky ? a.w >= 0.0 : (a.w < 0.0 || abs(a.w - zp) > tol)) continue;  // not what p showed then
        float w = bilinear_weight(o, f);
        sum += vec4(w * a.rgb, w);
    }
    return sum;
}

// q snapped to the pixel within 1e-3 of one: a still view reads that pixel alone.
vec2 snap_still(vec2 q) { return mix(q, floor(q + 0.5), lessThan(abs(q - floor(q + 0.5)), vec2(1e-3))); }

// zp and tol (above) of surface point p (unit normal n).
void reproject_depth(vec3 p, vec3 n, vec3 prev_camera_pos, vec3 prev_camera_forward, float pixel_angle,
                     out float zp, out float tol) {
    vec3 v = p - prev_camera_pos;
    zp = dot(v, prev_camera_forward);
    float cosv = max(abs(dot(n, normalize(v))), 0.05);
    tol = zp * (0.02 + 1.5 * pixel_angle * sqrt(max(1.0 - cosv * cosv, 0.0)) / cosv);
}

// Sum of the taps' weight * rgb (xyz) and of their weights (w); q (the last frame's pixel coordinate)
// returned, for a caller that filters the last frame otherwise where every tap is taken.
vec4 reproject_bilinear(sampler2D prev, mat4 prev_view_proj, vec3 prev_camera_pos, vec3 prev_camera_forward,
                        float pixel_angle, vec3 p, vec3 n, vec2 shift, out vec2 q) {
    if (!prev_pixel(prev_view_proj * vec4(p, 1.0), vec2(textureSize(prev, 0)), shift, q)) return vec4(0.0);
    q = snap_still(q);
    float zp, tol;
    reproject_depth(p, n, prev_camera_pos, prev_camera_forward, pixel_angle, zp, tol);
    return prev_taps(prev, q, false, zp, tol);
}
#endif
