// Fullscreen pass: one triangle from gl_VertexID (no vertex buffers: context.fullscreen_vao); the
// fragment stage receives v_uv in [0, 1]^2. Include it instead of common.glsl.
#include "common.glsl"

#if defined VERTEX_SHADER
out vec2 v_uv;
void main() {
    v_uv = fullscreen_uv(gl_VertexID);
    gl_Position = fullscreen_position(gl_VertexID);
#ifdef FULLSCREEN_Z
    gl_Position.z = FULLSCREEN_Z;  // NDC depth to test against a depth buffer: deferred.glsl SPLIT, lowres.glsl
#endif
}
#elif defined FRAGMENT_SHADER
in vec2 v_uv;
#endif
