// Ray-casting buffer (paper §9, Fig. 12-13): for every pixel whose visible surface reflects or
// refracts, the secondary rays the CPU ray tracer must follow. Only the reflective/refractive
// material ranges are drawn, against the G-buffer's depth (LEQUAL, no depth writes, early fragment
// tests), so a fragment runs only where that surface is the visible one; each appends one record
// to a storage buffer through an atomic counter, and the host reads back the count and the records
// alone (stream compaction on the GPU) instead of four full-screen float targets.
// Record i = records[5i .. 5i+4]:
//   0 origin   xyz = world position (m), w = ray-cone width at the surface (m)
//   1 reflect  xyz = unit reflected direction, w = cone spread angle (rad) after the bounce
//   2 refract  xyz = unit refracted direction (0 under total internal reflection), w = flags:
//              1 = trace reflection, 2 = trace refraction, 4 = total internal reflection
//   3 normal   xyz = shading normal facing the viewer, w = material index
//   4 pixel    x = row * width + column (row 0 = top), exact in a float up to 2^24 pixels
// Ray cones after Akenine-Moller et al., "Texture Level of Detail Strategies for Real-Time Ray
// Tracing" (Ray Tracing Gems, ch. 20): spread = pixel spread angle; width = distance * spread.
#extension GL_ARB_ES3_1_compatibility : require
#include "scene_vertex.glsl"

#if defined FRAGMENT_SHADER
layout(early_fragment_tests) in;
in vec3 v_world;
in vec3 v_normal;
uniform vec3 u_camera_pos;
uniform float u_pixel_spread;   // rad per pixel: atan(2 tan(fov/2) / height)
uniform float u_transparency;
uniform float u_ior;
uniform float u_material_index;
uniform int u_width;
uniform int u_height;
uniform uint u_capacity;        // records the buffer holds
layout(std430, binding = 0) buffer RayCount { uint ray_count; };
layout(std430, binding = 1) buffer RayRecords { vec4 records[]; };
void main() {
    if (gl_HelperInvocation) return;   // a quad's helper lanes must not append
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
    uint i = atomicAdd(ray_count, 1u);
    if (i >= u_capacity) return;
    int row = u_height - 1 - int(gl_FragCoord.y);
    records[5u * i + 0u] = vec4(v_world, dist * u_pixel_spread);
    records[5u * i + 1u] = vec4(r, u_pixel_spread);
    records[5u * i + 2u] = vec4(tir ? vec3(0.0) : normalize(t), flags);
    records[5u * i + 3u] = vec4(n, u_material_index);
    records[5u * i + 4u] = vec4(float(row * u_width + int(gl_FragCoord.x)), 0.0, 0.0, 0.0);
}
#endif
