// Sky lighting for the deferred passes (paper §5, §7): the paraboloid sky map and the sky irradiance
// volume. Mirrors serenity/kernels/atmosphere.py (sample_sky_map) and serenity/kernels/skylookup.py
// (the volume's lookup, SkyVolume.irradiance) exactly; tests/raster/test_sky_gl.py checks both.
//
// Sky map: 2-D RGB float texture uploaded without a row flip (array row i = texture row i), linear
// filtering, clamp to edge. (u, v) = ((d.x, d.z) / (1 + d.y) + 1) / 2, d.y clamped to >= 0 first.
//
// Sky volume: 7 3-D textures (6 RGBA + 1 RGB), width X, height Y, depth Z, linear filtering, clamp to
// edge, holding 27 irradiance SH coefficients per probe, flat index f = 3k + c (k = SH index 0..8,
// c = RGB channel): texture t < 6 holds f = 4t..4t+3, texture 6 holds f = 24..26.
//   g  = clamp((p + normal_offset * n - origin) / cell, 0, res - 1)     (grid units, probes at integers)
//   tc = (g + 0.5) / res                                                (trilinear between probes)
//   E  = max(0, sum_k c_k Y_k(n))                                       (W m^-2 per channel)
// Y_k: real L2 SH of Ramamoorthi & Hanrahan 2001 in world x, y, z (serenity/kernels/sh.py).
//
//   beyond the grid's sides and top the coefficients fade to the open sky's (u_sky_open: the 9 RGB
//   coefficients of an unoccluded probe) over SKY_OPEN_FADE_CELLS cells (the kernels' OPEN_FADE_CELLS)
// Uniforms set by serenity/raster/sky.py SkyTexturesGL.bind(program, first_unit):
//   sampler2D u_sky_map; sampler3D u_sky_volume[7]; vec3 u_sky_origin; vec3 u_sky_cell;
//   vec3 u_sky_res; float u_sky_normal_offset; vec3 u_sky_open[9]   (sky_irradiance(p, n) uses them)
//   sampler3D u_sky_vis (RG: the probes' octahedral depth moments, tiles of SKY_VIS_TILE² texels,
//   width X*T, height Y, depth Z*T), sampler3D u_sky_probe_offset (RGB, X, Y, Z: the probes' relocation)
// SKY_VISIBILITY (SkyConfig.gather_visibility with method "gather"): the 8 probes around the lookup are
// read one by one (texelFetch) and each weighed by whether it sees the point, as
// serenity/kernels/probegather.py's probe_visibility (DDGI's back-face weight and Chebyshev bound).
// Specular occlusion of the glossy term by the surface's own horizon: sky_horizon_occlusion(r, ng, m),
// the share of the Phong lobe (exponent m, around the mirror direction r) above the plane of the
// geometric normal ng, and gbuffer_flat_normal, ng from a G-buffer's positions.
#ifndef SERENITY_SKY_GLSL
#define SERENITY_SKY_GLSL
#include "common.glsl"

vec2 sky_paraboloid_uv(vec3 d) {
    d.y = max(d.y, 0.0);
    float len = length(d);
    if (len < 1e-12) { d = vec3(1.0, 0.0, 0.0); len = 1.0; }
    float k = 1.0 / (len + d.y);
    return vec2(0.5 * d.x * k + 0.5, 0.5 * d.z * k + 0.5);
}

vec3 sky_map_radiance(sampler2D sky_map, vec3 dir) {
    return texture(sky_map, sky_paraboloid_uv(dir)).rgb;
}

void sky_sh9(vec3 d, out float y[9]) {
    y[0] = 0.282094791773878;
    y[1] = 0.488602511902920 * d.y;
    y[2] = 0.488602511902920 * d.z;
    y[3] = 0.488602511902920 * d.x;
    y[4] = 1.092548430592079 * d.x * d.y;
    y[5] = 1.092548430592079 * d.y * d.z;
    y[6] = 0.315391565252520 * (3.0 * d.z * d.z - 1.0);
    y[7] = 1.092548430592079 * d.x * d.z;
    y[8] = 0.546274215296040 * (d.x * d.x - d.y * d.y);
}

#ifdef EXACT_FILTER
// Trilinear between the probes around grid point g (clamped to the grid) with float weights: the
// texture unit's 8-bit weights are too coarse for SH coefficients that cancel (raster/context.py).
#define SKY_TAP(t) trilinear_texels(t, gi0, gi1, g - vec3(gi0))
#else
#define SKY_TAP(t) texture(t, tc)
#endif

// The volume at surface point p with unit normal n: returns the irradiance E(p, n) (W m^-2) and
// writes to `glossy` the radiance around direction r filtered by the normalised Phong lobe of
// exponent m (W m^-2 sr^-1), both from the same 27 interpolated coefficients. The coefficients hold
// E_lm = A_l L_lm (A_l = pi, 2 pi / 3, pi / 4: the clamped cosine, times SkyConfig.window's factors);
// the Phong lobe's are 1, (m + 1) / (m + 2), m / (m + 3), so the glossy term weighs band l by
// lobe_l / A_l (serenity/kernels/skylookup.py, glossy_band_factors). Both clamped at 0.
const float SKY_OPEN_FADE_CELLS = 2.0;

#ifndef SKY_VISIBILITY
#define SKY_VISIBILITY 0
#endif
#if SKY_VISIBILITY
const int SKY_VIS_OCT = 8;
const int SKY_VIS_TILE = SKY_VIS_OCT + 2;
const float SKY_VIS_CRUSH = 0.2;
const float SKY_VIS_BIAS_CELLS = 0.5;
uniform sampler3D u_sky_vis;
uniform sampler3D u_sky_probe_offset;

vec2 sky_oct_encode(vec3 d) {
    vec2 o = d.xz / (abs(d.x) + abs(d.y) + abs(d.z));
    if (d.y < 0.0) o = (1.0 - abs(o.yx)) * vec2(o.x >= 0.0 ? 1.0 : -1.0, o.y >= 0.0 ? 1.0 : -1.0);
    return o;
}

// Weight of the probe in grid cell c (at grid_pos, moved by its relocation offset) for surface point p
// with normal n, looked up at x (skylookup.probe_visibility).
float sky_probe_visibility(ivec3 c, vec3 grid_pos, vec3 p, vec3 x, vec3 n) {
    vec3 q = grid_pos + texelFetch(u_sky_probe_offset, c, 0).xyz;
    float b = (dot(normalize(q - p), n) + 1.0) * 0.5;
    float w = b * b + 0.2;
    vec3 d = x - q;
    float dist = length(d);
    vec2 uv = sky_oct_encode(d / max(dist, 1e-9));
    vec2 t = vec2(c.xz * SKY_VIS_TILE + 1) + (uv * 0.5 + 0.5) * float(SKY_VIS_OCT) - 0.5;
    ivec2 t0 = ivec2(floor(t));
    vec2 f = t - vec2(t0);
    ivec2 lo = c.xz * SKY_VIS_TILE, hi = lo + SKY_VIS_TILE - 1;
    ivec2 a = clamp(t0, lo, hi), b1 = clamp(t0 + 1, lo, hi);
    vec2 m = mix(mix(texelFetch(u_sky_vis, ivec3(a.x, c.y, a.y), 0).xy,
                     texelFetch(u_sky_vis, ivec3(b1.x, c.y, a.y), 0).xy, f.x),
                 mix(texelFetch(u_sky_vis, ivec3(a.x, c.y, b1.y), 0).xy,
                     texelFetch(u_sky_vis, ivec3(b1.x, c.y, b1.y), 0).xy, f.x), f.y);
    if (dist > m.x) {
        float var = abs(m.y - m.x * m.x);
        float e = dist - m.x;
        float ch = var / (var + e * e + 1e-12);
        w *= max(ch * ch * ch, 0.0);
    }
    w = max(w, 1e-6);
    if (w < SKY_VIS_CRUSH) w = w * w * w / (SKY_VIS_CRUSH * SKY_VIS_CRUSH);
    return w;
}
#endif

vec3 sky_volume_lookup(sampler3D tex[7], vec3 open_sky[9], vec3 p, vec3 n, vec3 r, float m, vec3 origin, vec3 cell,
                       vec3 res, float normal_offset, out vec3 glossy) {
    vec3 xq = p + normal_offset * n;
    vec3 gr = (xq - origin) / cell;
    vec3 beyond = max(-gr, gr - (res - 1.0));
    float w_open = clamp(max(max(beyond.x, beyond.z), gr.y - (res.y - 1.0)) / SKY_OPEN_FADE_CELLS, 0.0, 1.0);
    vec3 g = clamp(gr, vec3(0.0), res - 1.0);
    vec3 tc = (g + 0.5) / res;
#ifdef EXACT_FILTER
    ivec3 gi0 = ivec3(floor(g));
    ivec3 gi1 = min(gi0 + 1, ivec3(res) - 1);
#endif
    float f[28];
#if SKY_VISIBILITY
    for (int k = 0; k < 28; ++k) f[k] = 0.0;
    ivec3 c0 = ivec3(floor(g));
    ivec3 cmax = ivec3(res) - 1;
    vec3 a = g - vec3(c0);
    float wsum = 0.0;
    vec3 x_vis = p + SKY_VIS_BIAS_CELLS * min(cell.x, min(cell.y, cell.z)) * n;
    for (int corner = 0; corner < 8; ++corner) {
        ivec3 dc = ivec3(corner & 1, (corner >> 1) & 1, corner >> 2);
        ivec3 c = min(c0 + dc, cmax);
        vec3 tw = mix(1.0 - a, a, vec3(dc));
        float w = tw.x * tw.y * tw.z * sky_probe_visibility(c, origin + vec3(c) * cell, p, x_vis, n);
        wsum += w;
        for (int t = 0; t < 6; ++t) {
            vec4 v = w * texelFetch(tex[t], c, 0);
            f[4 * t + 0] += v.x; f[4 * t + 1] += v.y; f[4 * t + 2] += v.z; f[4 * t + 3] += v.w;
        }
        vec3 last = w * texelFetch(tex[6], c, 0).rgb;
        f[24] += last.x; f[25] += last.y; f[26] += last.z;
    }
    for (int k = 0; k < 27; ++k) f[k] /= max(wsum, 1e-30);
#else
    for (int t = 0; t < 6; ++t) {
        vec4 v = SKY_TAP(tex[t]);
        f[4 * t + 0] = v.x; f[4 * t + 1] = v.y; f[4 * t + 2] = v.z; f[4 * t + 3] = v.w;
    }
    vec3 last = SKY_TAP(tex[6]).rgb;
    f[24] = last.x; f[25] = last.y; f[26] = last.z; f[27] = 0.0;
#endif
    float y[9], yr[9];
    sky_sh9(n, y);
    sky_sh9(r, yr);
    vec3 band = vec3(1.0 / PI, 1.5 * (m + 1.0) / ((m + 2.0) * PI), 4.0 * m / ((m + 3.0) * PI));
    vec3 e = vec3(0.0), l = vec3(0.0);
    for (int k = 0; k < 9; ++k) {
        vec3 c = mix(vec3(f[3 * k], f[3 * k + 1], f[3 * k + 2]), open_sky[k], w_open);
        e += y[k] * c;
        l += yr[k] * (k == 0 ? band.x : (k < 4 ? band.y : band.z)) * c;
    }
    glossy = max(l, vec3(0.0));
    return max(e, vec3(0.0));
}

vec3 sky_volume_irradiance(sampler3D tex[7], vec3 open_sky[9], vec3 p, vec3 n, vec3 origin, vec3 cell, vec3 res,
                           float normal_offset) {
    vec3 unused;
    return sky_volume_lookup(tex, open_sky, p, n, n, 0.0, origin, cell, res, normal_offset, unused);
}

// Specular occlusion by the horizon. A mesh's interpolated (shading) normals bend away from its flat faces
// where they are averaged across a corner: a table's apron smoothed into its legs leans 50 degrees off its
// face, and its mirror direction r points into the table. The light from there cannot reach the face: a
// path tracer's reflected ray goes into the object and finds it dark inside. The normalised Phong lobe
// cos^m around r is close to a 2-D Gaussian of standard deviation 1/sqrt(m + 1) per axis, so the share
// of it above the plane with normal ng is Phi(dot(r, ng) * sqrt(m + 1)) (Phi: the normal CDF, here the
// logistic 1 / (1 + exp(-1.7 x)), within 0.01 of it): 0.5 with r in the plane, about 0 with r a lobe's
// width below it. Where the shading normal is the flat one (ng = n), dot(r, n) = dot(v, n): only a
// grazing view loses a little.
float sky_horizon_occlusion(vec3 r, vec3 ng, float m) {
    return 1.0 / (1.0 + exp(-1.7 * dot(r, ng) * sqrt(max(m, 0.0) + 1.0)));
}

// The flat (geometric) normal at pixel q of a G-buffer's positions (xyz world, w = 0 where nothing is
// drawn), with point p and shading normal n there: the cross product of a tangent per image axis, turned
// to n's side. An axis's tangent is the central difference of its two neighbours where they lie on a line
// through p (their differences from p agree within a quarter of their lengths), else the difference to
// the nearer one (p on a silhouette or a crease: the neighbour on p's own face). One axis may be one-sided,
// not both: the two one-sided tangents of a wire a few pixels wide both run along the wire, and the
// normal they span has nothing to do with the wire's faces. n itself (no occlusion beyond the grazing
// view's) at the image border, where both axes are one-sided, or where the tangents are less than
// 15 degrees apart.
vec3 gbuffer_flat_tangent(vec4 after, vec4 before, vec3 p, out bool central) {
    vec3 a = after.w == 0.0 ? vec3(1e15) : after.xyz - p, b = before.w == 0.0 ? vec3(1e15) : p - before.xyz;
    central = length(a - b) <= 0.25 * (length(a) + length(b));
    return central ? a + b : (dot(a, a) < dot(b, b) ? a : b);
}

vec3 gbuffer_flat_normal(sampler2D positions, ivec2 q, vec3 p, vec3 n) {
    ivec2 hi = textureSize(positions, 0) - 1;
    if (any(lessThan(q, ivec2(1))) || any(greaterThan(q, hi - 1))) return n;
    bool cx, cy;
    vec3 tx = gbuffer_flat_tangent(texelFetch(positions, q + ivec2(1, 0), 0), texelFetch(positions, q - ivec2(1, 0), 0),
                                   p, cx);
    vec3 ty = gbuffer_flat_tangent(texelFetch(positions, q + ivec2(0, 1), 0), texelFetch(positions, q - ivec2(0, 1), 0),
                                   p, cy);
    if (!(cx || cy) || max(dot(tx, tx), dot(ty, ty)) > 1e20) return n;
    vec3 c = cross(tx, ty);
    float l = length(c);
    if (!(l > 0.25 * length(tx) * length(ty))) return n;
    c /= l;
    return dot(c, n) < 0.0 ? -c : c;
}

uniform sampler2D u_sky_map;
uniform sampler3D u_sky_volume[7];
uniform vec3 u_sky_origin;
uniform vec3 u_sky_cell;
uniform vec3 u_sky_res;
uniform float u_sky_normal_offset;
uniform vec3 u_sky_open[9];

// The volume's irradiance at surface point p with unit normal n, using the uniforms above.
vec3 sky_irradiance(vec3 p, vec3 n) {
    return sky_volume_irradiance(u_sky_volume, u_sky_open, p, n, u_sky_origin, u_sky_cell, u_sky_res,
                                 u_sky_normal_offset);
}

// The same, and the glossy radiance around r for Phong exponent m (sky_volume_lookup).
vec3 sky_irradiance_glossy(vec3 p, vec3 n, vec3 r, float m, out vec3 glossy) {
    return sky_volume_lookup(u_sky_volume, u_sky_open, p, n, r, m, u_sky_origin, u_sky_cell, u_sky_res,
                             u_sky_normal_offset, glossy);
}

#endif
