// Exposure, Reinhard (2002) global operator on luminance, sRGB encoding.
//   Lw = luminance(exposure * hdr);  Ld = Lw / (1 + Lw);  ldr = srgb(exposure * hdr * Ld / Lw)
// Scaling the colour by Ld/Lw keeps hue; channels above 1 (saturated highlights) clip.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_hdr;
uniform float u_exposure;
// pixels whose radiance is NaN or infinite (the clamp below would hide them in the LDR image):
// counted here, where every pixel is read anyway, so that a caller learns of them without
// reading the image back (Frame.nonfinite_pixels)
layout(std430, binding = 0) buffer NonFinite { uint nonfinite_pixels; };
out vec4 o_ldr;
void main() {
    vec3 h = texelFetch(u_hdr, ivec2(gl_FragCoord.xy), 0).rgb;  // the same size as the target
    // NaN or ±inf: all exponent bits set (a bit test, which no compiler's fast-math folds away as it
    // may isnan/isinf)
    if (any(equal(floatBitsToUint(h) & 0x7f800000u, uvec3(0x7f800000u)))) atomicAdd(nonfinite_pixels, 1u);
    vec3 c = max(h, vec3(0.0)) * u_exposure;
    float lw = luminance(c);
    vec3 mapped = lw > 0.0 ? c * (1.0 / (1.0 + lw)) : vec3(0.0);
    o_ldr = vec4(linear_to_srgb(mapped), 1.0);
}
#endif
