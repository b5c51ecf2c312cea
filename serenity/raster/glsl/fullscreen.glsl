// Fullscreen pass: one triangle from gl_VertexID (no vertex buffers: context.fullscreen_vao); the
// fragment stage receives v_uv in [0, 1]^2. Include it instead of common.glsl.
#include "common.glsl"

#if defined VERTEX_SHADER
out vec2 v_uv;
void main() {
    v_uv = fullscreen_uv(gl_VertexID);
    gl_Position = fullscreen_position(gl_VertexID);
#ifdef FULLSCREEN_AT_FAR
    gl_Position.z = 1.0;  // at the far plane, to be depth-tested against a G-buffer (deferred.glsl SPLIT)
#endif
}
#elif defined FRAGMENT_SHADER
in vec2 v_uv;
#endif
