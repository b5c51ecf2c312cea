// Which full-resolution pixels the upsampled low-res indirect light cannot stand for
// (raster/lowres.IndirectRefinement): those whose best low-res match (lowres_best_similarity, over
// the 2x2 texels upsample.glsl reads) is below u_refine_below — a table's rounded edge, a chair's
// leg, the far side of a silhouette, where the upsampling would paint the neighbouring surface's
// light. Per pixel: colour 0 (the refinement's targets cleared) with alpha 1 where refined, and the
// pixel's class as its depth (lowres.glsl's LOWRES_DEPTH_*: glossy, surface, or none), so that the
// indirect passes, drawn over it at scale 1 with the depth test ">", shade the refined pixels only.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "lowres.glsl"
uniform sampler2D g_position;
uniform sampler2D g_normal;
uniform sampler2D u_guide;          // the low-res guide (lowres_guide.glsl), laid out by lowres.glsl's uniforms
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
uniform float u_refine_below;
layout(location = 0) out vec4 o_irr;
layout(location = 1) out vec4 o_gloss;
void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    vec4 p = texelFetch(g_position, px, 0);
    o_gloss = vec4(0.0);
    o_irr = vec4(0.0);
    gl_FragDepth = LOWRES_DEPTH_BACKGROUND;
    if (p.w == 0.0) return;
    vec4 nrm = texelFetch(g_normal, px, 0);
    float z = dot(p.xyz - u_camera_pos, u_camera_forward);
    if (lowres_best_similarity(u_guide, px, z, nrm.xyz) >= u_refine_below) return;
    o_irr.a = 1.0;
    gl_FragDepth = nrm.w >= GLOSSY_MIN_SPECULAR ? LOWRES_DEPTH_GLOSSY : LOWRES_DEPTH_SURFACE;
}
#endif
