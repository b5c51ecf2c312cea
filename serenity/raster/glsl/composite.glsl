// Composite of the ray-traced effect buffers over the lit main view (paper §9, Fig. 18-19), with
// Schlick's Fresnel term. Per pixel (material from the main G-buffer, v = view direction):
//   glass (transparency T > 0): F = schlick(((ior-1)/(ior+1))^2, cos) (1 under total internal
//        reflection);  L = F * L_reflection + (1 - F) * (T * L_refraction + (1 - T) * L_surface)
//   mirror / metal (reflectivity R > 0, T = 0): F = schlick(R, cos);
//        L = F * L_reflection + (1 - F) * L_surface
// A pixel whose reflection (or refraction) ray was not traced (RenderConfig.reflections /
// .refractions off) has L_reflection (L_refraction) = L_surface: the rasterised surface stands in.
// Drawn as one fullscreen pass over the G-buffer rather than a second forward pass over the
// reflective meshes: the G-buffer already holds every attribute the forward pass would compute.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_surface;      // lit main view (HDR)
uniform sampler2D u_effects;      // the lit traced rays (HDR), packed: ray k at texel (k mod W, k div W)
uniform sampler2D u_index;        // per pixel: packed texel of its reflection (r), refraction (g); -1 none,
                                  // g = -2: total internal reflection (no refraction, F = 1)
uniform sampler2D g_normal;
uniform sampler2D g_position;
uniform sampler2D g_material;     // shininess, reflectivity, transparency, ior
uniform vec3 u_camera_pos;
out vec4 o_hdr;

vec3 traced(float k) {
    int w = textureSize(u_effects, 0).x;
    int i = int(k);
    return texelFetch(u_effects, ivec2(i % w, i / w), 0).rgb;
}

float schlick(float f0, float cos_theta) {
    float m = clamp(1.0 - cos_theta, 0.0, 1.0);
    return f0 + (1.0 - f0) * m * m * m * m * m;
}

void main() {
    vec3 surface = texture(u_surface, v_uv).rgb;
    vec4 pos = texture(g_position, v_uv);
    vec2 index = texture(u_index, v_uv).rg;
    // no traced ray (and no total internal reflection): the formulas below give the surface
    if (pos.w == 0.0 || (index.r < 0.0 && index.g > -1.5)) { o_hdr = vec4(surface, 1.0); return; }
    vec4 mat = texture(g_material, v_uv);
    vec3 n = normalize(texture(g_normal, v_uv).xyz);
    float cos_t = abs(dot(n, normalize(u_camera_pos - pos.xyz)));
    vec3 refl = index.r >= 0.0 ? traced(index.r) : surface;
    float transparency = mat.z;
    if (transparency > 0.0) {
        float f0 = pow((mat.w - 1.0) / (mat.w + 1.0), 2.0);
        float F = index.g < -1.5 ? 1.0 : schlick(f0, cos_t);
        vec3 refr = index.g >= 0.0 ? traced(index.g) : surface;
        o_hdr = vec4(F * refl + (1.0 - F) * (transparency * refr + (1.0 - transparency) * surface), 1.0);
    } else {
        float F = schlick(mat.y, cos_t);
        o_hdr = vec4(F * refl + (1.0 - F) * surface, 1.0);
    }
}
#endif
