// Screen-space ambient occlusion (paper §3), marched along cosine-distributed rays so that it
// estimates the same quantity as ray-traced AO of radius R:
//   AO(p) = 1 - (1/N) sum_i blocked(p, w_i),  w_i ~ cos(theta)/pi on the hemisphere around n,
// where a ray counts as blocked when one of its S march points (at t = R (j + 0.5) / S) lies behind
// the surface seen there (below its tangent plane) by more than `bias`, and behind it in depth by
// less than `thickness` (the depth buffer has no
// back faces, so a thin object in front must not block everything behind it).
// Output: AO in [0, 1] (1 = open). Applied to indirect light only. Runs at 1/u_scale resolution
// (lowres.glsl): each output pixel is the AO of its representative G-buffer pixel.
#include "fullscreen.glsl"

#if defined FRAGMENT_SHADER
#include "lowres.glsl"
uniform sampler2D g_position;   // world xyz, w = covered
uniform sampler2D g_normal;     // world normal
uniform mat4 u_view_proj;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
uniform float u_radius;         // metres
uniform float u_bias;           // metres
uniform float u_thickness;      // metres
uniform int u_directions;
uniform int u_steps;
out float o_ao;

float ign(vec2 pixel) { return fract(52.9829189 * fract(dot(pixel, vec2(0.06711056, 0.00583715)))); }

void main() {
    ivec2 low = lowres_pixel();
    ivec2 px = representative_pixel(low, textureSize(g_position, 0));
    vec4 pw = texelFetch(g_position, px, 0);
    if (pw.w == 0.0) { o_ao = 1.0; return; }
    vec3 p = pw.xyz;
    vec3 n = normalize(texelFetch(g_normal, px, 0).xyz);
    vec3 t = normalize(abs(n.y) < 0.99 ? cross(n, vec3(0.0, 1.0, 0.0)) : cross(n, vec3(1.0, 0.0, 0.0)));
    vec3 b = cross(n, t);
    float phi = 6.2831853 * ign(vec2(low) + 0.5);
    float jitter = ign(vec2(low.yx) + 17.5);
    int blocked = 0;
    for (int i = 0; i < u_directions; ++i) {
        // cosine-weighted direction: Vogel point in the unit disc lifted to the hemisphere
        float r = sqrt((float(i) + 0.5) / float(u_directions));
        float a = float(i) * 2.39996323 + phi;
        vec2 d2 = r * vec2(cos(a), sin(a));
        vec3 w = normalize(d2.x * t + d2.y * b + sqrt(max(0.0, 1.0 - dot(d2, d2))) * n);
        for (int j = 0; j < u_steps; ++j) {
            float dist = u_radius * (float(j) + jitter) / float(u_steps);
            vec3 s = p + n * u_bias + w * dist;
            vec4 c = u_view_proj * vec4(s, 1.0);
            if (c.w <= 0.0) break;
            vec2 uv = c.xy / c.w * 0.5 + 0.5;
            if (any(lessThan(uv, vec2(0.0))) || any(greaterThan(uv, vec2(1.0)))) break;
            vec4 q = texture(g_position, uv);
            if (q.w == 0.0) continue;
            // behind the surface seen at uv: below its tangent plane (robust to the pixel footprint
            // on slanted receivers) and not farther behind it than the assumed thickness
            vec3 nq = texture(g_normal, uv).xyz;
            float below = -dot(s - q.xyz, nq);
            float z_s = dot(s - u_camera_pos, u_camera_forward);
            float z_q = dot(q.xyz - u_camera_pos, u_camera_forward);
            if (below > u_bias && z_s - z_q > 0.0 && z_s - z_q < u_thickness) { blocked++; break; }
        }
    }
    o_ao = 1.0 - float(blocked) / float(u_directions);
}
#endif
