// The viewer's temporal anti-aliasing on a still view: the running mean of jittered HDR frames.
// Drawn with blending SRC_ALPHA, ONE_MINUS_SRC_ALPHA onto the mean of the n frames so far with
// alpha = 1 / (n + 1): mean' = mean + (x - mean) / (n + 1) (alpha 1 starts it afresh).
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_frame;   // this frame's HDR (linear radiance)
uniform float u_weight;      // 1 / (samples after this one)
out vec4 o_mean;

void main() {
    o_mean = vec4(texelFetch(u_frame, ivec2(gl_FragCoord.xy), 0).rgb, u_weight);
}
#endif
