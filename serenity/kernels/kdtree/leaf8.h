// Woop's watertight test on a leaf's triangles, 8 at a time as SIMD lanes (clang's vector
// extensions: CPU only), in the float32 and float64 operations of triangle.py's intersect_triangle
// per triangle, then the lanes' hits in the triangles' order under intersect_leaf's rule: closer,
// or as close with a lower triangle index than the best so far (the first such for any_hit).
// Statements included inside a native's body (triangle.h's leaf_pick, cpu/packets.h's leaf_simd).
//   in:  refs, first (the leaf's block: its first word), k (its triangle count), o, kx, ky, kz, sx,
//        sy, sz (the ray's Woop set-up), tlo, best_t (the hit interval), prim (the best so far),
//        any_hit
//   out: prim (the best triangle's index), best (its t), found (its place in the leaf; -1: none
//        beat the best so far), ev_found, ew_found, det_found (its edge functions' v, w and
//        determinant, for its barycentrics)
typedef float f8 __attribute__((ext_vector_type(8)));
typedef double d8 __attribute__((ext_vector_type(8)));
typedef int i8 __attribute__((ext_vector_type(8)));
const float* R = refs.data + (unsigned)first;
const int* P = (const int*)R + 9 * (size_t)k;
const float oc[3] = {o.c[0], o.c[1], o.c[2]};
const d8 dz = 0.0;
typedef __typeof__(dz < dz) l8; /* the mask type of a float64 comparison */
float best = best_t;
int found = -1;
double ev_found = 0.0, ew_found = 0.0, det_found = 1.0;
for (int b = 0; b < k; b += 8) {
    f8 w[3][3]; /* [vertex][axis]: the vertex minus the origin, as intersect_triangle's a = p0 - o */
    for (int v = 0; v < 3; ++v)
        for (int a = 0; a < 3; ++a) {
            f8 x;
            __builtin_memcpy(&x, R + (3 * v + a) * (size_t)k + b, sizeof(f8));
            w[v][a] = x - oc[a];
        }
    d8 ex[3], ey[3];
    f8 ez[3];
    for (int v = 0; v < 3; ++v) {
        ex[v] = __builtin_convertvector(w[v][kx] - sx * w[v][kz], d8);
        ey[v] = __builtin_convertvector(w[v][ky] - sy * w[v][kz], d8);
        ez[v] = w[v][kz];
    }
    /* Woop's edge functions in float64 (a = vertex 0, b = vertex 1, c = vertex 2) */
    d8 eu = ex[2] * ey[1] - ey[2] * ex[1];
    d8 ev = ex[0] * ey[2] - ey[0] * ex[2];
    d8 ew = ex[1] * ey[0] - ey[1] * ex[0];
    l8 neg = (eu < dz) | (ev < dz) | (ew < dz);
    l8 pos = (eu > dz) | (ev > dz) | (ew > dz);
    d8 det = eu + ev + ew;
    l8 ok = ~(neg & pos) & (det != dz);
    d8 tt = (eu * __builtin_convertvector(sz * ez[0], d8) + ev * __builtin_convertvector(sz * ez[1], d8)
             + ew * __builtin_convertvector(sz * ez[2], d8)) / det;
    f8 t = __builtin_convertvector(tt, f8);
    i8 in = __builtin_convertvector(ok, i8) & (t > tlo) & (t <= best);
    unsigned int m = 0;
    for (int j = 0; j < 8; ++j) m |= (in[j] != 0 && b + j < k) ? (1u << j) : 0u;
    while (m) {
        int j = __builtin_ctz(m);
        m &= m - 1;
        int f = P[b + j];
        float tj = t[j];
        if (tj <= best && (tj < best || f < prim)) {
            best = tj;
            prim = f;
            found = b + j;
            ev_found = ev[j];
            ew_found = ew[j];
            det_found = det[j];
            if (any_hit) { m = 0; b = k; }
        }
    }
}
