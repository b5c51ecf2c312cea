// Shared GLSL: constants and colour helpers. Included by every pass.
#ifndef SERENITY_COMMON_GLSL
#define SERENITY_COMMON_GLSL

const float PI = 3.14159265358979323846;

// Rec. 709 / sRGB primaries luminance.
float luminance(vec3 c) { return dot(c, vec3(0.2126, 0.7152, 0.0722)); }

// IEC 61966-2-1 sRGB encoding of a linear value in [0, 1].
vec3 linear_to_srgb(vec3 c) {
    c = clamp(c, 0.0, 1.0);
    vec3 lo = 12.92 * c;
    vec3 hi = 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055;
    return mix(lo, hi, step(vec3(0.0031308), c));
}

#ifdef EXACT_FILTER
// Trilinear interpolation of a 3-D texture with float weights, by texelFetch (raster/context.py
// EXACT_FILTER: a GPU's texture unit weights texels with 8-bit fractions): the corner texels i0 and
// i1 (already clamped to the texture) weighted 1 - w and w per axis.
vec4 trilinear_texels(sampler3D t, ivec3 i0, ivec3 i1, vec3 w) {
    vec4 c00 = mix(texelFetch(t, i0, 0), texelFetch(t, ivec3(i1.x, i0.y, i0.z), 0), w.x);
    vec4 c10 = mix(texelFetch(t, ivec3(i0.x, i1.y, i0.z), 0), texelFetch(t, ivec3(i1.x, i1.y, i0.z), 0), w.x);
    vec4 c01 = mix(texelFetch(t, ivec3(i0.x, i0.y, i1.z), 0), texelFetch(t, ivec3(i1.x, i0.y, i1.z), 0), w.x);
    vec4 c11 = mix(texelFetch(t, ivec3(i0.x, i1.y, i1.z), 0), texelFetch(t, i1, 0), w.x);
    return mix(mix(c00, c10, w.y), mix(c01, c11, w.y), w.z);
}
#endif

// Fullscreen triangle from gl_VertexID: covers clip space with one triangle; uv in [0,1] on screen.
vec2 fullscreen_uv(int id) { return vec2((id << 1) & 2, id & 2); }
vec4 fullscreen_position(int id) { return vec4(fullscreen_uv(id) * 2.0 - 1.0, 0.0, 1.0); }

#endif
