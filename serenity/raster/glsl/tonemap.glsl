// Exposure, Reinhard (2002) global operator on luminance, sRGB encoding.
//   Lw = luminance(exposure * hdr);  Ld = Lw / (1 + Lw);  ldr = srgb(exposure * hdr * Ld / Lw)
// Scaling the colour by Ld/Lw keeps hue; channels above 1 (saturated highlights) clip.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_hdr;
uniform float u_exposure;
out vec4 o_ldr;
void main() {
    vec3 c = max(texture(u_hdr, v_uv).rgb, vec3(0.0)) * u_exposure;
    float lw = luminance(c);
    vec3 mapped = lw > 0.0 ? c * (1.0 / (1.0 + lw)) : vec3(0.0);
    o_ldr = vec4(linear_to_srgb(mapped), 1.0);
}
#endif
