// Temporal anti-aliasing resolve (raster/taa.py, RenderConfig.antialiasing = "taa"), on the linear HDR
// frame before the tone map. Each frame's projection is jittered within the pixel (Halton(2, 3)); the
// resolve blends this frame's sample of each pixel with the pixel's history, the last resolved frame
// seen from this frame's camera (Karis 2014, "High quality temporal supersampling"; Salvi 2016,
// "An excursion in temporal supersampling"):
//   history  the pixel's surface point (G-buffer) reprojected into the last frame (reproject.glsl:
//            its unjittered view-projection, q shifted by this frame's jitter so that it is the pixel
//            centre's place, not the jittered sample's), bilinear over the taps that showed that
//            surface (depth test: a disocclusion, or a point off the image, keeps no history); with all
//            4 taps taken, a 5-tap Catmull-Rom instead (sharper: bilinear history blurs a moving image
//            a little more every frame). A pixel with a depth step in its 3x3 neighbourhood (an edge:
//            its jittered samples fall on either side) reprojects its nearest neighbour's point (the
//            silhouette's motion) and takes the taps without the depth test. The sky's pixels
//            reproject their view direction (w = 0) and take the taps that showed the sky.
//   clip     the history clipped towards the mean of this frame's 3x3 neighbourhood, into the box of
//            mean +- gamma * standard deviation (variance clipping), in YCoCg of the Reinhard-
//            compressed colour c / (1 + exposure * luminance(c)), and no brighter than the brightest
//            of the nine: what it showed of a light, a shadow or a surface that has changed or moved
//            is pulled back into what this frame shows there
//   blend    out = (w_c * c + w_h * h) / (w_c + w_h), w_c = a / (1 + exposure * E(c)), w_h = 1 - a,
//            E(c) = c's luminance above its brightest neighbour's (u_weights 2; Karis' E = L for
//            both, 1; none, 0): a single bright sample (a firefly) does not smear into the history
//   a, gamma u_alpha and u_gamma where the reprojection moves the image a pixel or more, u_alpha_still
//            and u_gamma_still where it stands still, in between by the distance: a still view
//            averages many jitter cycles in a wide box, or its edges step as the jitter cycles
// Output: rgb = the resolved image, a = the pixel's view depth (-1: sky), which the next frame reads.
#include "fullscreen.glsl"
#include "reproject.glsl"

#if defined FRAGMENT_SHADER
uniform sampler2D u_hdr;               // this frame, jittered (nearest)
uniform sampler2D u_position;          // G-buffer: world position (xyz, m), coverage (w)
uniform sampler2D u_normal;            // G-buffer: world normal (xyz)
uniform sampler2D u_history;           // the last resolved frame: rgb, view depth (a; -1 = sky); bilinear
uniform mat4 u_prev_view_proj;         // the last frame's world -> clip, unjittered
uniform mat4 u_inv_view_proj;          // this frame's clip -> world, unjittered
uniform vec3 u_prev_camera_pos;
uniform vec3 u_prev_camera_forward;
uniform vec3 u_camera_pos;
uniform vec3 u_camera_forward;
uniform vec2 u_jitter;                 // this frame's jitter, pixels (x right, y up)
uniform float u_pixel_angle;           // radians a pixel spans (vertically) at the view's centre
uniform float u_alpha;                 // weight of this frame's sample where the image moves a pixel or more
uniform float u_alpha_still;           // ... where it stands still (1: no history)
uniform float u_gamma;                 // variance clipping's box, standard deviations (0: no clip)
uniform float u_gamma_still;           // ... where the image stands still
uniform float u_exposure;
uniform int u_weights;                 // 0: plain blend; 1: Karis' 1 / (1 + exposure L); 2: the excess over the neighbours
uniform bool u_has_prev;
uniform bool u_catmull_rom;
out vec4 o_hdr;

vec3 compress(vec3 c) { return c / (1.0 + u_exposure * max(luminance(c), 0.0)); }
vec3 expand(vec3 c) { return c / max(1.0 - u_exposure * luminance(c), 1e-4); }

vec3 rgb_to_ycocg(vec3 c) {
    return vec3(0.25 * c.r + 0.5 * c.g + 0.25 * c.b, 0.5 * c.r - 0.5 * c.b, -0.25 * c.r + 0.5 * c.g - 0.25 * c.b);
}
vec3 ycocg_to_rgb(vec3 c) { return vec3(c.x + c.y - c.z, c.x + c.z, c.x - c.y - c.z); }

// The history at pixel coordinate q (integers at centres): Catmull-Rom from 5 bilinear taps (the
// 4x4 footprint's corners left out and the weights renormalised; Jimenez 2016)
vec3 catmull_rom(vec2 q) {
    vec2 size = vec2(textureSize(u_history, 0));
    vec2 t = floor(q);
    vec2 f = q - t;
    vec2 w0 = f * (-0.5 + f * (1.0 - 0.5 * f));
    vec2 w1 = 1.0 + f * f * (-2.5 + 1.5 * f);
    vec2 w2 = f * (0.5 + f * (2.0 - 1.5 * f));
    vec2 w3 = f * f * (-0.5 + 0.5 * f);
    vec2 w12 = w1 + w2;
    vec2 c0 = (t - 0.5) / size;                 // centre of texel t - 1
    vec2 c12 = (t + 0.5 + w2 / w12) / size;     // between texels t and t + 1
    vec2 c3 = (t + 2.5) / size;                 // texel t + 2
    vec3 s = texture(u_history, vec2(c12.x, c0.y)).rgb * (w12.x * w0.y)
           + texture(u_history, vec2(c0.x, c12.y)).rgb * (w0.x * w12.y)
           + texture(u_history, c12).rgb * (w12.x * w12.y)
           + texture(u_history, vec2(c3.x, c12.y)).rgb * (w3.x * w12.y)
           + texture(u_history, vec2(c12.x, c3.y)).rgb * (w12.x * w3.y);
    float wsum = w12.x * w0.y + w0.x * w12.y + w12.x * w12.y + w3.x * w12.y + w12.x * w3.y;
    return max(s / wsum, vec3(0.0));
}

// The history of a sky pixel: its view direction through the last frame's camera, bilinear over the
// taps that showed the sky (rgb sum, weight), q as reproject_bilinear's
vec4 sky_history(vec2 size, out vec2 q) {
    vec2 ndc = gl_FragCoord.xy / size * 2.0 - 1.0;
    vec4 far = u_inv_view_proj * vec4(ndc, 1.0, 1.0);
    vec3 dir = far.xyz / far.w - u_camera_pos;
    if (!prev_pixel(u_prev_view_proj * vec4(dir, 0.0), size, vec2(0.0), q)) return vec4(0.0);
    return prev_taps(u_history, q, true, 0.0, 0.0);
}

// h moved towards the box's centre until it lies in the box (centre +- extent)
vec3 clip_to_box(vec3 h, vec3 centre, vec3 extent) {
    vec3 d = h - centre;
    vec3 u = abs(d) / max(extent, vec3(1e-6));
    float m = max(u.x, max(u.y, u.z));
    return m > 1.0 ? centre + d / m : h;
}

void main() {
    ivec2 px = ivec2(gl_FragCoord.xy);
    ivec2 size = textureSize(u_hdr, 0);
    vec3 cur = texelFetch(u_hdr, px, 0).rgb;
    vec4 pos = texelFetch(u_position, px, 0);
    bool surface = pos.w > 0.0;
    float depth = surface ? dot(pos.xyz - u_camera_pos, u_camera_forward) : -1.0;
    bool finite_cur = all(lessThan(abs(cur), vec3(3.0e38)));  // NaN fails too
    if (!u_has_prev || u_alpha_still >= 1.0 || !finite_cur) {
        o_hdr = vec4(cur, depth);
        return;
    }
    // this frame's 3x3 neighbourhood: the colours' mean and standard deviation in compressed YCoCg;
    // whether it spans an edge (a neighbour of another coverage, or depth 5 % away), and its nearest surface
    vec3 m1 = vec3(0.0), m2 = vec3(0.0);
    float around = 0.0;  // the brightest neighbour's luminance
    float brightest = 0.0;  // ... and with the pixel itself
    bool edge = false;
    float near_z = 3.0e38;
    ivec2 near_o = ivec2(0);
    vec3 near_p = pos.xyz;
    for (int k = 0; k < 9; ++k) {
        ivec2 o = ivec2(k % 3 - 1, k / 3 - 1);
        ivec2 t = clamp(px + o, ivec2(0), size - 1);
        vec3 ck = max(texelFetch(u_hdr, t, 0).rgb, vec3(0.0));
        if (k != 4) around = max(around, luminance(ck));
        brightest = max(brightest, luminance(ck));
        vec3 y = rgb_to_ycocg(compress(ck));
        m1 += y;
        m2 += y * y;
        vec4 pk = texelFetch(u_position, t, 0);
        float zk = pk.w > 0.0 ? dot(pk.xyz - u_camera_pos, u_camera_forward) : 3.0e38;
        edge = edge || (pk.w > 0.0) != surface || (surface && abs(zk - depth) > 0.05 * depth);
        if (zk < near_z) {
            near_z = zk;
            near_o = t - px;
            near_p = pk.xyz;
        }
    }
    m1 /= 9.0;
    vec3 sigma = sqrt(max(m2 / 9.0 - m1 * m1, vec3(0.0)));
    vec3 n = normalize(texelFetch(u_normal, px, 0).xyz);
    // the jittered samples of an edge's pixels fall on either side: there the history follows the
    // nearest surface (the silhouette's motion; the sky's direction where there is none) and is taken
    // whatever depth its taps show, the clip below keeping what this frame's neighbourhood allows
    // (one reprojection either way: llvmpipe runs both sides of a branch its pixels disagree on)
    vec3 rp = edge ? near_p : pos.xyz;
    vec2 shift = u_jitter - (edge ? vec2(near_o) : vec2(0.0));
    vec2 q;
    vec4 sum = (edge ? near_z < 3.0e38 : surface)
        ? reproject_bilinear(u_history, u_prev_view_proj, u_prev_camera_pos, u_prev_camera_forward, u_pixel_angle,
                             rp, n, shift, q)
        : sky_history(vec2(size), q);
    bool off = any(lessThan(q, vec2(-0.5))) || any(greaterThan(q, vec2(size) - 0.5));
    if (edge ? off : sum.w < 0.5) {  // off the image, or a disocclusion: this frame's sample alone
        o_hdr = vec4(cur, depth);
        return;
    }
    vec3 hist = sum.rgb / max(sum.w, 1e-6);
    if (edge || sum.w > 0.999) {  // every tap taken
        hist = u_catmull_rom ? catmull_rom(q) : texture(u_history, (q + 0.5) / vec2(size)).rgb;
    }
    if (!all(lessThan(abs(hist), vec3(3.0e38)))) {
        o_hdr = vec4(cur, depth);
        return;
    }
    float motion = clamp(length(q - (gl_FragCoord.xy - 0.5)), 0.0, 1.0);  // pixels, up to one
    if (u_gamma > 0.0) {
        vec3 h = clip_to_box(rgb_to_ycocg(compress(hist)), m1, mix(u_gamma_still, u_gamma, motion) * sigma);
        hist = max(expand(ycocg_to_rgb(h)), vec3(0.0));
        // a corner of the box may lie beyond every neighbour's luminance (or near the compression's
        // pole, where expand() grows without bound): no brighter than the brightest of them
        float lh = luminance(hist);
        hist *= lh > brightest ? brightest / lh : 1.0;
    }
    float lc = max(luminance(cur), 0.0), lh = luminance(hist);
    if (u_weights == 2) {  // a sample brighter than all its neighbours counts for less
        lc = max(lc - around, 0.0);
        lh = 0.0;
    }
    float k = u_weights == 0 ? 0.0 : u_exposure;
    // a still image averages more frames (the jitter's cycle evenly, so an edge does not shimmer); a
    // moving one fewer (each resampling of the history blurs it, and what it lags shows)
    float a = mix(u_alpha_still, u_alpha, motion);
    float wc = a / (1.0 + k * lc);
    float wh = (1.0 - a) / (1.0 + k * lh);
    o_hdr = vec4((wc * cur + wh * hist) / (wc + wh), depth);
}
#endif
