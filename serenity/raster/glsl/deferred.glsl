// Deferred lighting of a G-buffer (paper §3, §6, §9): Phong + sun shadows, the indirect terms, and
// the sky behind uncovered pixels. Linear HDR radiance out. The same program lights the main view
// (rasterised G-buffer, view-fitted cascades, SSAO) and the ray-traced views (ray-traced G-buffer,
// the tracer's shadow rays or the overlapped shadow maps, no SSAO; the viewer of a pixel is its
// ray's origin).
//
// Radiance of a lit pixel (W m^-2 sr^-1 per channel), E = sun irradiance facing the sun:
//   L = (albedo/pi + k_s (n+2)/(2 pi) max(0, r.v)^n) * E * max(0, N.L) * visibility + indirect
// (energy-normalised Phong: its lobe integrates to k_s over the hemisphere at normal incidence).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "shadow_sampling.glsl"
#include "sky.glsl"
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
uniform vec3 u_sky_radiance;        // constant sky (placeholder until the sky map)
uniform vec3 u_ambient_irradiance;  // constant ambient term (baseline hack; 0 = off)
uniform bool u_use_ao;
uniform sampler2D u_ao;             // SSAO, 1 = open (multiplies indirect light only)
uniform bool u_rt_view;             // lighting a ray-traced G-buffer
uniform sampler2D g_eye;            // rt view: xyz = ray origin (the viewer of this pixel);
                                    // w = the sun's visibility from the tracer's shadow ray
uniform bool u_traced_sun;          // rt view: use g_eye.w, not the (overlapped) shadow maps
uniform sampler2D g_ray_dir;        // rt view: xyz = ray direction (0 = pixel not traced)
layout(location = 0) out vec4 o_hdr;
layout(location = 1) out vec4 o_direct;

vec3 sky(vec3 dir) {
    if (dot(dir, u_sun_dir) >= u_sun_cos_radius && u_sun_dir.y > 0.0) return u_sun_radiance;
    if (dir.y < 0.0) return vec3(0.0);
    return u_use_sky_map ? sky_map_radiance(u_sky_map, dir) : u_sky_radiance;
}

void main() {
    vec4 pos = texture(g_position, v_uv);
    vec3 eye = u_camera_pos;
    if (u_rt_view) {
        vec3 rd = texture(g_ray_dir, v_uv).xyz;
        if (dot(rd, rd) == 0.0) { o_hdr = vec4(0.0); o_direct = vec4(0.0); return; }  // not traced
        eye = texture(g_eye, v_uv).xyz;
        if (pos.w == 0.0) { o_hdr = vec4(sky(normalize(rd)), 1.0); o_direct = vec4(0.0); return; }
    } else if (pos.w == 0.0) {
        vec4 far_p = u_inv_view_proj * vec4(v_uv * 2.0 - 1.0, 1.0, 1.0);
        vec3 dir = normalize(far_p.xyz / far_p.w - u_camera_pos);
        o_hdr = vec4(sky(dir), 1.0);
        o_direct = vec4(0.0);
        return;
    }
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
        float metric = u_rt_view ? length(p - u_camera_pos) : dot(p - u_camera_pos, u_camera_forward);
        float vis = (u_rt_view && u_traced_sun) ? texture(g_eye, v_uv).w : sun_visibility(p, n, ndl, metric);
        vec3 r = reflect(-u_sun_dir, n);
        float spec = nrm.w * (mat.x + 2.0) / (2.0 * PI) * pow(max(dot(r, v), 0.0), mat.x);
        direct = (albedo / PI + vec3(spec)) * u_sun_irradiance * ndl * vis;
    }
    vec3 indirect = albedo / PI * u_ambient_irradiance;
    if (u_use_ao && !u_rt_view) indirect *= texture(u_ao, v_uv).r;
    o_hdr = vec4(direct + indirect, 1.0);
    o_direct = vec4(direct, 1.0);
}
#endif
