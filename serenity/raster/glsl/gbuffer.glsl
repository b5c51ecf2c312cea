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
// TEXTURE_TAPS (compiled in; GBufferPass builds one program per value it draws with): 0 = an
// untextured material (no sampling code at all: llvmpipe would run it for every fragment, textured
// or not); 1 = one trilinear tap (GL's isotropic footprint); N > 1 = N taps along the footprint's
// major axis (anisotropic filtering done in the shader).
#ifndef TEXTURE_TAPS
#define TEXTURE_TAPS 0
#endif
uniform vec3 u_albedo;
uniform float u_material_index;
uniform vec4 u_material;   // shininess, reflectivity, transparency, ior
uniform float u_specular;
uniform vec3 u_camera_pos;
layout(location = 0) out vec4 o_albedo;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_position;
layout(location = 3) out vec4 o_material;
#if TEXTURE_TAPS > 0
uniform sampler2D u_albedo_tex;
// Anisotropic texture filtering in the shader (the "footprint assembly" of Schilling et al. 1996, as
// GPUs do it): at a grazing angle the pixel's footprint in the texture is a long thin ellipse; GL's
// isotropic LOD blurs it to the long axis. Instead, N trilinear taps spread along the long axis, each at
// the LOD of max(minor axis, major axis / N). (llvmpipe's own anisotropic path: see context.anisotropy.)
vec3 sample_albedo(vec2 uv) {
#if TEXTURE_TAPS == 1
    return texture(u_albedo_tex, uv).rgb;
#else
    vec2 size = vec2(textureSize(u_albedo_tex, 0));
    vec2 dx = dFdx(uv), dy = dFdy(uv);
    float lx = length(dx * size), ly = length(dy * size);
    vec2 major = lx >= ly ? dx : dy;
    float n = float(TEXTURE_TAPS);
    float lod = log2(max(max(min(lx, ly), max(lx, ly) / n), 1.0));
    vec3 sum = vec3(0.0);
    for (int i = 0; i < TEXTURE_TAPS; ++i)
        sum += textureLod(u_albedo_tex, uv + major * ((float(i) + 0.5) / n - 0.5), lod).rgb;
    return sum / n;
#endif
}
#endif

void main() {
    vec3 albedo = u_albedo;
#if TEXTURE_TAPS > 0
    albedo *= sample_albedo(v_uv);
#endif
    vec3 n = normalize(v_normal);
    // two-sided: the shading normal faces the viewer (thin walls, glass panes)
    if (dot(n, u_camera_pos - v_world) < 0.0) n = -n;
    o_albedo = vec4(albedo, u_material_index);
    o_normal = vec4(n, u_specular);
    o_position = vec4(v_world, 1.0);
    o_material = u_material;
}
#endif
