// G-buffer pass: one draw per material range. Outputs (all float targets, linear):
//   0 albedo   rgb = linear albedo (material colour x texture), a = material index
//   1 normal   xyz = world shading normal facing the camera, w = Phong specular strength k_s
//   2 position xyz = world position (m), w = 1 where covered (0 = background)
//   3 material x = Phong exponent, y = reflectivity, z = transparency, w = index of refraction
#define SCENE_VERTEX_UV
#include "scene_vertex.glsl"

#if defined FRAGMENT_SHADER
in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
uniform vec3 u_albedo;
uniform bool u_has_texture;
uniform sampler2D u_albedo_tex;
uniform float u_material_index;
uniform vec4 u_material;   // shininess, reflectivity, transparency, ior
uniform float u_specular;
uniform vec3 u_camera_pos;
layout(location = 0) out vec4 o_albedo;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_position;
layout(location = 3) out vec4 o_material;
void main() {
    vec3 albedo = u_albedo;
    if (u_has_texture) albedo *= texture(u_albedo_tex, v_uv).rgb;
    vec3 n = normalize(v_normal);
    // two-sided: the shading normal faces the viewer (thin walls, glass panes)
    if (dot(n, u_camera_pos - v_world) < 0.0) n = -n;
    o_albedo = vec4(albedo, u_material_index);
    o_normal = vec4(n, u_specular);
    o_position = vec4(v_world, 1.0);
    o_material = u_material;
}
#endif
