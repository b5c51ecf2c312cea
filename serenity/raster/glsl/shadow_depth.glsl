// Depth-only pass from the sun (orthographic). Bias is applied when the map is read.
#if defined VERTEX_SHADER
in vec3 in_position;
uniform mat4 u_light_view_proj;
void main() { gl_Position = u_light_view_proj * vec4(in_position, 1.0); }
#endif

#if defined FRAGMENT_SHADER
void main() {}
#endif
