// Temporal hysteresis of the upsampled indirect light (raster/temporal.py, RenderConfig.
// indirect_history = a), included by the deferred pass (deferred.glsl, UPSAMPLE 2): each pixel's
// indirect light I = albedo * E + G, as upsampled from the low-res passes (upsample.glsl), blended
// with the light the last frame showed at the same surface point,
//   I = a * I_now + (1 - a) * I_before,
// "before" bilinear over the 4 last-frame pixels around the point's place in the last frame's view,
// each taken only where it showed the point's surface: its view depth within what the surface's slope
// allows of the point's own depth in the last frame's camera (otherwise the point was hidden or beside
// an edge then, a disocclusion); the weights renormalised, and with under half of the weight left the
// pixel shows this frame's light. The low-res texels stand for G-buffer pixels that slide over the
// surfaces as the camera moves, and the upsampled light slid with them: a moving camera stepped the
// LPV's light by a few per cent a frame. The deferred pass writes I and the pixel's view depth
// (rgb, a; a = -1 where it shows the sky: the target is cleared so) for the next frame to read.
uniform sampler2D u_prev_irr;       // the last frame's I (rgb) and view depth (a)
uniform mat4 u_prev_view_proj;      // the last frame's world -> clip
uniform vec3 u_prev_camera_pos;
uniform vec3 u_prev_camera_forward;
uniform float u_history_alpha;      // weight of this frame's light (1: none of the last frame's)
uniform float u_pixel_angle;        // radians a pixel spans (vertically) at the view's centre
uniform bool u_has_prev;

// I at surface point p (unit normal n) from this frame's upsampled light ``irr``
vec3 history_blend(vec3 p, vec3 n, vec3 irr) {
    if (!u_has_prev || u_history_alpha >= 1.0) return irr;
    vec2 size = vec2(textureSize(u_prev_irr, 0));
    vec4 c = u_prev_view_proj * vec4(p, 1.0);
    if (c.w <= 1e-6) return irr;
    vec2 q = (c.xy / c.w * 0.5 + 0.5) * size - 0.5;  // its pixel then (integers at pixel centres)
    q = mix(q, floor(q + 0.5), lessThan(abs(q - floor(q + 0.5)), vec2(1e-3)));  // a still view: that pixel
    ivec2 i0 = ivec2(floor(q));
    vec2 f = q - vec2(i0);
    vec3 v = p - u_prev_camera_pos;
    float zp = dot(v, u_prev_camera_forward);  // the point's depth in the last frame's camera
    // how far the surface's depth may move over one pixel there: the pixel's footprint over the cosine
    // of the angle between the surface and the view ray, with 2 % of the depth for the rest
    float cosv = max(abs(dot(n, normalize(v))), 0.05);
    float tol = zp * (0.02 + 1.5 * u_pixel_angle * sqrt(max(1.0 - cosv * cosv, 0.0)) / cosv);
    vec3 bi = vec3(0.0);
    float wsum = 0.0;
    for (int k = 0; k < 4; ++k) {
        ivec2 o = ivec2(k & 1, k >> 1);
        ivec2 t = i0 + o;
        if (any(lessThan(t, ivec2(0))) || any(greaterThanEqual(t, ivec2(size)))) continue;
        vec4 a = texelFetch(u_prev_irr, t, 0);
        if (a.w < 0.0 || abs(a.w - zp) > tol) continue;  // not this surface then
        float w = bilinear_weight(o, f);
        bi += w * a.rgb;
        wsum += w;
    }
    if (wsum < 0.5) return irr;
    bi /= wsum;
    return bi + u_history_alpha * (irr - bi);  // exactly the light itself when it did not change
}
