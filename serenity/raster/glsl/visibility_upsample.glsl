// The sun's visibility sampled sparsely (ShadowConfig.visibility): deferred.glsl with VIS_PASS
// computes it — the cascaded shadow maps' filter (PCSS) and the contact march, the costly part of the
// lighting pass — at some of the pixels only, in a pass of its own, and deferred.glsl with
// VIS_UPSAMPLE reads it back for every pixel, weighting the samples it reads as the indirect light's
// upsampling does (guide_similarity, lowres.glsl: ~0 across a silhouette or a crease; the most similar
// sample when every weight vanishes):
//   VIS_CHECKERBOARD: the pixels with x + y even, stored (x / 2, y) in a texture of half the width.
//     Such a pixel reads its own value; any other, the weighted mean of its 4 neighbours (left, right,
//     below, above: all samples). Every row and every column keeps half its pixels, so a shadow one
//     pixel thin, horizontal or vertical, is still sampled.
//   VIS_HALF: one sample per 2 x 2 block, at the block's representative pixel (lowres.glsl), read back
//     bilinearly from the 2 x 2 samples around the pixel: 1/4 of the pixels, but a shadow thinner than
//     two pixels can fall between the samples and come out lit.
// Each sample carries its own guide, so a tap is one fetch: xy = the sampled pixel's unit normal,
// octahedral-encoded; z = its view depth (-1: background); w = the visibility, 0..1 (0 where the
// surface faces away from the sun).
#ifndef SERENITY_VISIBILITY_UPSAMPLE_GLSL
#define SERENITY_VISIBILITY_UPSAMPLE_GLSL
#include "lowres.glsl"
#define VIS_CHECKERBOARD 1
#define VIS_HALF 2
// the visibility pass's step 1 writes this depth where step 2 is to shade (surfaces facing the sun),
// 1 elsewhere; step 2 draws at window depth 0.75 (deferred.glsl) with the depth test >, so llvmpipe
// shades neither the background nor the surfaces facing away, whatever the block
const float VIS_SHADE_DEPTH = 0.5;

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

// the full-resolution pixel that visibility texel q samples
ivec2 visibility_sample_pixel(int mode, ivec2 q, ivec2 full_size) {
    if (mode == VIS_CHECKERBOARD) return min(ivec2(2 * q.x + (q.y & 1), q.y), full_size - 1);
    return representative_pixel_at(q, full_size, 2);
}

#if VIS_UPSAMPLE
uniform sampler2D u_vis;     // the VIS_PASS target

// visibility at full-resolution pixel px (view depth z, unit normal n)
float upsampled_visibility(ivec2 px, float z, vec3 n) {
    ivec2 low_max = textureSize(u_vis, 0) - 1;
    float vis = 0.0, wsum = 0.0, best = -1.0, best_vis = 0.0;
#if VIS_UPSAMPLE == VIS_CHECKERBOARD
    vec4 own = texelFetch(u_vis, ivec2(px.x >> 1, px.y), 0);
    if (((px.x + px.y) & 1) == 0) return own.w;  // a sampled pixel
    for (int k = 0; k < 4; ++k) {
        ivec2 o = k == 0 ? ivec2(-1, 0) : k == 1 ? ivec2(1, 0) : k == 2 ? ivec2(0, -1) : ivec2(0, 1);
        ivec2 q = px + o;
        vec4 g = texelFetch(u_vis, clamp(ivec2(q.x >> 1, q.y), ivec2(0), low_max), 0);
        float sim = guide_similarity(oct_decode(g.xy), g.z, n, z);
        vis += sim * g.w;
        wsum += sim;
        if (sim > best) { best = sim; best_vis = g.w; }
    }
#else
    ivec2 i0;
    vec2 f;
    lowres_footprint(px, 2, i0, f);
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        vec4 g = texelFetch(u_vis, clamp(i0 + o, ivec2(0), low_max), 0);
        float bil = bilinear_weight(o, f);
        float sim = guide_similarity(oct_decode(g.xy), g.z, n, z);
        float w = (bil + 1e-3) * sim;
        vis += w * g.w;
        wsum += w;
        if (sim > best) { best = sim; best_vis = g.w; }
    }
#endif
    return wsum > 1e-6 ? vis / wsum : best_vis;
}
#endif
#endif
