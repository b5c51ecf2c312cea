// Separable bilateral blur of the AO: Gaussian in pixels x depth similarity x normal similarity,
// so occlusion does not bleed across silhouettes. u_axis = (1,0) then (0,1). Runs at the AO's
// resolution: each texel's depth and normal are its representative G-buffer pixel's (lowres.glsl).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "lowres.glsl"
uniform sampler2D u_src;
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform vec2 u_axis;
uniform int u_radius;          // pixels
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
out float o_value;
void main() {
    ivec2 full = textureSize(g_position, 0);
    ivec2 low = ivec2(gl_FragCoord.xy), low_max = textureSize(u_src, 0) - 1;
    ivec2 step = ivec2(u_axis);
    vec4 p0 = texelFetch(g_position, representative_pixel(low, full), 0);
    if (p0.w == 0.0) { o_value = 1.0; return; }
    float z0 = dot(p0.xyz - u_camera_pos, u_camera_forward);
    vec3 n0 = texelFetch(g_normal, representative_pixel(low, full), 0).xyz;
    float sigma = max(float(u_radius) * 0.5, 0.5);
    float sum = 0.0, wsum = 0.0;
    for (int k = -u_radius; k <= u_radius; ++k) {
        ivec2 q = clamp(low + step * k, ivec2(0), low_max);
        ivec2 rq = representative_pixel(q, full);
        vec4 p = texelFetch(g_position, rq, 0);
        if (p.w == 0.0) continue;
        float z = dot(p.xyz - u_camera_pos, u_camera_forward);
        vec3 n = texelFetch(g_normal, rq, 0).xyz;
        float w = exp(-0.5 * float(k * k) / (sigma * sigma))
                * exp(-abs(z - z0) / (0.02 * z0 + 1e-3))
                * pow(max(dot(n, n0), 0.0), 8.0);
        sum += w * texelFetch(u_src, q, 0).r;
        wsum += w;
    }
    o_value = wsum > 0.0 ? sum / wsum : texelFetch(u_src, low, 0).r;
}
#endif
