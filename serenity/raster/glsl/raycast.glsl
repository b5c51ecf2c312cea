// Ray-casting buffer (paper §9, Fig. 12-13): for every pixel whose visible surface reflects or
// refracts, the secondary rays the CPU ray tracer must follow. Two ways to find them, the cheaper
// for the frame (raster/raycast.py): FROM_GBUFFER 0 rasterises the reflective/refractive material
// ranges again, against the G-buffer's depth (LEQUAL, no depth writes, early fragment tests), so a
// fragment runs only where that surface is the visible one (the paper's way; cheap for a few
// large mirrors); FROM_GBUFFER 1 reads each pixel's point, shading normal and material from the
// G-buffer in a fullscreen pass over the screen tiles those ranges cover (cheap for 100k chrome
// triangles: the breakfast room's chairs cost 21 ms a frame to rasterise again at 320x180). Each
// pixel that needs rays appends one record to a storage buffer through an atomic counter, and the
// host reads back the count and the records alone (stream compaction on the GPU) instead of four
// full-screen float targets.
// Record i = records[5i .. 5i+4]:
//   0 origin   xyz = world position (m), w = ray-cone width at the surface (m)
//   1 reflect  xyz = unit reflected direction, w = cone spread angle (rad) after the bounce
//   2 refract  xyz = unit refracted direction (0 under total internal reflection), w = flags:
//              1 = trace reflection, 2 = trace refraction, 4 = total internal reflection
//   3 normal   xyz = shading normal facing the viewer, w = material index
//   4 pixel    x = row * width + column (row 0 = top), exact in a float up to 2^24 pixels
// FROM_GBUFFER: the G-buffer's normal faces the viewer, and the sign of its ior (g_material.w) says
// which side of the surface the viewer sees (negative: the back, where a refracted ray leaves the
// medium).
// Ray cones after Akenine-Moller et al., "Texture Level of Detail Strategies for Real-Time Ray
// Tracing" (Ray Tracing Gems, ch. 20): spread = pixel spread angle; width = distance * spread.
#extension GL_ARB_ES3_1_compatibility : require
#ifndef FROM_GBUFFER
#define FROM_GBUFFER 1
#endif
#if FROM_GBUFFER
#include "fullscreen.glsl"
#else
#include "scene_vertex.glsl"
#endif

#if defined FRAGMENT_SHADER
uniform vec3 u_camera_pos;
uniform float u_pixel_spread;   // rad per pixel: atan(2 tan(fov/2) / height)
uniform int u_width;
uniform int u_height;
uniform uint u_capacity;        // records the buffer holds
layout(std430, binding = 0) buffer RayCount { uint ray_count; };
layout(std430, binding = 1) buffer RayRecords { vec4 records[]; };

// Append the record of pixel px, whose visible surface point p (unit normal n facing the viewer;
// ``entering``: the viewer sees the front, the side a ray enters the material by) has this ior,
// transparency and material index.
void append_rays(ivec2 px, vec3 p, vec3 n, bool entering, float ior, float transparency, float material) {
    vec3 v = p - u_camera_pos;
    float dist = length(v);
    v /= dist;
    float eta = entering ? 1.0 / ior : ior;
    vec3 r = reflect(v, n);
    vec3 t = refract(v, n, eta);
    float flags = 1.0;                 // Fresnel reflection exists for glass too
    bool tir = dot(t, t) == 0.0;
    if (transparency > 0.0 && !tir) flags += 2.0;
    if (transparency > 0.0 && tir) flags += 4.0;
    uint i = atomicAdd(ray_count, 1u);
    if (i >= u_capacity) return;
    int row = u_height - 1 - px.y;
    records[5u * i + 0u] = vec4(p, dist * u_pixel_spread);
    records[5u * i + 1u] = vec4(r, u_pixel_spread);
    records[5u * i + 2u] = vec4(tir ? vec3(0.0) : normalize(t), flags);
    records[5u * i + 3u] = vec4(n, material);
    records[5u * i + 4u] = vec4(float(row * u_width + px.x), 0.0, 0.0, 0.0);
}

#if FROM_GBUFFER
uniform sampler2D g_albedo;     // a = material index
uniform sampler2D g_normal;     // xyz = shading normal facing the viewer
uniform sampler2D g_position;   // xyz = world point, w = 0 where nothing is seen
uniform sampler2D g_material;   // shininess, reflectivity, transparency, ior (negative: the back seen)
void main() {
    if (gl_HelperInvocation) return;   // a quad's helper lanes must not append
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 pos = texelFetch(g_position, px, 0);
    vec4 mat = texelFetch(g_material, px, 0);
    if (pos.w == 0.0 || (mat.y <= 0.0 && mat.z <= 0.0)) return;  // no surface, or one that needs no ray
    append_rays(px, pos.xyz, normalize(texelFetch(g_normal, px, 0).xyz), mat.w > 0.0, abs(mat.w), mat.z,
                texelFetch(g_albedo, px, 0).a);
}
#else
layout(early_fragment_tests) in;
in vec3 v_world;
in vec3 v_normal;
uniform float u_transparency;
uniform float u_ior;
uniform float u_material_index;
void main() {
    if (gl_HelperInvocation) return;   // a quad's helper lanes must not append
    vec3 n = normalize(v_normal);
    bool entering = dot(n, v_world - u_camera_pos) < 0.0;   // front face: the ray enters the material
    append_rays(ivec2(gl_FragCoord.xy), v_world, entering ? n : -n, entering, u_ior, u_transparency,
                u_material_index);
}
#endif  // FROM_GBUFFER
#endif
