// Indirect lighting of a G-buffer, one technique per program, added onto the lit image with
// additive blending (so each technique has its own cost, as in the paper's Table 1):
//   TECHNIQUE == 1  sky lighting (paper §7):   L += albedo/pi * E_sky(p, n)       (sky volume, L2 SH)
//                   SKY_GLOSSY (SkyConfig.glossy): + k_s * L_sky(p, r, m), the volume's radiance around the
//                   mirror direction r filtered by the Phong lobe (sky.glsl, sky_irradiance_glossy), times
//                   the lobe's share above the surface's flat face (sky_horizon_occlusion; the face from
//                   the G-buffer's positions in the main view, the shading normal in ray-traced views)
//   TECHNIQUE == 2  LPV (paper §8, Fig. 10):   L += albedo/pi * E_lpv(p, n) + k_s * L_glossy(p, r, m)
// u_diffuse / u_glossy (LPVConfig.diffuse / .glossy) switch the two LPV terms: a switched-off term
// is not looked up. Main view: multiplied by SSAO (indirect light only, paper §3). Ray-traced views (u_rt_view): the
// viewer is each pixel's ray origin, no SSAO, untraced pixels and misses get nothing.
// LOWRES (main view at 1/u_scale resolution, lowres.glsl): no albedo here; out 0 = E/pi * AO,
// out 1 = k_s * L_glossy * AO, summed over the techniques, then upsample.glsl multiplies by the
// full-resolution albedo while it upsamples (textures stay sharp, the smooth light is computed on
// fewer pixels).
// LPV_TERMS (TECHNIQUE 2): 3 = diffuse and glossy (full resolution), 1 = diffuse only, 2 = glossy
// only: at low resolution the two are drawn apart, the glossy one over the glossy class alone
// (lowres.glsl), since only a few pixels need its march.
#ifndef LPV_TERMS
#define LPV_TERMS 3
#endif
#ifndef SKY_GLOSSY
#define SKY_GLOSSY 0
#endif
#include "lowres.glsl"
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#if TECHNIQUE == 1
#include "sky.glsl"
#else
#include "lpv.glsl"
#endif
uniform sampler2D g_albedo;
uniform sampler2D g_normal;
uniform sampler2D g_position;
uniform sampler2D g_material;
uniform sampler2D g_eye;        // rt views: ray origin
uniform sampler2D u_ao;         // SSAO (1 = open; not padded: LOWRES reads the image's texel)
uniform bool u_use_ao;
uniform bool u_rt_view;
uniform vec3 u_camera_pos;
uniform bool u_diffuse;         // TECHNIQUE 2: add the LPV's diffuse term
uniform bool u_glossy;          // TECHNIQUE 2: add the LPV's glossy term
#if LOWRES
uniform int u_ao_div;           // AO texels per low-res pixel: 1, or the low-res scale for a scale-1 refinement
layout(location = 0) out vec4 o_irr;
layout(location = 1) out vec4 o_gloss;
#define GBUF(t) texelFetch(t, px, 0)
#else
out vec4 o_hdr;
#define GBUF(t) texture(t, v_uv)
#endif

void main() {
#if LOWRES
    ivec2 low = lowres_pixel();
    ivec2 px = representative_pixel(low, textureSize(g_position, 0));
    o_irr = vec4(0.0); o_gloss = vec4(0.0);
    vec4 pos = GBUF(g_position);
    if (pos.w == 0.0) return;
    vec3 albedo = vec3(1.0);
    float ao = u_use_ao ? texelFetch(u_ao, low / max(u_ao_div, 1), 0).r : 1.0;
#else
    vec4 pos = GBUF(g_position);
    if (pos.w == 0.0) { o_hdr = vec4(0.0); return; }     // background, miss, or not traced
    vec3 albedo = GBUF(g_albedo).rgb;
    float ao = (u_use_ao && !u_rt_view) ? texture(u_ao, v_uv).r : 1.0;
#endif
    vec4 nrm = GBUF(g_normal);
    vec3 n = normalize(nrm.xyz);
    vec3 p = pos.xyz;
    vec3 eye = u_rt_view ? GBUF(g_eye).xyz : u_camera_pos;
    vec3 v = normalize(eye - p);
    if (dot(n, v) < 0.0) n = -n;                          // lit from the viewer's side
    vec3 diffuse = vec3(0.0), glossy = vec3(0.0);
#if TECHNIQUE == 1
#if SKY_GLOSSY
    vec3 sky_gloss;
    vec3 r = reflect(-v, n);
    float m = GBUF(g_material).x;
    diffuse = albedo / PI * sky_irradiance_glossy(p, n, r, m, sky_gloss);
#if LOWRES
    vec3 ng = gbuffer_flat_normal(g_position, px, p, n);
#else
    vec3 ng = u_rt_view ? n : gbuffer_flat_normal(g_position, ivec2(gl_FragCoord.xy), p, n);
#endif
    glossy = nrm.w * sky_horizon_occlusion(r, ng, m) * sky_gloss;
#else
    diffuse = albedo / PI * sky_irradiance(p, n);
#endif
#else
    float shininess = GBUF(g_material).x;
#if LPV_TERMS & 1
    if (u_diffuse) diffuse = albedo / PI * lpv_irradiance(p, n);
#endif
#if LPV_TERMS & 2
    if (u_glossy && nrm.w >= GLOSSY_MIN_SPECULAR) glossy = nrm.w * lpv_glossy(p, reflect(-v, n), shininess);
#endif
#endif
#if LOWRES
    o_irr = vec4(diffuse * ao, 0.0);
    o_gloss = vec4(glossy * ao, 0.0);
#else
    o_hdr = vec4((diffuse + glossy) * ao, 0.0);
#endif
}
#endif
