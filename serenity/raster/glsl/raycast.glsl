// Ray-casting buffer (paper §9, Fig. 12-13): for every pixel whose visible surface reflects or
// refracts, the secondary rays the CPU ray tracer must follow. Opaque surfaces write zeros (they
// are drawn so that they hide the reflective surfaces behind them).
//   0 origin   xyz = world position (m), w = ray-cone width at the surface (m)
//   1 reflect  xyz = unit reflected direction, w = cone spread angle (rad) after the bounce
//   2 refract  xyz = unit refracted direction (0 under total internal reflection), w = flags:
//              1 = trace reflection, 2 = trace refraction, 4 = total internal reflection
//   3 normal   xyz = shading normal facing the viewer, w = material index
// Ray cones after Akenine-Moller et al., "Texture Level of Detail Strategies for Real-Time Ray
// Tracing" (Ray Tracing Gems, ch. 20): spread = pixel spread angle; width = distance * spread.
#include "scene_vertex.glsl"

#if defined FRAGMENT_SHADER
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_camera_pos;
uniform float u_pixel_spread;   // rad per pixel: atan(2 tan(fov/2) / height)
uniform float u_reflectivity;
uniform float u_transparency;
uniform float u_ior;
uniform float u_material_index;
layout(location = 0) out vec4 o_origin;
layout(location = 1) out vec4 o_reflect;
layout(location = 2) out vec4 o_refract;
layout(location = 3) out vec4 o_normal;
void main() {
    if (u_reflectivity <= 0.0 && u_transparency <= 0.0) {
        o_origin = vec4(0.0); o_reflect = vec4(0.0); o_refract = vec4(0.0); o_normal = vec4(0.0);
        return;
    }
    vec3 n = normalize(v_normal);
    vec3 v = v_world - u_camera_pos;
    float dist = length(v);
    v /= dist;
    bool entering = dot(n, v) < 0.0;   // front face: the ray enters the material
    if (!entering) n = -n;
    float eta = entering ? 1.0 / u_ior : u_ior;
    vec3 r = reflect(v, n);
    vec3 t = refract(v, n, eta);
    float flags = 1.0;                 // Fresnel reflection exists for glass too
    bool tir = dot(t, t) == 0.0;
    if (u_transparency > 0.0 && !tir) flags += 2.0;
    if (u_transparency > 0.0 && tir) flags += 4.0;
    o_origin = vec4(v_world, dist * u_pixel_spread);
    o_reflect = vec4(r, u_pixel_spread);
    o_refract = vec4(tir ? vec3(0.0) : normalize(t), flags);
    o_normal = vec4(n, u_material_index);
}
#endif
