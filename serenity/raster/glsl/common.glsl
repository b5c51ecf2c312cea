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

// Fullscreen triangle from gl_VertexID: covers clip space with one triangle; uv in [0,1] on screen.
vec2 fullscreen_uv(int id) { return vec2((id << 1) & 2, id & 2); }
vec4 fullscreen_position(int id) { return vec4(fullscreen_uv(id) * 2.0 - 1.0, 0.0, 1.0); }

#endif
