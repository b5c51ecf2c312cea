// G-buffer pass: one draw per material range. Outputs (all float targets, linear):
//   0 albedo   rgb = linear albedo (material colour x texture), a = material index
//   1 normal   xyz = world shading normal facing the camera, w = Phong specular strength k_s
//   2 position xyz = world position (m), w = 1 where covered (0 = background)
//   3 material x = Phong exponent, y = reflectivity, z = transparency, w = index of refraction
// Variants (compiled in, GBufferPass keeps one program per combination it draws): TEXTURE_TAPS (below);
// ALPHA_MASK = 1: a cut-out (glTF alphaMode MASK) — a fragment whose coverage u_alpha x the albedo
// texture's alpha is below u_alpha_cutoff is discarded; NORMAL_MAP = 1: the shading normal comes from a
// tangent-space normal map (per-vertex tangents, xyz and handedness w). Texture coordinates go through
// the material's uv transforms (KHR_texture_transform) first.
#ifndef ALPHA_MASK
#define ALPHA_MASK 0
#endif
#ifndef NORMAL_MAP
#define NORMAL_MAP 0
#endif
#define SCENE_VERTEX_UV
#if NORMAL_MAP
#define SCENE_VERTEX_TANGENT
#endif
#include "scene_vertex.glsl"

#if defined FRAGMENT_SHADER
in vec3 v_world;
in vec3 v_normal;
in vec2 v_uv;
#if NORMAL_MAP
in vec4 v_tangent;
uniform sampler2D u_normal_tex;
uniform vec3 u_normal_uv0, u_normal_uv1;   // the normal map's uv transform, rows of a 2x3 matrix
uniform mat2 u_normal_frame;               // turns the map's xy into the untransformed uvs' tangent frame
uniform float u_normal_scale;
#endif
uniform vec3 u_albedo_uv0, u_albedo_uv1;   // the albedo (and alpha) texture's uv transform
#if ALPHA_MASK
uniform float u_alpha;
uniform float u_alpha_cutoff;
#endif
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
    vec2 uv = vec2(dot(u_albedo_uv0, vec3(v_uv, 1.0)), dot(u_albedo_uv1, vec3(v_uv, 1.0)));
#if ALPHA_MASK
    if (u_alpha * texture(u_albedo_tex, uv).a < u_alpha_cutoff) discard;
#endif
    albedo *= sample_albedo(uv);
#endif
    vec3 n = normalize(v_normal);
    // two-sided: the shading normal faces the viewer (thin walls, glass panes)
    float side = dot(n, u_camera_pos - v_world) < 0.0 ? -1.0 : 1.0;
#if NORMAL_MAP
    vec2 uvn = vec2(dot(u_normal_uv0, vec3(v_uv, 1.0)), dot(u_normal_uv1, vec3(v_uv, 1.0)));
    vec3 tn = texture(u_normal_tex, uvn).xyz * 2.0 - 1.0;
    tn.xy = u_normal_frame * (tn.xy * u_normal_scale);
    vec3 t = v_tangent.xyz - n * dot(n, v_tangent.xyz);
    float lt = length(t);
    if (lt > 1e-8) {
        t /= lt;
        vec3 b = cross(n, t) * (v_tangent.w < 0.0 ? -1.0 : 1.0);
        vec3 nm = t * tn.x + b * tn.y + n * tn.z;
        if (dot(nm, nm) > 1e-12) n = normalize(nm);
    }
#endif
    n *= side;
    o_albedo = vec4(albedo, u_material_index);
    o_normal = vec4(n, u_specular);
    o_position = vec4(v_world, 1.0);
    // the ior's sign: which side of the surface the viewer sees (negative: its back), for the
    // ray-casting buffer's refraction (raycast.glsl); n faces the viewer either way
    o_material = vec4(u_material.xyz, side * u_material.w);
}
#endif
