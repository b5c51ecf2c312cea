// The cut-out test of the light-view passes (shadow_depth.glsl, rsm.glsl), included in their fragment
// shaders: with ALPHA_MASK = 1, discard_cut_out() discards a fragment whose coverage u_alpha x the
// albedo texture's alpha, at the uv through the material's uv transform (KHR_texture_transform), is
// below u_alpha_cutoff (glTF alphaMode MASK).
#if ALPHA_MASK
in vec2 v_uv;
uniform sampler2D u_albedo_tex;
uniform vec3 u_albedo_uv0, u_albedo_uv1;
uniform float u_alpha;
uniform float u_alpha_cutoff;
void discard_cut_out() {
    vec2 uv = vec2(dot(u_albedo_uv0, vec3(v_uv, 1.0)), dot(u_albedo_uv1, vec3(v_uv, 1.0)));
    if (u_alpha * texture(u_albedo_tex, uv).a < u_alpha_cutoff) discard;
}
#endif
