// Vertex stage of the passes that rasterise the scene's triangles (SceneGL.vao): world position and
// normal to the fragment stage, the uv when SCENE_VERTEX_UV is defined before the include and the
// tangent (xyz, handedness w) when SCENE_VERTEX_TANGENT is.
// u_view_proj is the camera's or the light's view-projection. Includes common.glsl.
#include "common.glsl"

#if defined VERTEX_SHADER
in vec3 in_position;
in vec3 in_normal;
#ifdef SCENE_VERTEX_UV
in vec2 in_uv;
out vec2 v_uv;
#endif
#ifdef SCENE_VERTEX_TANGENT
in vec4 in_tangent;
out vec4 v_tangent;
#endif
uniform mat4 u_view_proj;
out vec3 v_world;
out vec3 v_normal;
void main() {
    v_world = in_position;
    v_normal = in_normal;
#ifdef SCENE_VERTEX_UV
    v_uv = in_uv;
#endif
#ifdef SCENE_VERTEX_TANGENT
    v_tangent = in_tangent;
#endif
    gl_Position = u_view_proj * vec4(in_position, 1.0);
}
#endif
