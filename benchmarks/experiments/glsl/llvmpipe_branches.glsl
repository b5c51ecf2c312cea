// bench_llvmpipe_branches.py: a full-screen triangle whose fragment shader does BODY (12 steps of one
// kind of work) placed as PLACEMENT (#defines: serenity.raster.context.compile_program prepends them).
//   BODY 0: 12 texture taps in a loop of compile-time length (unrolled)
//        1: the same loop with a run-time trip count (12 + u_zero: not unrolled)
//        2: 12 steps of arithmetic (unrolled)
//   PLACEMENT 0: no body; 1: always; 2: inside `if` on a uniform no pixel satisfies; 3: inside `if` on
//        the pixel's x (the right half takes it); 4: after an early `return` every pixel takes;
//        5: inside a loop whose run-time trip count is 0
#if defined VERTEX_SHADER
out vec2 v_uv;
void main() {
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2);
    v_uv = p;
    gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0);
}
#endif

#if defined FRAGMENT_SHADER
in vec2 v_uv;
uniform sampler2D u_tex;
uniform float u_flag;   // 0: the uniform conditions are false
uniform int u_zero;     // 0, unknown to the compiler
layout(location = 0) out vec4 o_colour;

#if BODY == 0
#define WORK for (int k = 0; k < 12; ++k) acc += texture(u_tex, v_uv + vec2(k) * 0.001);
#elif BODY == 1
#define WORK for (int k = 0; k < 12 + u_zero; ++k) acc += texture(u_tex, v_uv + vec2(k) * 0.001);
#else
#define WORK for (int k = 0; k < 12; ++k) acc = sin(acc) * 1.01 + vec4(v_uv, 0.0, 0.0);
#endif

void main() {
    vec4 acc = vec4(0.0);
#if PLACEMENT == 1
    WORK
#elif PLACEMENT == 2
    if (u_flag > 0.5) { WORK }
#elif PLACEMENT == 3
    if (v_uv.x > 0.5) { WORK }
#elif PLACEMENT == 4
    if (u_flag < 0.5) { o_colour = vec4(1.0); return; }
    WORK
#elif PLACEMENT == 5
    for (int j = 0; j < u_zero; ++j) { WORK }
#endif
    o_colour = acc + vec4(v_uv, 0.0, 1.0);
}
#endif
