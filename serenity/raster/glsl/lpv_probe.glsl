// Evaluates the LPV lookups of lpv.glsl at arbitrary points (tests, debugging): pixel (x, y) reads
// a point from u_points and a unit direction + shininess from u_dirs (texelFetch, no filtering) and
// writes lpv_irradiance(p, dir) to target 0 and lpv_glossy(p, dir, shininess) to target 1.
#include "common.glsl"

#if defined VERTEX_SHADER
void main() { gl_Position = fullscreen_position(gl_VertexID); }
#endif

#if defined FRAGMENT_SHADER
#include "lpv.glsl"
uniform sampler2D u_points;  // xyz: world position (m)
uniform sampler2D u_dirs;    // xyz: normal / reflected direction, w: Phong exponent
layout(location = 0) out vec4 o_irradiance;
layout(location = 1) out vec4 o_glossy;
void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec3 p = texelFetch(u_points, px, 0).xyz;
    vec4 d = texelFetch(u_dirs, px, 0);
    o_irradiance = vec4(lpv_irradiance(p, d.xyz), 1.0);
    o_glossy = vec4(lpv_glossy(p, d.xyz, d.w), 1.0);
}
#endif
