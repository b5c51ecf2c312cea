// The viewer's overlay lines (the LPV cascades' bounds): world-space segments, one colour each.
#include "common.glsl"

#if defined VERTEX_SHADER
uniform mat4 u_view_proj;
in vec3 in_position;
in vec3 in_color;
out vec3 v_color;
void main() { v_color = in_color; gl_Position = u_view_proj * vec4(in_position, 1.0); }
#elif defined FRAGMENT_SHADER
in vec3 v_color;
out vec4 o_color;
void main() { o_color = vec4(v_color, 1.0); }
#endif
