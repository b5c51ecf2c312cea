// FXAA on the linear HDR frame, before the tone map (Lottes 2009, "FXAA", NVIDIA white paper; the
// compact 5-tap "FXAA 2 / console" form, with FXAA 3.11's local-contrast early exit).
//   luma(c)   = sqrt(Reinhard(exposure * luminance(c)))  (display-like: the edges a viewer sees)
//   skip      if lumaMax - lumaMin < max(u_edge_min, u_edge_rel * lumaMax)  (texture and flat areas)
//   dir       = the luma gradient of the 2x2 corner taps, turned 90 deg (along the edge),
//               normalised by its smaller component (+ a reduce term), clamped to u_span_max pixels
//   rgbA      = mean of 2 bilinear taps at +-1/6 of dir;  rgbB = (rgbA + 2 taps at +-1/2 of dir) / 2
//   out       = rgbB unless its luma leaves [lumaMin, lumaMax] (it crossed another edge), then rgbA
// Colours are blended after a Reinhard compression, c' = c / (1 + exposure * luminance(c)), and expanded
// back (the inverse-luminance weighting of HDR resolves, Karis 2014): a blend in raw linear radiance lets
// one sun-lit specular or sun-disc pixel (10^4-10^5 W m^-2 sr^-1) smear over its dark neighbours.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_hdr;     // bilinear, clamp to edge
uniform float u_exposure;
uniform float u_edge_min;    // absolute luma contrast below which nothing is done
uniform float u_edge_rel;    // ... and relative to the local maximum
uniform float u_span_max;    // longest blend, in pixels
out vec4 o_hdr;

float fxaa_luma(vec3 c) {
    float l = max(luminance(c), 0.0) * u_exposure;
    return sqrt(l / (1.0 + l));
}

vec3 tap(vec2 uv) {  // compressed: c / (1 + exposure * luminance(c))
    vec3 c = max(texture(u_hdr, uv).rgb, vec3(0.0));
    return c / (1.0 + u_exposure * luminance(c));
}

vec3 expand(vec3 c) { return c / max(1.0 - u_exposure * luminance(c), 1e-4); }

void main() {
    vec2 texel = 1.0 / vec2(textureSize(u_hdr, 0));
    vec3 rgbM = texture(u_hdr, v_uv).rgb;
    float lumaNW = fxaa_luma(texture(u_hdr, v_uv + vec2(-1.0, -1.0) * texel).rgb);
    float lumaNE = fxaa_luma(texture(u_hdr, v_uv + vec2(1.0, -1.0) * texel).rgb);
    float lumaSW = fxaa_luma(texture(u_hdr, v_uv + vec2(-1.0, 1.0) * texel).rgb);
    float lumaSE = fxaa_luma(texture(u_hdr, v_uv + vec2(1.0, 1.0) * texel).rgb);
    float lumaM = fxaa_luma(rgbM);
    float lumaMin = min(lumaM, min(min(lumaNW, lumaNE), min(lumaSW, lumaSE)));
    float lumaMax = max(lumaM, max(max(lumaNW, lumaNE), max(lumaSW, lumaSE)));
    if (lumaMax - lumaMin < max(u_edge_min, u_edge_rel * lumaMax)) {
        o_hdr = vec4(rgbM, 1.0);
        return;
    }
    vec2 dir = vec2(-((lumaNW + lumaNE) - (lumaSW + lumaSE)), (lumaNW + lumaSW) - (lumaNE + lumaSE));
    float reduce = max((lumaNW + lumaNE + lumaSW + lumaSE) * (0.25 / 8.0), 1.0 / 128.0);
    float rcpMin = 1.0 / (min(abs(dir.x), abs(dir.y)) + reduce);
    dir = clamp(dir * rcpMin, vec2(-u_span_max), vec2(u_span_max)) * texel;
    vec3 a = 0.5 * (tap(v_uv + dir * (1.0 / 3.0 - 0.5)) + tap(v_uv + dir * (2.0 / 3.0 - 0.5)));
    vec3 b = 0.5 * a + 0.25 * (tap(v_uv - 0.5 * dir) + tap(v_uv + 0.5 * dir));
    vec3 rgbA = expand(a);
    vec3 rgbB = expand(b);
    float lumaB = fxaa_luma(rgbB);
    o_hdr = vec4((lumaB < lumaMin || lumaB > lumaMax) ? rgbA : rgbB, 1.0);
}
#endif
