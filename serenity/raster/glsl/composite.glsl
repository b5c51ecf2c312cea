// Composite of the ray-traced effect buffers over the lit main view (paper §9, Fig. 18-19), with
// Schlick's Fresnel term. Per pixel (material from the main G-buffer, v = view direction):
//   glass (transparency T > 0): F = schlick(((ior-1)/(ior+1))^2, cos) (1 under total internal
//        reflection);  L = T * (F * L_reflection + (1 - F) * L_refraction) + (1 - T) * L_surface
//        — a fraction T of the pane is clear glass (Fresnel reflection + refraction), the rest its
//        Phong surface: the reference's blendbsdf(T, phong, dielectric) (eval/reference.py)
//   mirror / metal (reflectivity R > 0, T = 0): F = schlick(R, cos);
//        L = F * L_reflection + (1 - F) * L_surface
// A pixel whose reflection (or refraction) ray was not traced (RayTracingConfig.reflections /
// .refractions off) has L_reflection (L_refraction) = L_surface: the rasterised surface stands in.
//
// Drawn in place, into the lit main view, as one point per pixel of the ray-casting buffer (the
// only pixels it changes): the fragment outputs the traced part of L premultiplied, rgb = Σ w_i L_i
// over the traced rays, and a = the weight left on L_surface, and the blend (ONE, SRC_ALPHA) adds
// it to a * L_surface already in the target. On a CPU rasteriser a pass costs its pixels: a
// fullscreen composite cost ~10 ms at 640×360 for ~4k traced pixels.
#include "common.glsl"

#if defined VERTEX_SHADER
in vec3 in_point;               // flat pixel index (row 0 = top), reflection texel, refraction texel
uniform ivec2 u_size;           // the view, pixels
flat out vec2 v_rays;
void main() {
    int p = int(in_point.x);
    int row = p / u_size.x;
    vec2 pixel = vec2(float(p - row * u_size.x), float(u_size.y - 1 - row)) + 0.5;
    gl_Position = vec4(pixel / vec2(u_size) * 2.0 - 1.0, 0.0, 1.0);
    gl_PointSize = 1.0;
    v_rays = in_point.yz;
}
#elif defined FRAGMENT_SHADER
flat in vec2 v_rays;            // packed texel of the reflection, the refraction; -1 none, -2 TIR
uniform sampler2D u_effects;    // the lit traced rays (HDR), packed: ray k at texel (k mod W, k div W)
uniform sampler2D g_normal;
uniform sampler2D g_position;
uniform sampler2D g_material;   // shininess, reflectivity, transparency, ior
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
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 pos = texelFetch(g_position, px, 0);
    vec4 mat = texelFetch(g_material, px, 0);
    vec3 n = normalize(texelFetch(g_normal, px, 0).xyz);
    float cos_t = abs(dot(n, normalize(u_camera_pos - pos.xyz)));
    bool has_refl = v_rays.x >= 0.0;
    bool has_refr = v_rays.y >= 0.0;
    vec3 rgb = vec3(0.0);
    float keep = 1.0;                  // weight of L_surface
    float transparency = mat.z;
    if (transparency > 0.0) {
        float ior = abs(mat.w);  // its sign is the side seen (gbuffer.glsl)
        float f0 = pow((ior - 1.0) / (ior + 1.0), 2.0);
        float F = v_rays.y < -1.5 ? 1.0 : schlick(f0, cos_t);
        float wr = transparency * F;
        if (has_refl) { rgb += wr * traced(v_rays.x); keep -= wr; }
        float wt = transparency * (1.0 - F);
        if (has_refr) { rgb += wt * traced(v_rays.y); keep -= wt; }
    } else {
        float F = schlick(mat.y, cos_t);
        if (has_refl) { rgb += F * traced(v_rays.x); keep -= F; }
    }
    o_hdr = vec4(rgb, keep);
}
#endif
