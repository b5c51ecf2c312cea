// Reduced-resolution passes (SSAO, indirect light at 1/u_scale of the view per axis): each low-res
// pixel stands for the full-resolution G-buffer pixel at the centre of its u_scale x u_scale block
// (its "representative"), read with texelFetch, so the low-res result belongs to one real surface
// point; the joint bilateral upsampling (upsample.glsl) weighs low-res pixels by how close their
// representatives are in depth and normal to the pixel it fills. u_scale = 1: the pixel itself.
#ifndef SERENITY_LOWRES_GLSL
#define SERENITY_LOWRES_GLSL
uniform int u_scale;

ivec2 representative_pixel(ivec2 low, ivec2 full_size) {
    return min(low * u_scale + ivec2(u_scale / 2), full_size - 1);
}
#endif
