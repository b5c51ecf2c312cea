// The low-resolution passes' guide (lowres.glsl): per low-res texel, the shading normal and view
// depth of its representative G-buffer pixel — what the SSAO blur (bilateral_blur.glsl) and the
// joint bilateral upsampling (upsample.glsl) weigh their taps by. Computed once per frame, so a tap
// reads one texel instead of the G-buffer's position and normal and a dot product.
//   xyz = the G-buffer normal as stored (not renormalised), w = view depth (m) along the camera
//   axis; w = -1 where the representative is background. Depth: the texel's class (lowres.glsl).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "lowres.glsl"
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
out vec4 o_guide;
void main() {
    ivec2 rq = representative_pixel(lowres_pixel(), textureSize(g_position, 0));
    vec4 p = texelFetch(g_position, rq, 0);
    if (p.w == 0.0) {
        o_guide = vec4(0.0, 0.0, 0.0, -1.0);
        gl_FragDepth = LOWRES_DEPTH_BACKGROUND;
        return;
    }
    vec4 nrm = texelFetch(g_normal, rq, 0);
    o_guide = vec4(nrm.xyz, dot(p.xyz - u_camera_pos, u_camera_forward));
    gl_FragDepth = nrm.w >= GLOSSY_MIN_SPECULAR ? LOWRES_DEPTH_GLOSSY : LOWRES_DEPTH_SURFACE;
}
#endif
