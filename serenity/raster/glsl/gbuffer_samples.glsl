// Every u_stride-th G-buffer pixel (from u_first, in image rows top-down and columns), gathered into
// a small target so the host reads back only those pixels (the LPV's sky VPLs and surfels) instead
// of whole G-buffer images. Output texel (i, row j from the top) = G-buffer image pixel
// (u_first + u_stride i, u_first + u_stride j); GL rows run bottom-up on both sides.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform sampler2D g_albedo;
uniform int u_first;
uniform int u_stride;
uniform int u_rows_out;       // rows of the output target
layout(location = 0) out vec4 o_position;
layout(location = 1) out vec4 o_normal;
layout(location = 2) out vec4 o_albedo;
void main() {
    ivec2 full = textureSize(g_position, 0);
    ivec2 out_px = ivec2(gl_FragCoord.xy);
    int j = u_rows_out - 1 - out_px.y;
    ivec2 src = ivec2(u_first + u_stride * out_px.x, full.y - 1 - (u_first + u_stride * j));
    o_position = texelFetch(g_position, src, 0);
    o_normal = texelFetch(g_normal, src, 0);
    o_albedo = texelFetch(g_albedo, src, 0);
}
#endif
