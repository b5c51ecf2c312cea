// Joint bilateral upsampling of the low-resolution indirect light (indirect.glsl with LOWRES), done
// inside the deferred pass (deferred.glsl with UPSAMPLE; one full-resolution pass instead of a
// second one that re-read the G-buffer and blended onto the lit image):
//   L = albedo * E_lo + G_lo,   E_lo, G_lo = sum_i w_i X_i / sum_i w_i over the 2x2 low-res texels
//   around the pixel, w_i = bilinear_i * exp(-|z_i - z| / (0.05 z)) * max(0, n_i . n)^8
//   (guide_similarity in lowres.glsl)
// where z, n are the pixel's view depth and normal and z_i, n_i those of texel i's representative
// G-buffer pixel (lowres.glsl), read from the low-res guide (lowres_guide.glsl). Across a silhouette
// or a crease the texels of the other surface get ~no weight; when every weight vanishes (a pixel
// unlike all four) the most similar texel is used.
// UPSAMPLE_REFINE 1: the pixels that no texel stands for (lowres_best_similarity below
// IndirectConfig.refine_below, marked by upsample_refine.glsl) have their light computed at
// full resolution instead (raster/lowres.IndirectRefinement), read here where alpha marks them.
#ifndef SERENITY_UPSAMPLE_GLSL
#define SERENITY_UPSAMPLE_GLSL
#ifndef UPSAMPLE_REFINE
#define UPSAMPLE_REFINE 0
#endif
#include "lowres.glsl"
uniform sampler2D u_irr;     // E/pi * AO (W m^-2 sr^-1 per unit albedo)
uniform sampler2D u_gloss;   // k_s * glossy * AO (W m^-2 sr^-1)
uniform sampler2D u_guide;   // per low-res texel: xyz = normal, w = view depth (-1: background)
#if UPSAMPLE_REFINE
uniform sampler2D u_refine_irr;    // full resolution: as u_irr, alpha 1 where refined
uniform sampler2D u_refine_gloss;  // full resolution: as u_gloss
#endif

// albedo * E + G at full-resolution pixel px (view depth z, G-buffer normal n)
vec3 upsampled_indirect(ivec2 px, float z, vec3 n, vec3 albedo) {
#if UPSAMPLE_REFINE
    vec4 refined = texelFetch(u_refine_irr, px, 0);
    if (refined.a > 0.5) return albedo * refined.rgb + texelFetch(u_refine_gloss, px, 0).rgb;
#endif
    ivec2 i0;
    vec2 f;
    lowres_footprint(px, u_scale, i0, f);
    vec3 irr = vec3(0.0), gloss = vec3(0.0);
    float wsum = 0.0, best = -1.0;
    vec3 best_irr = vec3(0.0), best_gloss = vec3(0.0);
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 q = lowres_texel(i0 + o);
        vec4 g = texelFetch(u_guide, q, 0);
        float bil = bilinear_weight(o, f);
        float sim = guide_similarity(g.xyz, g.w, n, z);
        float w = (bil + 1e-3) * sim;
        vec3 xi = texelFetch(u_irr, q, 0).rgb, xg = texelFetch(u_gloss, q, 0).rgb;
        irr += w * xi; gloss += w * xg; wsum += w;
        if (sim > best) { best = sim; best_irr = xi; best_gloss = xg; }
    }
    if (wsum > 1e-6) { irr /= wsum; gloss /= wsum; } else { irr = best_irr; gloss = best_gloss; }
    return albedo * irr + gloss;
}
#endif
