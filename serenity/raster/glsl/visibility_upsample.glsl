// The sun's visibility at reduced resolution (ShadowConfig.visibility_scale > 1): deferred.glsl with
// VIS_PASS computes it — the cascaded shadow maps' filter (PCSS) and the contact march, the costly
// part of the lighting pass — once per u_vis_scale x u_vis_scale block of pixels, at the block's
// representative G-buffer pixel (lowres.glsl), and deferred.glsl with VIS_UPSAMPLE reads it back per
// pixel by joint bilateral upsampling, weighted as the indirect light's (upsample.glsl):
//   V = sum_i w_i V_i / sum_i w_i over the 2x2 low-res texels around the pixel,
//   w_i = bilinear_i * guide_similarity(n_i, z_i, n, z)
// (the most similar texel when every weight vanishes). Each texel carries its own guide, so a tap is
// one fetch: xy = the representative's unit normal, octahedral-encoded; z = its view depth (-1:
// background); w = the visibility, 0..1 (0 where the surface faces away from the sun).
#ifndef SERENITY_VISIBILITY_UPSAMPLE_GLSL
#define SERENITY_VISIBILITY_UPSAMPLE_GLSL
#include "lowres.glsl"
uniform int u_vis_scale;     // full-resolution pixels per visibility texel, per axis

// Octahedral encoding of a unit vector (Meyer et al. 2010): the octahedron |x|+|y|+|z| = 1 unfolded
// onto [-1, 1]^2, its lower half folded over the diagonals.
vec2 sign_not_zero(vec2 v) { return vec2(v.x >= 0.0 ? 1.0 : -1.0, v.y >= 0.0 ? 1.0 : -1.0); }
vec2 oct_encode(vec3 n) {
    vec2 e = n.xy / (abs(n.x) + abs(n.y) + abs(n.z));
    return n.z >= 0.0 ? e : (1.0 - abs(e.yx)) * sign_not_zero(e);
}
vec3 oct_decode(vec2 e) {
    vec3 v = vec3(e, 1.0 - abs(e.x) - abs(e.y));
    if (v.z < 0.0) v.xy = (1.0 - abs(v.yx)) * sign_not_zero(v.xy);
    return normalize(v);
}

#if VIS_UPSAMPLE
uniform sampler2D u_vis;     // the VIS_PASS target

// visibility at full-resolution pixel px (view depth z, unit normal n)
float upsampled_visibility(ivec2 px, float z, vec3 n) {
    ivec2 low_max = textureSize(u_vis, 0) - 1;
    vec2 t = (vec2(px) - float(u_vis_scale / 2)) / float(u_vis_scale);
    ivec2 i0 = ivec2(floor(t));
    vec2 f = t - vec2(i0);
    float vis = 0.0, wsum = 0.0, best = -1.0, best_vis = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        vec4 g = texelFetch(u_vis, clamp(i0 + o, ivec2(0), low_max), 0);
        float bil = (o.x == 1 ? f.x : 1.0 - f.x) * (o.y == 1 ? f.y : 1.0 - f.y);
        float sim = guide_similarity(oct_decode(g.xy), g.z, n, z);
        float w = (bil + 1e-3) * sim;
        vis += w * g.w;
        wsum += w;
        if (sim > best) { best = sim; best_vis = g.w; }
    }
    return wsum > 1e-6 ? vis / wsum : best_vis;
}
#endif
#endif
