// Deferred lighting of a G-buffer (paper §3, §6, §9): Phong + sun shadows, the indirect terms (with
// IndirectConfig.scale > 1, the low-res sky and LPV light upsampled: upsample.glsl), and the sky behind
// uncovered pixels. Linear HDR radiance out. The same program lights the main view
// (rasterised G-buffer, view-fitted cascades, SSAO) and the ray-traced views (ray-traced G-buffer,
// the tracer's shadow rays or the overlapped shadow maps, no SSAO; the viewer of a pixel is its
// ray's origin).
//
// Radiance of a lit pixel (W m^-2 sr^-1 per channel), E = sun irradiance facing the sun:
//   L = (albedo/pi + k_s (n+2)/(2 pi) max(0, r.v)^n) * E * max(0, N.L) * visibility + indirect
// (energy-normalised Phong: its lobe integrates to k_s over the hemisphere at normal incidence).
#if defined(SPLIT) && SPLIT > 0
#define FULLSCREEN_Z 1.0
#endif
#if defined(VIS_STEP) && VIS_STEP == 2
#define FULLSCREEN_Z 0.5  // window depth 0.75, behind VIS_SHADE_DEPTH (visibility_upsample.glsl), before 1
#endif
#include "fullscreen.glsl"

// Compiled per use (DeferredPass picks the variant): llvmpipe runs every path of a fragment shader
// for every pixel, whatever its branches decide, so a path a view never takes is left out of its
// program instead of being skipped by a uniform.
//   RT_VIEW 1: a ray-traced G-buffer (else the main view);  TRACED_SUN 1 (rt views): the sun's
//   visibility is the tracer's shadow ray, g_eye.w (else the shadow maps);  CONTACT_STEPS N > 0 (main
//   view): the screen-space contact shadow, N march steps;  UPSAMPLE 1 (main view): add the low-res
//   indirect light; UPSAMPLE 2: that light blended with the last frame's (indirect_history.glsl),
//   written to o_history too. (The shadow filter and its taps are compiled in too: shadow_sampling.glsl.)
//   VIS_PASS m > 0 (main view): not the lighting but the sun's visibility at the pixels that
//   sampling m keeps (visibility_upsample.glsl), in two steps: VIS_STEP 1 writes each sample's guide
//   and visibility 0, and its class as its depth; VIS_STEP 2, drawn over that depth, computes the
//   visibility (shadow maps, contact march) of the samples on surfaces facing the sun only;
//   VIS_UPSAMPLE m > 0 (main view): the sun's visibility read from that pass's target instead of
//   computed here.
//   SPLIT (main view): 0 = one program for every pixel; 1 = the G-buffer's surfaces only; 2 = the
//   sky only. DeferredPass draws 2 then 1 at the far plane over the G-buffer's depth (depth test <=,
//   then >), and llvmpipe rejects a pixel by depth before shading it: neither half runs the other's
//   code (the sky's for every surface pixel, the lighting for every sky pixel).
#ifndef RT_VIEW
#define RT_VIEW 0
#endif
#ifndef TRACED_SUN
#define TRACED_SUN 0
#endif
#ifndef CONTACT_STEPS
#define CONTACT_STEPS 0
#endif
#ifndef UPSAMPLE
#define UPSAMPLE 0
#endif
#ifndef SPLIT
#define SPLIT 0
#endif
#ifndef VIS_PASS
#define VIS_PASS 0
#endif
#ifndef VIS_UPSAMPLE
#define VIS_UPSAMPLE 0
#endif

#if defined FRAGMENT_SHADER
#include "shadow_sampling.glsl"
#include "sky.glsl"
#if UPSAMPLE
#include "upsample.glsl"
#endif
#if UPSAMPLE == 2
#include "indirect_history.glsl"
#endif
#if VIS_PASS || VIS_UPSAMPLE
#include "visibility_upsample.glsl"
#endif
uniform bool u_use_sky_map;         // sky dome from the paraboloid sky map (else the constant sky)
uniform sampler2D g_albedo;
uniform sampler2D g_normal;
uniform sampler2D g_position;
uniform sampler2D g_material;
uniform vec3 u_sun_dir;             // unit, towards the sun
uniform vec3 u_sun_irradiance;      // W m^-2 per channel
uniform vec3 u_sun_radiance;        // disc radiance, W m^-2 sr^-1
uniform float u_sun_cos_radius;     // cos of the disc's angular radius
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
uniform mat4 u_inv_view_proj;
uniform vec3 u_sky_radiance;        // the sky where no sky map is bound: a constant sky
uniform vec3 u_ambient_irradiance;  // constant ambient term (baseline hack; 0 = off)
uniform bool u_use_ao;
uniform sampler2D u_ao;             // SSAO, 1 = open (multiplies indirect light only)
uniform sampler2D g_eye;            // rt view: xyz = ray origin (the viewer of this pixel);
                                    // w = the sun's visibility from the tracer's shadow ray
uniform sampler2D g_ray_dir;        // rt view: xyz = ray direction (0 = pixel not traced)
uniform mat4 u_view_proj;           // main view: world -> clip (contact shadows)
uniform float u_contact_pixels;     // contact-shadow march length, pixel footprints at the receiver
uniform float u_contact_texels;     // ... and at most this many shadow-map texels of its cascade
#if VIS_PASS
layout(location = 0) out vec4 o_vis;  // visibility_upsample.glsl
#else
layout(location = 0) out vec4 o_hdr;
layout(location = 1) out vec4 o_direct;
#if UPSAMPLE == 2
layout(location = 2) out vec4 o_history;  // this frame's indirect light and view depth, for the next
#endif
#endif

vec3 sky(vec3 dir) {
    if (dot(dir, u_sun_dir) >= u_sun_cos_radius && u_sun_dir.y > 0.0) return u_sun_radiance;
    if (dir.y < 0.0) return vec3(0.0);
    return u_use_sky_map ? sky_map_radiance(u_sky_map, dir) : u_sky_radiance;
}

#if CONTACT_STEPS > 0
// Screen-space contact shadow (main view): march from p towards the sun over u_contact_pixels pixel
// footprints, but no further than u_contact_texels texels of the shadow map (what its resolution and
// bias cannot resolve; beyond that the map is right and a screen-space march only adds view-dependent
// errors); a march point behind the surface the G-buffer shows there (that pixel's plane, so a plane
// never shadows itself), by less than the march length, is blocked. It catches a receiver within a
// few texels of a blocker it touches (a floor at the foot of a wall nearly parallel to the sun,
// whose filter taps reach past the wall's edge in the map; a wall under an eave, lit by the bias).
float contact_visibility(vec3 p, vec3 n, float view_depth) {
    vec2 size = vec2(textureSize(g_position, 0));
    float p11 = length(vec3(u_view_proj[0][1], u_view_proj[1][1], u_view_proj[2][1]));
    float pixel = 2.0 * view_depth / (p11 * size.y);       // metres per pixel at the receiver
    float len = min(u_contact_pixels * pixel, u_contact_texels * cascade_texel_at(view_depth));
    // march point i: m = p + d i, in clip space c0 + dc i (linear), seen from the camera along r0 + d i
    vec3 d = u_sun_dir * (len / float(CONTACT_STEPS));
    vec4 c0 = u_view_proj * vec4(p, 1.0), dc = u_view_proj * vec4(d, 0.0);
    vec3 r0 = p - u_camera_pos;
    float k_near = 2.0 * pixel / max(view_depth, 1e-6);   // metres of plane per metre of depth
    for (int i = 1; i <= CONTACT_STEPS; ++i) {
        vec4 c = c0 + dc * float(i);
        if (c.w <= 0.0) break;
        vec2 uv = c.xy / c.w * 0.5 + 0.5;
        if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) break;
        vec4 g = texture(g_position, uv);
        if (g.w == 0.0) continue;                            // sky
        vec3 gn = texture(g_normal, uv).xyz;                 // unit to f16 precision; s is scale-free
        vec3 r = r0 + d * float(i);                          // camera to m
        float rn = dot(r, gn);
        float dist = length(r);
        if (abs(rn) < 1e-3 * dist) continue;
        float s = dot(g.xyz - u_camera_pos, gn) / rn;        // that pixel's plane at camera + r s
        float t = s * dist;
        float behind = dist - t;
        // the plane only near its pixel (a grazing plane extrapolated far past it is not the occluder)
        vec3 e = u_camera_pos + r * s - g.xyz;
        float near_g = k_near * max(t, 0.0);
        if (t > 0.0 && behind > 0.05 * pixel && behind < len && dot(e, e) < near_g * near_g) return 0.0;
    }
    return 1.0;
}
#endif

#if VIS_PASS && VIS_STEP == 1
// the G-buffer pixel this texel samples: its normal and view depth (the upsampling's guide), no
// light yet, and its class as depth: VIS_SHADE_DEPTH where the lighting would look the sun up
void main() {
    ivec2 rq = visibility_sample_pixel(VIS_PASS, ivec2(gl_FragCoord.xy), textureSize(g_position, 0));
    vec4 pos = texelFetch(g_position, rq, 0);
    vec3 n = normalize(texelFetch(g_normal, rq, 0).xyz);
    float metric = dot(pos.xyz - u_camera_pos, u_camera_forward);
    bool lit = pos.w != 0.0 && dot(n, u_sun_dir) > 0.0 && u_sun_dir.y > -0.02;
    o_vis = pos.w == 0.0 ? vec4(0.0, 0.0, -1.0, 1.0) : vec4(oct_encode(n), metric, 0.0);  // open sky: 1
    gl_FragDepth = lit ? VIS_SHADE_DEPTH : 1.0;
}
#elif VIS_PASS
// the visibility of the G-buffer pixel this texel samples, as the main view's lighting below would
// compute it there (only the w channel is written: the guide stays)
void main() {
    ivec2 rq = visibility_sample_pixel(VIS_PASS, ivec2(gl_FragCoord.xy), textureSize(g_position, 0));
    vec3 p = texelFetch(g_position, rq, 0).xyz;
    vec3 n = normalize(texelFetch(g_normal, rq, 0).xyz);
    float metric = dot(p - u_camera_pos, u_camera_forward);
    float vis = sun_visibility(p, n, dot(n, u_sun_dir), metric);
#if CONTACT_STEPS > 0
    if (vis > 0.0) vis *= contact_visibility(p, n, metric);
#endif
    o_vis = vec4(0.0, 0.0, 0.0, vis);
}
#else
void main() {
    vec4 pos = texture(g_position, v_uv);
#if RT_VIEW
    vec3 rd = texture(g_ray_dir, v_uv).xyz;
    if (dot(rd, rd) == 0.0) { o_hdr = vec4(0.0); o_direct = vec4(0.0); return; }  // not traced
    vec4 eye_w = texture(g_eye, v_uv);
    vec3 eye = eye_w.xyz;
    if (pos.w == 0.0) { o_hdr = vec4(sky(normalize(rd)), 1.0); o_direct = vec4(0.0); return; }
#else
    vec3 eye = u_camera_pos;
#if SPLIT == 0
    if (pos.w == 0.0) {
#endif
#if SPLIT != 1
        vec4 far_p = u_inv_view_proj * vec4(v_uv * 2.0 - 1.0, 1.0, 1.0);
        vec3 dir = normalize(far_p.xyz / far_p.w - u_camera_pos);
        o_hdr = vec4(sky(dir), 1.0);
        o_direct = vec4(0.0);
        return;
#endif
#if SPLIT == 0
    }
#endif
#endif
    vec3 albedo = texture(g_albedo, v_uv).rgb;
    vec4 nrm = texture(g_normal, v_uv);
    vec4 mat = texture(g_material, v_uv);
    vec3 n = normalize(nrm.xyz);
    vec3 p = pos.xyz;
    vec3 v = normalize(eye - p);
    float ndl = dot(n, u_sun_dir);
    vec3 direct = vec3(0.0);
    if (ndl > 0.0 && u_sun_dir.y > -0.02) {
        // cascades are chosen by view depth; overlapped maps (rt views) by distance to the camera
#if RT_VIEW && TRACED_SUN
        float vis = eye_w.w;
#elif RT_VIEW
        float vis = sun_visibility(p, n, ndl, length(p - u_camera_pos));
#elif VIS_UPSAMPLE
        float vis = upsampled_visibility(ivec2(gl_FragCoord.xy), dot(p - u_camera_pos, u_camera_forward), n);
#else
        float metric = dot(p - u_camera_pos, u_camera_forward);
        float vis = sun_visibility(p, n, ndl, metric);
#if CONTACT_STEPS > 0
        if (vis > 0.0) vis *= contact_visibility(p, n, metric);
#endif
#endif
        vec3 r = reflect(-u_sun_dir, n);
        float spec = nrm.w * (mat.x + 2.0) / (2.0 * PI) * pow(max(dot(r, v), 0.0), mat.x);
        direct = (albedo / PI + vec3(spec)) * u_sun_irradiance * ndl * vis;
    }
    vec3 indirect = albedo / PI * u_ambient_irradiance;
#if !RT_VIEW
    if (u_use_ao) indirect *= texture(u_ao, v_uv).r;
#if UPSAMPLE
    float view_z = dot(p - u_camera_pos, u_camera_forward);
    vec3 up = upsampled_indirect(ivec2(gl_FragCoord.xy), view_z, nrm.xyz, albedo);
#if UPSAMPLE == 2
    up = history_blend(p, n, up);
    o_history = vec4(up, view_z);
#endif
    indirect += up;
#endif
#endif
    o_hdr = vec4(direct + indirect, 1.0);
    o_direct = vec4(direct, 1.0);
}
#endif
#endif
