// Separable bilateral blur of the AO: Gaussian in pixels x depth similarity x normal similarity,
// so occlusion does not bleed across silhouettes. u_axis = (1,0) then (0,1). Runs at the AO's
// resolution: each texel's depth and normal are its representative G-buffer pixel's, read from
// the low-res guide (lowres_guide.glsl). The source and the guide lie in the padded targets
// (lowres.glsl: u_lowres_origin); the destination's image starts at u_dst_origin (the padded
// origin, or 0 for the unpadded AO that the last pass writes).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "lowres.glsl"
uniform ivec2 u_dst_origin;
uniform sampler2D u_src;
uniform sampler2D u_guide;     // xyz = normal, w = view depth (-1: background)
uniform vec2 u_axis;
uniform int u_radius;          // pixels
out float o_value;
void main() {
    ivec2 low = ivec2(gl_FragCoord.xy) - u_dst_origin;
    ivec2 step = ivec2(u_axis);
    vec4 g0 = texelFetch(u_guide, lowres_texel(low), 0);
    if (g0.w < 0.0) { o_value = 1.0; return; }
    float z0 = g0.w;
    vec3 n0 = g0.xyz;
    float sigma = max(float(u_radius) * 0.5, 0.5);
    float sum = 0.0, wsum = 0.0;
    for (int k = -u_radius; k <= u_radius; ++k) {
        ivec2 q = lowres_texel(low + step * k);
        vec4 g = texelFetch(u_guide, q, 0);
        if (g.w < 0.0) continue;
        float c = max(dot(g.xyz, n0), 0.0);
        c *= c; c *= c; c *= c;  // ^8
        float w = exp(-0.5 * float(k * k) / (sigma * sigma))
                * exp(-abs(g.w - z0) / (0.02 * z0 + 1e-3))
                * c;
        sum += w * texelFetch(u_src, q, 0).r;
        wsum += w;
    }
    o_value = wsum > 0.0 ? sum / wsum : texelFetch(u_src, lowres_texel(low), 0).r;
}
#endif
