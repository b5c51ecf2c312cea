// Reduced-resolution passes (SSAO, indirect light at 1/u_scale of the view per axis): each low-res
// pixel stands for the full-resolution G-buffer pixel at the centre of its u_scale x u_scale block
// (its "representative"), read with texelFetch, so the low-res result belongs to one real surface
// point; the joint bilateral upsampling (upsample.glsl) weighs low-res pixels by how close their
// representatives are in depth and normal to the pixel it fills. u_scale = 1: the pixel itself.
#ifndef SERENITY_LOWRES_GLSL
#define SERENITY_LOWRES_GLSL
uniform int u_scale;
// Where the low-res image lies in its targets (raster/context.LowResLayout): texel (0, 0) of the
// image is target texel u_lowres_origin, and the image is u_lowres_size texels; the targets are
// padded so that the image straddles llvmpipe's 64-pixel tiles evenly (an 80-texel row in one
// 64-texel tile and one 16-texel tile left one of two rasteriser threads with 4/5 of the pass).
uniform ivec2 u_lowres_origin;
uniform ivec2 u_lowres_size;
#if defined FRAGMENT_SHADER
// In a low-res pass drawn into the padded targets: the image texel being shaded.
ivec2 lowres_pixel() { return ivec2(gl_FragCoord.xy) - u_lowres_origin; }
#endif
// The target texel of image texel i, clamped to the image (as clamp-to-edge would an unpadded one).
ivec2 lowres_texel(ivec2 i) { return clamp(i, ivec2(0), u_lowres_size - 1) + u_lowres_origin; }

// The glossy LPV light is looked up only where the specular lobe is strong enough to show it (the
// march costs glossy_steps x 3 cascades x 3 fetches per pixel; k_s = 0.05 plaster gains < 1 %).
const float GLOSSY_MIN_SPECULAR = 0.1;
// The low-res guide pass writes each texel's class as its depth (lowres_guide.glsl), and the low-res
// passes draw at a depth that passes only the classes they shade (depth test >, IndirectPass):
// llvmpipe shades no pixel the depth test rejects, where a per-pixel branch saves nothing.
const float LOWRES_DEPTH_GLOSSY = 0.25;      // a surface whose k_s >= GLOSSY_MIN_SPECULAR
const float LOWRES_DEPTH_SURFACE = 0.5;      // any other surface
const float LOWRES_DEPTH_BACKGROUND = 1.0;   // no surface (the clear value)

ivec2 representative_pixel_at(ivec2 low, ivec2 full_size, int scale) {
    return min(low * scale + ivec2(scale / 2), full_size - 1);
}
ivec2 representative_pixel(ivec2 low, ivec2 full_size) { return representative_pixel_at(low, full_size, u_scale); }

// The 2x2 low-res texels whose representatives surround full-resolution pixel px (1/scale per axis):
// the first one, i0, and px's bilinear fractions f between them; bilinear_weight: texel i0 + o's share.
void lowres_footprint(ivec2 px, int scale, out ivec2 i0, out vec2 f) {
    vec2 t = (vec2(px) - float(scale / 2)) / float(scale);  // integers at the representatives
    i0 = ivec2(floor(t));
    f = t - vec2(i0);
}
float bilinear_weight(ivec2 o, vec2 f) { return (o.x == 1 ? f.x : 1.0 - f.x) * (o.y == 1 ? f.y : 1.0 - f.y); }

// Joint bilateral upsampling (upsample.glsl, visibility_upsample.glsl): how alike a low-res texel's
// representative (normal gn, view depth gz; gz < 0: background) is to the pixel being filled (n, z):
// exp(-|gz - z| / (0.05 z)) * max(0, gn . n)^8 — ~0 across a silhouette or a crease.
float guide_similarity(vec3 gn, float gz, vec3 n, float z) {
    float c = max(dot(gn, n), 0.0);
    c *= c; c *= c; c *= c;  // ^8
    return gz < 0.0 ? 0.0 : exp(-abs(gz - z) / (0.05 * z + 1e-3)) * c;
}

// The highest guide_similarity among the 2x2 low-res texels the upsampling (upsample.glsl) draws
// full-resolution pixel px (view depth z, normal n) from: ~0 where no texel stands for px's surface
// (a strip thinner than the low-res grid, the far side of a silhouette or a crease).
float lowres_best_similarity(sampler2D guide, ivec2 px, float z, vec3 n) {
    ivec2 i0;
    vec2 f;
    lowres_footprint(px, u_scale, i0, f);
    float best = 0.0;
    for (int k = 0; k < 4; ++k) {
        vec4 g = texelFetch(guide, lowres_texel(i0 + ivec2(k & 1, k >> 1)), 0);
        best = max(best, guide_similarity(g.xyz, g.w, n, z));
    }
    return best;
}
#endif
