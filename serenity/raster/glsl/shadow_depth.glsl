// Depth-only pass from the sun (orthographic). Bias is applied when the map is read.
// ALPHA_MASK = 1: a cut-out's variant (glTF alphaMode MASK): a fragment whose coverage u_alpha x the
// albedo texture's alpha (at the uv through the material's uv transform) is below u_alpha_cutoff is
// discarded, so the shadow has the cut-out's holes.
#ifndef ALPHA_MASK
#define ALPHA_MASK 0
#endif
#if defined VERTEX_SHADER
in vec3 in_position;
#if ALPHA_MASK
in vec2 in_uv;
out vec2 v_uv;
#endif
uniform mat4 u_light_view_proj;
void main() {
#if ALPHA_MASK
    v_uv = in_uv;
#endif
    gl_Position = u_light_view_proj * vec4(in_position, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
#include "alpha_mask.glsl"
void main() {
#if ALPHA_MASK
    discard_cut_out();
#endif
}
#endif
