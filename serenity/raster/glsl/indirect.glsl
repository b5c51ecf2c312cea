// Indirect lighting of a G-buffer, one technique per program, added onto the lit image with
// additive blending (so each technique has its own cost, as in the paper's Table 1):
//   TECHNIQUE == 1  sky lighting (paper §7):   L += albedo/pi * E_sky(p, n)       (sky volume, L2 SH)
//   TECHNIQUE == 2  LPV (paper §8, Fig. 10):   L += albedo/pi * E_lpv(p, n) + k_s * L_glossy(p, r, m)
// Main view: multiplied by SSAO (indirect light only, paper §3). Ray-traced views (u_rt_view): the
// viewer is each pixel's ray origin, no SSAO, untraced pixels and misses get nothing.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#if TECHNIQUE == 1
#include "sky.glsl"
#else
#include "lpv.glsl"
#endif
// glossy LPV light only where the specular lobe is strong enough to show it (the march costs
// glossy_steps x 3 cascades x 3 fetches per pixel; k_s = 0.05 plaster gains < 1 % from it)
const float GLOSSY_MIN_SPECULAR = 0.1;
uniform sampler2D g_albedo;
uniform sampler2D g_normal;
uniform sampler2D g_position;
uniform sampler2D g_material;
uniform sampler2D g_eye;        // rt views: ray origin
uniform sampler2D u_ao;         // SSAO (1 = open)
uniform bool u_use_ao;
uniform bool u_rt_view;
uniform vec3 u_camera_pos;
out vec4 o_hdr;

void main() {
    vec4 pos = texture(g_position, v_uv);
    if (pos.w == 0.0) { o_hdr = vec4(0.0); return; }     // background, miss, or not traced
    vec3 albedo = texture(g_albedo, v_uv).rgb;
    vec4 nrm = texture(g_normal, v_uv);
    vec3 n = normalize(nrm.xyz);
    vec3 p = pos.xyz;
    vec3 eye = u_rt_view ? texture(g_eye, v_uv).xyz : u_camera_pos;
    vec3 v = normalize(eye - p);
    if (dot(n, v) < 0.0) n = -n;                          // lit from the viewer's side
    vec3 L;
#if TECHNIQUE == 1
    L = albedo / PI * sky_irradiance(p, n);
#else
    float shininess = texture(g_material, v_uv).x;
    L = albedo / PI * lpv_irradiance(p, n);
    if (nrm.w >= GLOSSY_MIN_SPECULAR) L += nrm.w * lpv_glossy(p, reflect(-v, n), shininess);
#endif
    if (u_use_ao && !u_rt_view) L *= texture(u_ao, v_uv).r;
    o_hdr = vec4(L, 0.0);
}
#endif
