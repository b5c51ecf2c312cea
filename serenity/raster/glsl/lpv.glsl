// Light propagation volume lookups (paper §8, Fig. 10): the GLSL twin of lookup_irradiance and
// lookup_glossy in serenity/kernels/lpv/kernels.py; serenity/kernels/lpv/__init__.py states the SH convention and
// units. Mirror any change there. Include it in a fragment shader and call
//   vec3 lpv_irradiance(vec3 p, vec3 n)           // W m^-2, >= 0: diffuse irradiance at p, normal n
//   vec3 lpv_glossy(vec3 p, vec3 r, float m)      // W m^-2 sr^-1: radiance from around direction r,
//                                                 // prefiltered by a normalised Phong lobe cos^m
// Uniforms are set by serenity.raster.lpv_gl.LPVTexturesGL.bind.
//
// Three RGBA32F 3-D textures, one per colour channel, and one of face openness, each an atlas of
// the active cascades (finest first, u_lpv_count of them) stacked along z: RGBA = L1 SH (Y0, x, y, z)
// of the accumulated radiant intensity in W/sr, texel (x, y, z + u_lpv_zofs[c]) = cell (x, y, z) of
// cascade c, LINEAR filtering, clamped to the cascade's block as CLAMP_TO_EDGE would. Cell of world
// point p: u = (p - origin) / cell_size (in cells).
// One set of samplers for every cascade lets the lookups loop over the cascades from the first one
// that covers the point and leave the loop once the point's weight is spent: llvmpipe runs every
// side of a branch for a block of pixels, but leaves a loop once every pixel of the block has, so
// a pixel deep inside cascade 0 no longer pays for cascades 1 and 2 (the unrolled form, one block
// per cascade with its own samplers, ran all three everywhere: ~half of the LPV lighting passes).
#ifndef SERENITY_LPV_GLSL
#define SERENITY_LPV_GLSL
#include "common.glsl"
// The lookup's switches are compile-time where the program defines them (the renderer's LPV
// lighting passes, lpv_gl.lookup_defines: llvmpipe runs the code of a branch that a uniform skips,
// e.g. the plain trilinear fetch beside the guarded one, ~14 % of the pass), else the uniforms of
// the same names (the probe pass that checks the lookups against the Warp twin). LPV_DAMPING 0 leaves
// the self-illumination damping out (~20 % of the pass while off).
#ifdef LPV_LEAK_GUARD
#define LPV_GUARD (LPV_LEAK_GUARD != 0)
#else
#define LPV_GUARD u_lpv_leak_guard
#endif
#ifdef LPV_OCCLUSION
#define LPV_OCCL (LPV_OCCLUSION != 0)
#else
#define LPV_OCCL u_lpv_occlusion
#endif
#ifdef LPV_PLANES
#define LPV_PLANE (LPV_PLANES != 0)
#else
#define LPV_PLANE u_lpv_planes
#endif
#ifndef LPV_DAMPING
#define LPV_DAMPING 1
#endif

uniform sampler3D u_lpv_r;            // the cascades' SH of red, green, blue (atlases along z)
uniform sampler3D u_lpv_g;
uniform sampler3D u_lpv_b;
uniform sampler3D u_lpv_o;            // RGB = openness of each cell's +x, +y, +z faces (1 - the
                                      // geometry volume's blocking; lookup occlusion), A = planes
uniform int u_lpv_zofs[3];            // cascade c's first z texel in the atlases
uniform vec3 u_lpv_atlas;             // the atlases' size, texels (the largest cascade's res², Σ res)
uniform bool u_lpv_occlusion;         // the leak guard also drops cells across a blocking face
uniform bool u_lpv_planes;            // the home cell crosses a blocker inside it (A of u_lpv_o*)
uniform vec4 u_lpv_geom[3];           // xyz: grid min corner (m), w: cell size (m)
uniform int u_lpv_res[3];             // cells per axis
uniform int u_lpv_count;              // active cascades, 0..3 (0: the LPV adds nothing)
uniform float u_lpv_lookup_offset;    // cells along the normal (irradiance)
uniform bool u_lpv_leak_guard;        // irradiance: drop cells behind the surface (LPVConfig.leak_guard)
uniform float u_lpv_margin;           // cells at a non-last cascade's border with zero weight
uniform float u_lpv_band;             // cells of the blend band (0: hard switch)
uniform int u_lpv_glossy_steps;       // samples along the reflected direction
uniform float u_lpv_glossy_step;      // metres between glossy samples
uniform float u_lpv_damp_dist;        // self-illumination damping: cells along the normal (0: off)
uniform float u_lpv_damp_pow;         // its exponent (LPVConfig.self_damping_power)

const float LPV_C0 = 0.28209479177387814;   // 1 / (2 sqrt(pi))
const float LPV_C1 = 0.48860251190291992;   // sqrt(3) / (2 sqrt(pi))
const float LPV_E0 = 0.88622692545275801;   // sqrt(pi) / 2
const float LPV_E1 = 1.02332670794648848;   // sqrt(pi / 3)

// alpha of cascade c at grid coordinate u (cells): smoothstep(margin, margin + band, d), or a
// step when band = 0; the last active cascade: clamp(d + 1, 0, 1). d = distance to the box border.
float lpv_cascade_weight(vec3 u, int res, bool last) {
    float fr = float(res);
    float d = min(min(min(u.x, u.y), u.z), min(min(fr - u.x, fr - u.y), fr - u.z));
    if (last) return clamp(d + 1.0, 0.0, 1.0);
    if (u_lpv_band > 0.0) {
        float t = clamp((d - u_lpv_margin) / u_lpv_band, 0.0, 1.0);
        return t * t * (3.0 - 2.0 * t);
    }
    return d > u_lpv_margin ? 1.0 : 0.0;
}

// Cascade c's cell i in an atlas.
vec4 lpv_texel(sampler3D t, int c, ivec3 i) { return texelFetch(t, i + ivec3(0, 0, u_lpv_zofs[c]), 0); }

// R, G, B SH trilinear at grid coordinate u (cells) of cascade c, of res cells.
// (EXACT_FILTER: by hand with float weights, as the texture unit's clamp-to-edge trilinear filter
// would with exact weights; raster/context.py says why. Else the texture unit's, the coordinate
// clamped to the cascade's block of the atlas as clamp-to-edge would.)
void lpv_fetch(int c, int res, vec3 u, out vec4 sr, out vec4 sg, out vec4 sb) {
#ifdef EXACT_FILTER
    vec3 us = u - 0.5;
    vec3 f = floor(us);
    vec3 w = us - f;
    ivec3 z = ivec3(0, 0, u_lpv_zofs[c]);
    ivec3 i0 = clamp(ivec3(f), ivec3(0), ivec3(res - 1)) + z;
    ivec3 i1 = clamp(ivec3(f) + 1, ivec3(0), ivec3(res - 1)) + z;
    sr = trilinear_texels(u_lpv_r, i0, i1, w); sg = trilinear_texels(u_lpv_g, i0, i1, w);
    sb = trilinear_texels(u_lpv_b, i0, i1, w);
#else
    vec3 t = (clamp(u, vec3(0.5), vec3(float(res) - 0.5)) + vec3(0.0, 0.0, float(u_lpv_zofs[c]))) / u_lpv_atlas;
    sr = textureLod(u_lpv_r, t, 0.0); sg = textureLod(u_lpv_g, t, 0.0); sb = textureLod(u_lpv_b, t, 0.0);
#endif
}

// Where the blockers of cell i's +x, +y, +z faces lie, in cells from the face (0: on it): the openness
// texel's A, qx + 256 qy + 65536 qz with q = round((t + 1/2) 254) (LightPropagationVolume.openness).
vec3 lpv_planes(int c, ivec3 i) {
    float a = lpv_texel(u_lpv_o, c, i).a;
    float qz = floor(a * (1.0 / 65536.0));
    a -= qz * 65536.0;
    float qy = floor(a * (1.0 / 256.0));
    float qx = a - qy * 256.0;
    return vec3(qx, qy, qz) * (1.0 / 254.0) - 0.5;
}

// The home cell (the twin of kernels.home_cell): h = floor(q), q = us + n/4, moved down an axis when
// h's low face there is blocked and its blocker lies inside h beyond q, up when the high face's does.
ivec3 lpv_home(int c, int res, vec3 us, vec3 n) {
    vec3 q = us + 0.25 * n;
    ivec3 h = clamp(ivec3(floor(q)), ivec3(0), ivec3(res - 1));
    if (!LPV_PLANE) return h;
    ivec3 h0 = h;
    vec4 oh = lpv_texel(u_lpv_o, c, h0);
    vec3 thi = lpv_planes(c, h0);
    for (int a = 0; a < 3; ++a) {
        float f = q[a] - float(h0[a]);
        bool moved = false;
        if (h0[a] > 0) {
            ivec3 lo = h0;
            lo[a] -= 1;
            float t = lpv_planes(c, lo)[a];
            if (t > 0.0 && f < t && lpv_texel(u_lpv_o, c, lo)[a] < 1.0) { h[a] -= 1; moved = true; }
        }
        if (!moved && h0[a] < res - 1 && thi[a] < 0.0 && f > 1.0 + thi[a] && oh[a] < 1.0) h[a] += 1;
    }
    return h;
}

// Trilinear with each of the 8 cells also weighted by g = clamp(4 n.(centre - us), 0, 1):
// cells whose centre lies behind the surface point us (cells) do not light it; with u_lpv_occlusion
// also by the openness of the faces between the home cell h (lpv_home) and the cell, one per
// axis where they differ, taken in h's row (the twin of kernels.open_weight).
void lpv_fetch_guarded(int c, int res, vec3 u, vec3 us, vec3 n, out vec4 sr, out vec4 sg, out vec4 sb) {
    vec3 p = u - vec3(0.5);
    vec3 f = floor(p);
    vec3 t = p - f;
    ivec3 i0 = clamp(ivec3(f), ivec3(0), ivec3(res - 1));
    ivec3 i1 = clamp(ivec3(f) + 1, ivec3(0), ivec3(res - 1));
    ivec3 h = LPV_OCCL ? lpv_home(c, res, us, n) : ivec3(0);
    // openness of the face between h and i0 / i1 on each axis (1 where they coincide)
    vec3 o0 = vec3(1.0), o1 = vec3(1.0);
    if (LPV_OCCL) {
        if (i0.x != h.x) o0.x = lpv_texel(u_lpv_o, c, ivec3(min(i0.x, h.x), h.y, h.z)).r;
        if (i1.x != h.x) o1.x = lpv_texel(u_lpv_o, c, ivec3(min(i1.x, h.x), h.y, h.z)).r;
        if (i0.y != h.y) o0.y = lpv_texel(u_lpv_o, c, ivec3(h.x, min(i0.y, h.y), h.z)).g;
        if (i1.y != h.y) o1.y = lpv_texel(u_lpv_o, c, ivec3(h.x, min(i1.y, h.y), h.z)).g;
        if (i0.z != h.z) o0.z = lpv_texel(u_lpv_o, c, ivec3(h.x, h.y, min(i0.z, h.z))).b;
        if (i1.z != h.z) o1.z = lpv_texel(u_lpv_o, c, ivec3(h.x, h.y, min(i1.z, h.z))).b;
    }
    sr = vec4(0.0); sg = vec4(0.0); sb = vec4(0.0);
    float wsum = 0.0;
    for (int k = 0; k < 8; ++k) {
        bool bx = (k & 1) != 0, by = (k & 2) != 0, bz = (k & 4) != 0;
        ivec3 ii = ivec3(bx ? i1.x : i0.x, by ? i1.y : i0.y, bz ? i1.z : i0.z);
        float g = clamp(4.0 * dot(n, vec3(ii) + vec3(0.5) - us), 0.0, 1.0);
        g *= (bx ? o1.x : o0.x) * (by ? o1.y : o0.y) * (bz ? o1.z : o0.z);
        float w = (bx ? t.x : 1.0 - t.x) * (by ? t.y : 1.0 - t.y) * (bz ? t.z : 1.0 - t.z) * g;
        sr += w * lpv_texel(u_lpv_r, c, ii); sg += w * lpv_texel(u_lpv_g, c, ii); sb += w * lpv_texel(u_lpv_b, c, ii);
        wsum += w;
    }
    if (wsum < 1.0e-4) {
        lpv_fetch(c, res, u, sr, sg, sb);
        return;
    }
    sr /= wsum; sg /= wsum; sb /= wsum;
}

float lpv_eval_irradiance(vec4 s, vec3 n, float inv_area) {
    return max((LPV_E0 * s.x - LPV_E1 * dot(s.yzw, n)) * inv_area, 0.0);
}

// Self-illumination damping (the twin of kernels.self_damping): (far / near)^power clamped to [0, 1],
// near the DC where the surface looks up, far the DC u_lpv_damp_dist cells further along the normal.
float lpv_self_damping(float near, float far) {
    if (!(near > 0.0)) return 1.0;
    return pow(clamp(far / near, 0.0, 1.0), u_lpv_damp_pow);
}

// Product of the openness of the `steps` faces met going from the home cell h along the normal's
// dominant axis, stopping at the grid's edge (the twin of kernels.open_ahead).
float lpv_open_ahead(int cascade, int res, ivec3 h, vec3 n, int steps) {
    int a = 0;
    if (abs(n.y) > abs(n[a])) a = 1;
    if (abs(n.z) > abs(n[a])) a = 2;
    int st = n[a] < 0.0 ? -1 : 1;
    ivec3 c = h;
    float o = 1.0;
    for (int k = 0; k < steps; ++k) {
        if (c[a] + st >= 0 && c[a] + st <= res - 1) {
            ivec3 lo = c;
            lo[a] = min(c[a], c[a] + st);
            o *= lpv_texel(u_lpv_o, cascade, lo)[a];
            c[a] += st;
        }
    }
    return o;
}

float lpv_eval_radiance(vec4 s, vec3 w, float a1, float inv_area) {
    return max((LPV_C0 * s.x + a1 * LPV_C1 * dot(s.yzw, w)) * inv_area, 0.0);
}

// The first cascade whose weight at p (its grid coordinate plus ``offset`` cells) is above 0 (the
// last if none): the finer ones would add nothing and leave the weight to spend as it was. No fetch.
int lpv_first_cascade(vec3 p, vec3 offset) {
    int c = 0;
    for (; c < u_lpv_count - 1; ++c) {
        vec3 u = (p - u_lpv_geom[c].xyz) / u_lpv_geom[c].w + offset;
        if (lpv_cascade_weight(u, u_lpv_res[c], false) > 0.0) break;
    }
    return c;
}

// Irradiance from cascade c, weighted by its alpha times what the finer cascades left (keep, updated).
vec3 lpv_cascade_irradiance(int c, vec3 p, vec3 n, inout float keep) {
    float cell = u_lpv_geom[c].w;
    int res = u_lpv_res[c];
    vec3 us = (p - u_lpv_geom[c].xyz) / cell;
    vec3 u = us + n * u_lpv_lookup_offset;
    float alpha = lpv_cascade_weight(u, res, c == u_lpv_count - 1) * keep;
    if (alpha <= 0.0) return vec3(0.0);
    vec4 sr, sg, sb;
    if (LPV_GUARD) lpv_fetch_guarded(c, res, u, us, n, sr, sg, sb);
    else lpv_fetch(c, res, u, sr, sg, sb);
#if LPV_DAMPING
    if (u_lpv_damp_dist > 0.0) {
        vec4 fr, fg, fb;
        lpv_fetch(c, res, u + n * u_lpv_damp_dist, fr, fg, fb);
        float o = LPV_GUARD && LPV_OCCL
            ? lpv_open_ahead(c, res, lpv_home(c, res, us, n), n, int(ceil(u_lpv_damp_dist))) : 1.0;
        sr *= 1.0 - o * (1.0 - lpv_self_damping(sr.x, fr.x));
        sg *= 1.0 - o * (1.0 - lpv_self_damping(sg.x, fg.x));
        sb *= 1.0 - o * (1.0 - lpv_self_damping(sb.x, fb.x));
    }
#endif
    float inv_area = 1.0 / (cell * cell);
    keep -= alpha;
    return alpha * vec3(lpv_eval_irradiance(sr, n, inv_area), lpv_eval_irradiance(sg, n, inv_area),
                        lpv_eval_irradiance(sb, n, inv_area));
}

vec3 lpv_irradiance(vec3 p, vec3 n_in) {
    vec3 n = normalize(n_in);
    vec3 e = vec3(0.0);
    float keep = 1.0;
    for (int c = lpv_first_cascade(p, n * u_lpv_lookup_offset); c < u_lpv_count; ++c) {
        e += lpv_cascade_irradiance(c, p, n, keep);
        if (keep <= 0.0) break;
    }
    return e;
}

// Radiance travelling along w at world point q from cascade c, weighted as in the irradiance.
vec3 lpv_cascade_radiance(int c, vec3 q, vec3 w, float a1, inout float keep) {
    float cell = u_lpv_geom[c].w;
    int res = u_lpv_res[c];
    vec3 u = (q - u_lpv_geom[c].xyz) / cell;
    float alpha = lpv_cascade_weight(u, res, c == u_lpv_count - 1) * keep;
    if (alpha <= 0.0) return vec3(0.0);
    vec4 sr, sg, sb;
    lpv_fetch(c, res, u, sr, sg, sb);
    float inv_area = 1.0 / (cell * cell);
    keep -= alpha;
    return alpha * vec3(lpv_eval_radiance(sr, w, a1, inv_area), lpv_eval_radiance(sg, w, a1, inv_area),
                        lpv_eval_radiance(sb, w, a1, inv_area));
}

vec3 lpv_glossy(vec3 p, vec3 r_in, float shininess) {
    if (u_lpv_glossy_steps <= 0 || u_lpv_count <= 0) return vec3(0.0);
    vec3 r = normalize(r_in);
    float a1 = (shininess + 1.0) / (shininess + 2.0);
    vec3 w = -r;
    vec3 acc = vec3(0.0);
    for (int k = 0; k < u_lpv_glossy_steps; ++k) {
        vec3 q = p + r * (u_lpv_glossy_step * float(k + 1));
        float keep = 1.0;
        for (int c = lpv_first_cascade(q, vec3(0.0)); c < u_lpv_count; ++c) {
            acc += lpv_cascade_radiance(c, q, w, a1, keep);
            if (keep <= 0.0) break;
        }
    }
    return acc / float(u_lpv_glossy_steps);
}

#endif
