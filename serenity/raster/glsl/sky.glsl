// Sky lighting for the deferred passes (paper §5, §7): the paraboloid sky map and the sky irradiance
// volume. Mirrors serenity/kernels/atmosphere.py (sample_sky_map) and serenity/kernels/skyvolume.py
// (SkyVolume.irradiance) exactly; tests/raster/test_sky_gl.py checks both.
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
// lobe_l / A_l (serenity/kernels/skyvolume.py, glossy_band_factors). Both clamped at 0.
const float SKY_OPEN_FADE_CELLS = 2.0;

vec3 sky_volume_lookup(sampler3D tex[7], vec3 open_sky[9], vec3 p, vec3 n, vec3 r, float m, vec3 origin, vec3 cell,
                       vec3 res, float normal_offset, out vec3 glossy) {
    vec3 gr = (p + normal_offset * n - origin) / cell;
    vec3 beyond = max(-gr, gr - (res - 1.0));
    float w_open = clamp(max(max(beyond.x, beyond.z), gr.y - (res.y - 1.0)) / SKY_OPEN_FADE_CELLS, 0.0, 1.0);
    vec3 g = clamp(gr, vec3(0.0), res - 1.0);
    vec3 tc = (g + 0.5) / res;
#ifdef EXACT_FILTER
    ivec3 gi0 = ivec3(floor(g));
    ivec3 gi1 = min(gi0 + 1, ivec3(res) - 1);
#endif
    float f[28];
    for (int t = 0; t < 6; ++t) {
        vec4 v = SKY_TAP(tex[t]);
        f[4 * t + 0] = v.x; f[4 * t + 1] = v.y; f[4 * t + 2] = v.z; f[4 * t + 3] = v.w;
    }
    vec3 last = SKY_TAP(tex[6]).rgb;
    f[24] = last.x; f[25] = last.y; f[26] = last.z; f[27] = 0.0;
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
