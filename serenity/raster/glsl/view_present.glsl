// The viewer's present pass: one of the renderer's textures (or two, side by side at a split
// line) drawn into the window, nearest-texel so that a window the size of the render shows the
// image bit for bit. Modes: 0 display values as stored (the tone-mapped RGBA8 image, a FLIP map),
// 1 HDR radiance tone-mapped like tonemap.glsl, 2 signed vectors as 0.5 + 0.5 v (normals),
// 3 linear [0, 1] colours sRGB-encoded (albedo), 4 the red channel as grey (AO, ray mask).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_a;
uniform sampler2D u_b;
uniform int u_mode_a;
uniform int u_mode_b;
uniform float u_exposure;
uniform float u_split;       // x in [0, 1] where B starts; > 1: A only
uniform float u_line_px;     // split line half width, in uv units of x
uniform int u_block_a;       // > 1: A is a 1/u_block_a resolution image of the render (texel = pixel / block)
uniform ivec2 u_render_size; // the render's size in pixels (for u_block_a)
out vec4 o_color;

vec3 show(sampler2D tex, int mode, int block) {
    ivec2 size = textureSize(tex, 0);
    ivec2 t = block > 1 ? ivec2(floor(v_uv * vec2(u_render_size))) / block : ivec2(floor(v_uv * vec2(size)));
    t = clamp(t, ivec2(0), size - 1);
    vec3 c = texelFetch(tex, t, 0).rgb;
    if (mode == 1) {
        c = max(c, vec3(0.0)) * u_exposure;
        float lw = luminance(c);
        return linear_to_srgb(lw > 0.0 ? c * (1.0 / (1.0 + lw)) : vec3(0.0));
    }
    if (mode == 2) return clamp(0.5 + 0.5 * c, 0.0, 1.0);
    if (mode == 3) return linear_to_srgb(c);
    if (mode == 4) return vec3(clamp(c.r, 0.0, 1.0));
    return c;
}

void main() {
    vec3 c = v_uv.x < u_split ? show(u_a, u_mode_a, u_block_a) : show(u_b, u_mode_b, 1);
    if (u_split <= 1.0 && abs(v_uv.x - u_split) < u_line_px) c = vec3(1.0, 0.8, 0.2);
    o_color = vec4(c, 1.0);
}
#endif
