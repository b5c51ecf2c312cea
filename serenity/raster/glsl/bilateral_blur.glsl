// Separable bilateral blur of the AO: Gaussian in pixels x depth similarity x normal similarity,
// so occlusion does not bleed across silhouettes. u_axis = (1,0) then (0,1).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_src;
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform vec2 u_axis;
uniform int u_radius;          // pixels
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
out float o_value;
void main() {
    vec2 texel = 1.0 / vec2(textureSize(u_src, 0));
    vec4 p0 = texture(g_position, v_uv);
    if (p0.w == 0.0) { o_value = 1.0; return; }
    float z0 = dot(p0.xyz - u_camera_pos, u_camera_forward);
    vec3 n0 = texture(g_normal, v_uv).xyz;
    float sigma = max(float(u_radius) * 0.5, 0.5);
    float sum = 0.0, wsum = 0.0;
    for (int k = -u_radius; k <= u_radius; ++k) {
        vec2 uv = v_uv + u_axis * texel * float(k);
        vec4 p = texture(g_position, uv);
        if (p.w == 0.0) continue;
        float z = dot(p.xyz - u_camera_pos, u_camera_forward);
        vec3 n = texture(g_normal, uv).xyz;
        float w = exp(-0.5 * float(k * k) / (sigma * sigma))
                * exp(-abs(z - z0) / (0.02 * z0 + 1e-3))
                * pow(max(dot(n, n0), 0.0), 8.0);
        sum += w * texture(u_src, uv).r;
        wsum += w;
    }
    o_value = wsum > 0.0 ? sum / wsum : texture(u_src, v_uv).r;
}
#endif
