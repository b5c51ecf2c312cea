// The CPU's reordering passes (cpu/sort.py): the keys of 16 rays at a time, the counting sort's
// prefetches, the gather and scatter loops. CPU only: the loader makes each a __trap() on CUDA.
// Constants from cpu/sort.py: KEY_LANES, ORIGIN_MASK, DIRECTION_MASK, ORIGIN_CELLS_MAX,
// DIRECTION_CELLS, DIRECTION_CELLS_MAX, FINE_BITS, FINE_MASK, DIRECTION_KEY_BITS, FLT_MAX_F,
// GATHER_PREFETCH, SCATTER_PREFETCH.

void keys_simd(wp::vec3 box_lo, wp::vec3 scale, wp::array_t<wp::vec3> origins, wp::array_t<wp::vec3> directions,
               wp::array_t<wp::uint32> keys, int first)
{
#include "lanes16.h"
#include "../spread.h"
    typedef float kf __attribute__((ext_vector_type(KEY_LANES)));
    typedef int ki __attribute__((ext_vector_type(KEY_LANES)));
    kf o[3], d[3];
    DEINTERLEAVE16(o, (const float*)origins.data + 3 * (size_t)first, kf);
    DEINTERLEAVE16(d, (const float*)directions.data + 3 * (size_t)first, kf);
    const kf zero = 0.0f;
    const kf cells = ORIGIN_CELLS_MAX;
    const kf dcells = DIRECTION_CELLS_MAX;
    ki q[3];
    for (int a = 0; a < 3; ++a) {
        kf f = (o[a] - box_lo.c[a]) * scale.c[a];
        f = f >= zero ? f : zero;
        f = f < cells ? f : cells;
        ki x = __builtin_convertvector(f, ki) & ORIGIN_MASK;
        SPREAD3(x);
        q[a] = x;
    }
    ki origin = q[0] | (q[1] << 1) | (q[2] << 2);
    kf ax = (kf)((ki)d[0] & 0x7FFFFFFF);
    kf ay = (kf)((ki)d[1] & 0x7FFFFFFF);
    kf az = (kf)((ki)d[2] & 0x7FFFFFFF);
    ki octant = ((d[0] < zero) & 1) | ((d[1] < zero) & 2) | ((d[2] < zero) & 4);
    kf l1 = (ax + ay) + az;
    kf s = ((l1 > zero) & (l1 <= FLT_MAX_F)) ? DIRECTION_CELLS / l1 : zero;
    kf fu = s > zero ? ax * s : zero;
    kf fv = s > zero ? ay * s : zero;
    fu = fu < dcells ? fu : dcells;
    fv = fv < dcells ? fv : dcells;
    ki uv[2] = {__builtin_convertvector(fu, ki), __builtin_convertvector(fv, ki)};
    for (int a = 0; a < 2; ++a) {
        ki x = uv[a] & DIRECTION_MASK;
        SPREAD2(x);
        uv[a] = x;
    }
    ki direction = uv[0] | (uv[1] << 1);
    ki coarse = origin >> FINE_BITS;
    ki key = ((((coarse << 3) | octant) << FINE_BITS) | (origin & FINE_MASK)) << DIRECTION_KEY_BITS | direction;
    __builtin_memcpy((unsigned int*)keys.data + (size_t)first, &key, sizeof(key));
}

void prefetch_low_place(wp::array_t<wp::uint32> keys, wp::array_t<int> starts, wp::array_t<int> first,
                        wp::array_t<wp::uint16> high, int base, int mask, int ahead, int end)
{
    if (ahead < keys.shape[0] && ahead < end) {
        const int b = base + (int)(keys.data[ahead] & mask);
        const int j = starts.data[b];
        __builtin_prefetch(first.data + j, 1, 3);
        __builtin_prefetch(high.data + j, 1, 3);
    }
}

void prefetch_high_place(wp::array_t<wp::uint16> high, wp::array_t<int> starts, wp::array_t<int> order, int base,
                         int ahead, int end)
{
    if (ahead < end) __builtin_prefetch(order.data + starts.data[base + (int)high.data[ahead]], 1, 3);
}

void move_range(wp::array_t<int> order, wp::uint64 src, wp::uint64 dst, int size, int scatter, int first, int count)
{
    const int* ord = order.data;
    const char* S = (const char*)src;
    char* D = (char*)dst;
    const int n = order.shape[0];
    const int end = first + count;
    /* gather: D[i] = S[ord[i]], the source prefetched; scatter: D[ord[i]] = S[i], the target prefetched
       for writing; the element's size a constant in the common cases */
#define SERENITY_MOVE(SIZE)                                                                 \
    for (int i = first; i < end; ++i) {                                                     \
        if (scatter) {                                                                      \
            if (i + SCATTER_PREFETCH < n)                                                   \
                __builtin_prefetch(D + (SIZE) * (size_t)ord[i + SCATTER_PREFETCH], 1, 3);   \
            __builtin_memcpy(D + (SIZE) * (size_t)ord[i], S + (SIZE) * (size_t)i, (SIZE));  \
        } else {                                                                            \
            if (i + GATHER_PREFETCH < n)                                                    \
                __builtin_prefetch(S + (SIZE) * (size_t)ord[i + GATHER_PREFETCH], 0, 3);    \
            __builtin_memcpy(D + (SIZE) * (size_t)i, S + (SIZE) * (size_t)ord[i], (SIZE));  \
        }                                                                                   \
    }
    switch (size) {
        case 4: SERENITY_MOVE(4) break;
        case 12: SERENITY_MOVE(12) break;
        case 16: SERENITY_MOVE(16) break;
        default: SERENITY_MOVE(size) break;
    }
#undef SERENITY_MOVE
}

void scatter_hits_range(wp::array_t<int> order, wp::array_t<float> t, wp::array_t<int> prim, wp::array_t<float> u,
                        wp::array_t<float> v, wp::array_t<wp::vec4> records, int first, int count)
{
    const int* ord = order.data;
    char* R = (char*)records.data;
    const int n = order.shape[0];
    const int end = first + count;
    for (int i = first; i < end; ++i) {
        if (i + SCATTER_PREFETCH < n)
            __builtin_prefetch(R + 16 * (size_t)ord[i + SCATTER_PREFETCH], 1, 3);
        float rec[4];
        rec[0] = t.data[i];
        __builtin_memcpy(rec + 1, prim.data + i, 4);
        rec[2] = u.data[i];
        rec[3] = v.data[i];
        __builtin_memcpy(R + 16 * (size_t)ord[i], rec, 16);
    }
}
