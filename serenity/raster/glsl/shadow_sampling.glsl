// Sun visibility from the cascaded shadow-map atlas: hard, PCF or PCSS (Fernando 2005).
// See serenity/raster/shadow.py for the cascade fitting, atlas layout and bias units.
#ifndef SERENITY_SHADOW_SAMPLING_GLSL
#define SERENITY_SHADOW_SAMPLING_GLSL
#include "common.glsl"

#define SHADOW_HARD 0
#define SHADOW_PCF 1
#define SHADOW_PCSS 2

uniform sampler2D u_shadow_map;       // depth atlas of T x T tiles: slot s at tile (s % T, s / T)
uniform int u_cascade_count;
uniform float u_atlas_tiles;          // tiles per side T (1, 2, or 3 with a staggered atlas's second slots)
// Each cascade's tile (index c) and, while a staggered tile cross-fades (ShadowPass.render), the same
// tile as drawn before its last redraw (index c + 4, its weight in u_cascade_prev_weight, 0 = none):
// one array per parameter, so that a lookup picks its tile by one index (llvmpipe gathers a
// dynamically indexed uniform lane by lane, and a select between two sets of them reads both)
uniform mat4 u_tile_vp[8];            // world -> light clip
uniform mat3 u_tile_plane[8];         // inverse transpose of the tile's linear part: a world normal ->
                                      // the normal of that plane in the map's coordinates
uniform vec4 u_tile_info[8];          // atlas slot, one texel (m), light depth extent (m), 0
uniform vec4 u_cascade_prev_weight;
uniform vec4 u_cascade_far;           // view depth (m) where each cascade ends
uniform vec4 u_cascade_texel;         // one texel of each cascade's tile, metres
uniform float u_shadow_bias;          // texels
uniform float u_normal_offset;        // texels
uniform float u_pcf_radius;           // texels (PCF mode)
uniform float u_sun_tan_half;         // tan of the sun's angular radius
uniform float u_pcss_max_blocker;     // metres: farthest blocker the search looks for

// The filter and its tap counts are compiled in (DeferredPass builds one program per setting): the
// loops unroll and the modes not chosen are left out, which a CPU rasteriser would otherwise run
// for every pixel (it runs every side of a branch).
#ifndef SHADOW_FILTER
#define SHADOW_FILTER SHADOW_PCSS
#endif
// The taps' Vogel discs come in as constants (BLOCKER_DISC, FILTER_DISC: serenity.raster.shadow.
// disc_defines, with BLOCKER_SAMPLES and FILTER_SAMPLES): each pixel turns them by its own angle, one
// cos/sin pair instead of one per tap (llvmpipe evaluates them in software).
#if !defined(BLOCKER_DISC) || !defined(FILTER_DISC)
#error "shadow_sampling.glsl: compile with serenity.raster.shadow.disc_defines (BLOCKER_DISC, FILTER_DISC)"
#endif
const vec2 BLOCKER_POINTS[BLOCKER_SAMPLES] = vec2[BLOCKER_SAMPLES](BLOCKER_DISC);
const vec2 FILTER_POINTS[FILTER_SAMPLES] = vec2[FILTER_SAMPLES](FILTER_DISC);
uniform float u_cascade_blend;        // fraction of a cascade's depth blended into the next
const float MAX_PLANE_SLOPE = 32.0;

float interleaved_gradient_noise(vec2 pixel) {
    return fract(52.9829189 * fract(dot(pixel, vec2(0.06711056, 0.00583715))));
}

// A disc point turned by the angle whose (cos, sin) is rot.
vec2 rotated(vec2 p, vec2 rot) {
    return vec2(p.x * rot.x - p.y * rot.y, p.x * rot.y + p.y * rot.x);
}

// One cascade's tile of the atlas, and the receiver's plane in it. The tap at tile coordinates
// uv + o reads the atlas texel at base + o * scale (kept half a texel inside the tile), and the
// receiver's depth there is its tangent plane's at that texel's centre (receiver-plane depth bias):
// a plane meets its own depth at the centre of every texel it drew, so a tap compares the map with
// the receiver at the same point, and neither a sloped receiver nor a wide filter needs a bias that
// grows with them (which detached and shortened the shadows of eaves on walls under a grazing sun).
struct AtlasTile { vec2 base; float scale; vec2 lo; vec2 hi; float texels; vec2 grad; float z; };

// s: the receiver in the tile's [0,1]^3 map coordinates; m: its normal there (u_tile_plane);
// bias: depth units subtracted from the receiver
AtlasTile atlas_tile(int slot, vec3 s, vec3 m, vec2 texel, float max_grad, float bias) {
    int t = int(u_atlas_tiles + 0.5);
    vec2 tile = vec2(slot % t, slot / t);
    float scale = 1.0 / u_atlas_tiles;
    // depth per unit of tile coordinates along the plane, no steeper than max_grad
    vec2 grad = clamp(-m.xy / (abs(m.z) > 1e-6 ? m.z : 1e-6), -max_grad, max_grad);
    return AtlasTile((tile + s.xy) * scale, scale, (tile + 0.5 * texel) * scale, (tile + 1.0 - 0.5 * texel) * scale,
                     u_atlas_tiles / texel.x, grad / scale, s.z - bias);
}

// the tap at o (offset in atlas units, i.e. times scale): the centre of the texel it reads
vec2 tap_centre(AtlasTile t, vec2 o) {
    return (floor(clamp(t.base + o, t.lo, t.hi) * t.texels) + 0.5) / t.texels;
}
// the receiver's plane depth at atlas point a; no farther than the map's far plane, which an empty
// texel holds (a plane steep in the map would otherwise pass behind it within a wide filter)
float plane_depth(AtlasTile t, vec2 a) { return min(t.z + dot(t.grad, a - t.base), 1.0); }

// The sun's visibility from one tile (light matrix vp, plane transform, atlas slot, texel_w m per
// texel, range m of depth); -1 where p lies outside it.
// The receiver p (normal n) in a tile's [0,1]^3 map coordinates (light matrix vp, texel_w m per texel),
// offset along its normal by the slope-scaled normal offset; outside_tile says whether it lies outside.
vec3 tile_coords(mat4 vp, float texel_w, vec3 p, vec3 n, float ndl) {
    float slope = clamp(sqrt(max(0.0, 1.0 - ndl * ndl)) / max(ndl, 0.05), 1.0, 4.0);
    vec4 lp = vp * vec4(p + n * texel_w * u_normal_offset * slope, 1.0);
    return lp.xyz / lp.w * 0.5 + 0.5;
}

bool outside_tile(vec3 s) { return any(lessThan(s.xy, vec2(0.0))) || any(greaterThan(s.xy, vec2(1.0))) || s.z > 1.0; }

float tile_visibility(mat4 vp, mat3 plane, int slot, float texel_w, float range, vec3 p, vec3 n, float ndl,
                      float size) {
    vec3 s = tile_coords(vp, texel_w, p, n, ndl);
    if (outside_tile(s)) return -1.0;
    vec2 texel = vec2(1.0 / size);
    float phi = 6.2831853 * interleaved_gradient_noise(gl_FragCoord.xy);
    vec2 rot = vec2(cos(phi), sin(phi));
    // at most MAX_PLANE_SLOPE metres of depth per metre across the map (a plane ~88 deg from the sun)
    float max_grad = MAX_PLANE_SLOPE * size * texel_w / range;
    AtlasTile tile = atlas_tile(slot, s, plane * n, texel, max_grad, u_shadow_bias * texel_w / range);
    float radius = 0.0;  // filter radius, texels
#if SHADOW_FILTER == SHADOW_PCF
    radius = u_pcf_radius;
#elif SHADOW_FILTER == SHADOW_PCSS
    {
        float search = clamp(u_pcss_max_blocker * 2.0 * u_sun_tan_half / texel_w, 1.0, 16.0);
        float gap = 0.0;  // the blockers' mean depth above the receiver's plane, map depth units
        int found = 0;
        vec2 spread = rot * (search * texel.x * tile.scale);   // texels are square
        for (int i = 0; i < BLOCKER_SAMPLES; ++i) {
            vec2 a = tap_centre(tile, rotated(BLOCKER_POINTS[i], spread));
            float above = plane_depth(tile, a) - texture(u_shadow_map, a).r;
            if (above > 0.0) { gap += above; found++; }
        }
        if (found == 0) return 1.0;
        float penumbra_m = gap / float(found) * range * 2.0 * u_sun_tan_half;  // full width
        radius = clamp(0.5 * penumbra_m / texel_w, 0.5, 24.0);
    }
#endif
#if SHADOW_FILTER == SHADOW_HARD
    vec2 a = tap_centre(tile, vec2(0.0));
    return plane_depth(tile, a) <= texture(u_shadow_map, a).r ? 1.0 : 0.0;
#else
    float lit = 0.0;
    vec2 spread = rot * (radius * texel.x * tile.scale);
    for (int i = 0; i < FILTER_SAMPLES; ++i) {
        vec2 a = tap_centre(tile, rotated(FILTER_POINTS[i], spread));
        lit += plane_depth(tile, a) <= texture(u_shadow_map, a).r ? 1.0 : 0.0;
    }
    return lit / float(FILTER_SAMPLES);
#endif
}

// Cascade c's visibility: its tile's, or while the tile's version before its last redraw still has a
// weight w (a staggered cascade, ShadowPass.render), that version's at a fraction w of the pixels
// (those whose noise is below w: the expected value is the cross-fade, each pixel switches once, and
// the tile is chosen per pixel so that a block of pixels runs one filter, not two); 1 outside the
// tile (and the new version where p lies outside the old one). One filter per pixel: llvmpipe runs
// both sides of a branch, so the old version's coverage is tested first and the filter runs once.
float cascade_visibility(int c, vec3 p, vec3 n, float ndl, float size) {
    int k = c;
    if (interleaved_gradient_noise(gl_FragCoord.xy + vec2(13.0, 29.0)) < u_cascade_prev_weight[c]
        && !outside_tile(tile_coords(u_tile_vp[c + 4], u_tile_info[c + 4].y, p, n, ndl))) k = c + 4;
    vec4 info = u_tile_info[k];
    float v = tile_visibility(u_tile_vp[k], u_tile_plane[k], int(info.x), info.y, info.z, p, n, ndl, size);
    return v < 0.0 ? 1.0 : v;
}

// One texel (m) of the first cascade that holds view depth ``view_depth`` (before any blending).
float cascade_texel_at(float view_depth) {
    for (int c = 0; c < u_cascade_count; ++c) {
        if (view_depth <= u_cascade_far[c]) return u_cascade_texel[c];
    }
    return u_cascade_texel[max(u_cascade_count - 1, 0)];
}

// view_depth: distance along the camera axis (m); n: shading normal; ndl = dot(n, sun) > 0.
// The cascade is chosen first and filtered once, outside any loop: a CPU rasteriser runs a loop body
// for a block of pixels until every pixel in it has left, so a filter inside the cascade loop ran
// once per cascade up to the pixel's own (4x the taps in the farthest cascade).
float sun_visibility(vec3 p, vec3 n, float ndl, float view_depth) {
    if (u_cascade_count <= 0) return 1.0;
    float size = float(textureSize(u_shadow_map, 0).x) / u_atlas_tiles;
    int c = u_cascade_count - 1;  // the first cascade that holds view_depth, else the last
    for (int k = u_cascade_count - 2; k >= 0; --k) {
        if (view_depth <= u_cascade_far[k]) c = k;
    }
    // in the blend band before the split, the next cascade is chosen with probability w (dithered
    // by the pixel's noise): the expected value is the linear cross-fade, at the cost of one
    // cascade lookup (a CPU rasteriser runs both sides of a branch for a whole block of pixels, so
    // a real cross-fade cost a second PCSS for every block it touched)
    float far_c = u_cascade_far[c];
    float near_c = c == 0 ? 0.0 : u_cascade_far[c - 1];
    float band = u_cascade_blend * (far_c - near_c);
    int use = c;
    if (c + 1 < u_cascade_count && view_depth > far_c - band) {
        float w = (view_depth - (far_c - band)) / max(band, 1e-6);
        if (interleaved_gradient_noise(gl_FragCoord.yx + 7.0) < w) use = c + 1;
    }
    return cascade_visibility(use, p, n, ndl, size);
}
#endif
