// Evaluates sky.glsl at given inputs, one per pixel (SkyTexturesGL.evaluate_*: tests and debugging).
// Inputs: RGB float textures without a row flip, pixel (x, y) = item y * width + x.
//   u_mode 0: o = sky_map_radiance(u_sky_map, u_in_a)           (u_in_a = directions)
//   u_mode 1: o = sky_irradiance(u_in_a, u_in_b)                (u_in_a = points, u_in_b = normals)
#include "common.glsl"
#include "sky.glsl"

#if defined VERTEX_SHADER
void main() { gl_Position = fullscreen_position(gl_VertexID); }
#endif

#if defined FRAGMENT_SHADER
uniform sampler2D u_in_a;
uniform sampler2D u_in_b;
uniform int u_mode;
out vec4 o_value;
void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 a = texelFetch(u_in_a, px, 0).xyz;
    vec3 r;
    if (u_mode == 0) r = sky_map_radiance(u_sky_map, a);
    else r = sky_irradiance(a, texelFetch(u_in_b, px, 0).xyz);
    o_value = vec4(r, 1.0);
}
#endif
