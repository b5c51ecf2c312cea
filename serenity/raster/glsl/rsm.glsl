// Reflective shadow map of the sun (Dachsbacher & Stamminger 2005; paper §8): every texel is a
// virtual point light. Orthographic view from the sun, so each texel covers an area A (m^2)
// perpendicular to the sun and receives power E*A; a diffuse surface re-emits rho*E*A (W).
//   0 flux     rgb = rho * E * A (W), a = 1 where covered
//   1 normal   xyz = world normal facing the sun
//   2 position xyz = world position (m)
// ALPHA_MASK = 1: a cut-out's variant: fragments whose coverage is below the cutoff are discarded
// (as in the shadow maps; shadow_depth.glsl).
#ifndef ALPHA_MASK
#define ALPHA_MASK 0
#endif
#if ALPHA_MASK
#define SCENE_VERTEX_UV
#endif
#include "scene_vertex.glsl"

#if defined FRAGMENT_SHADER
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_albedo;   // material albedo x its texture's mean (rsm.py)
uniform vec3 u_sun_dir;
uniform vec3 u_sun_irradiance;
uniform float u_texel_area;
#include "alpha_mask.glsl"
layout(location = 0) out vec4 o_flux;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_position;
void main() {
#if ALPHA_MASK
    discard_cut_out();
#endif
    vec3 albedo = u_albedo;
    vec3 n = normalize(v_normal);
    if (dot(n, u_sun_dir) < 0.0) n = -n;
    o_flux = vec4(albedo * u_sun_irradiance * u_texel_area, 1.0);
    o_normal = vec4(n, 0.0);
    o_position = vec4(v_world, 1.0);
}
#endif
