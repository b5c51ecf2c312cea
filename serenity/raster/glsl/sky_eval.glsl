// Evaluates sky.glsl at given inputs, one per pixel (SkyTexturesGL.evaluate_*: tests and debugging).
// Inputs: RGB float textures without a row flip, pixel (x, y) = item y * width + x.
//   u_mode 0: o = sky_map_radiance(u_sky_map, u_in_a)           (u_in_a = directions)
//   u_mode 1: o = sky_irradiance(u_in_a, u_in_b)                (u_in_a = points, u_in_b = normals)
//   u_mode 2: o = the glossy radiance of sky_irradiance_glossy(u_in_a, u_in_b, u_in_c, u_shininess)
//             (u_in_c = directions)
//   u_mode 3: o = sky_horizon_occlusion(u_in_a, u_in_b, u_shininess) in every channel
//             (u_in_a = mirror directions, u_in_b = geometric normals)
#include "common.glsl"
#include "sky.glsl"

#if defined VERTEX_SHADER
void main() { gl_Position = fullscreen_position(gl_VertexID); }
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_in_a;
uniform sampler2D u_in_b;
uniform sampler2D u_in_c;
uniform float u_shininess;
uniform int u_mode;
out vec4 o_value;
void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 a = texelFetch(u_in_a, px, 0).xyz;
    vec3 r;
    if (u_mode == 0) r = sky_map_radiance(u_sky_map, a);
    else if (u_mode == 1) r = sky_irradiance(a, texelFetch(u_in_b, px, 0).xyz);
    else if (u_mode == 3) r = vec3(sky_horizon_occlusion(a, texelFetch(u_in_b, px, 0).xyz, u_shininess));
    else sky_irradiance_glossy(a, texelFetch(u_in_b, px, 0).xyz, texelFetch(u_in_c, px, 0).xyz, u_shininess, r);
    o_value = vec4(r, 1.0);
}
#endif
