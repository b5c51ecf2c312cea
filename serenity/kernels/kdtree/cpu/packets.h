// The packet traversal's lane arithmetic (cpu/packets.py): Warp's CPU code is scalar, and clang's
// vector extensions (the module is compiled for the host CPU, so AVX2/AVX-512 where there is one)
// do one node's step for all lanes in a few vector instructions. The arithmetic is the one-ray
// traversal's (traverse.py), lane by lane, in the same float32 operations (no contraction), so every
// lane makes its choices. CPU only: the loader makes each a __trap() on CUDA.
// The packet's workspace s from base, PK_LANES floats per row: origin and inverse direction per
// axis (PK_O, PK_IA), interval tolerance (PK_TE), current interval (PK_T0, PK_T1), best hit t
// (PK_BT), interval at the root box (PK_S0, PK_S1), Woop's axes and shears (PK_KX, PK_SX, 3 rows
// each), octant (PK_OCT), the best hit of leaf_simd (PK_HIT: t, u, v), then a (t0, t1) pair of rows
// per stack level (PK_STACK). Constants from cpu/packets.py, with FLT_MAX_F, T_TOLERANCE_F, TINY_F.

long long packet_step(wp::array_t<float> s, int base, int axis, float split, int a_side, int level)
{
#include "packet_lanes.h"
    pk_f o = PK_LD(PK_O + axis * PK_LANES);
    pk_f ia = PK_LD(PK_IA + axis * PK_LANES);
    pk_f te = PK_LD(PK_TE);
    pk_f t0 = PK_LD(PK_T0);
    pk_f t1 = PK_LD(PK_T1);
    pk_f bt = PK_LD(PK_BT);
    pk_f ts = (split - o) * ia;
    pk_f tn = ts + te;
    pk_f tf = ts - te;
    auto near_only = (ts <= 0.0f) | (ts > t1 + te);
    auto far_only = ~near_only & (ts < t0 - te);
    auto both = ~(near_only | far_only);
    float sgn = a_side ? -1.0f : 1.0f;
    auto origin_b = (o - split) * sgn >= 0.0f;
    auto go_a = (near_only & ~origin_b) | both;
    auto go_b = ~go_a | both;
    pk_f a_t1 = (both & (tn < t1)) ? tn : t1;
    pk_f b_t0 = (both & (tf > t0)) ? tf : t0;
    PK_ST(PK_STACK + level * 2 * PK_LANES, b_t0);
    PK_ST(PK_STACK + level * 2 * PK_LANES + PK_LANES, t1);
    PK_ST(PK_T1, a_t1);
    pk_f first_t1 = go_a ? a_t1 : t1;
    long long m = PK_MASK(go_a) | (PK_MASK(go_b) << 20) | (PK_MASK(bt <= first_t1) << 40);
    return m;
}

int packet_pop(wp::array_t<float> s, int base, int level)
{
#include "packet_lanes.h"
    pk_f t0 = PK_LD(PK_STACK + level * 2 * PK_LANES);
    pk_f t1 = PK_LD(PK_STACK + level * 2 * PK_LANES + PK_LANES);
    pk_f bt = PK_LD(PK_BT);
    PK_ST(PK_T0, t0);
    PK_ST(PK_T1, t1);
    int m = (int)PK_MASK(t0 <= bt);
    return m;
}

int lowest_lane(int x)
{
    return __builtin_ctz((unsigned)x);
}

long long packet_setup(wp::vec3 lo, wp::vec3 hi, float scale, wp::array_t<wp::vec3> origins,
                       wp::array_t<wp::vec3> directions, wp::array_t<float> tmax, float tmin_, int first, int count,
                       wp::array_t<float> s, int base)
{
#include "packet_lanes.h"
#include "lanes16.h"
    typedef int pk_i __attribute__((ext_vector_type(PK_LANES)));
    pk_f o[3], d[3], tm;
    if (count == PK_LANES) {
        DEINTERLEAVE16(o, (const float*)origins.data + 3 * (size_t)first, pk_f);
        DEINTERLEAVE16(d, (const float*)directions.data + 3 * (size_t)first, pk_f);
        __builtin_memcpy(&tm, (const float*)tmax.data + (size_t)first, sizeof(pk_f));
    } else {
        float ob[3 * PK_LANES] = {0}, db[3 * PK_LANES] = {0}, tb[PK_LANES] = {0};
        __builtin_memcpy(ob, (const float*)origins.data + 3 * (size_t)first, 12 * (size_t)count);
        __builtin_memcpy(db, (const float*)directions.data + 3 * (size_t)first, 12 * (size_t)count);
        __builtin_memcpy(tb, (const float*)tmax.data + (size_t)first, 4 * (size_t)count);
        DEINTERLEAVE16(o, ob, pk_f);
        DEINTERLEAVE16(d, db, pk_f);
        __builtin_memcpy(&tm, tb, sizeof(pk_f));
    }
    const pk_f zero = 0.0f, one = 1.0f, fmax_ = FLT_MAX_F, inf_ = __builtin_inff();
    pk_i lane;
    for (int r = 0; r < PK_LANES; ++r) lane[r] = r;
#define PK_ABS(x) ((pk_f)((pk_i)(x) & 0x7FFFFFFF))
#define PK_FINITE(x) (PK_ABS(x) <= fmax_)
    pk_f ad[3] = {PK_ABS(d[0]), PK_ABS(d[1]), PK_ABS(d[2])};
    /* setup_ray: the dominant axis kz, kx and ky after it (swapped when d[kz] < 0), the shears */
    pk_i c0 = (ad[0] >= ad[1]) & (ad[0] >= ad[2]);
    pk_i c1 = ~c0 & (ad[1] >= ad[2]);
    pk_i kz = (~c0 & ~c1 & 2) | (c1 & 1);
    pk_i kx = (kz == 2) ? 0 : kz + 1;
    pk_i ky = (kx == 2) ? 0 : kx + 1;
#define PK_PICK(v, k) (((k) == 0) ? (v)[0] : (((k) == 1) ? (v)[1] : (v)[2]))
    pk_f dkz = PK_PICK(d, kz);
    pk_i neg = dkz < zero;
    pk_i kx2 = neg ? ky : kx;
    pk_i ky2 = neg ? kx : ky;
    pk_f sx = PK_PICK(d, kx2) / dkz;
    pk_f sy = PK_PICK(d, ky2) / dkz;
    pk_f sz = one / dkz;
    /* start_ray: validity, the inverse direction (0 where parallel), the root box clip */
    pk_f tlo = tmin_ > 0.0f ? tmin_ : 0.0f;
    pk_f t0 = tlo, t1 = tm;
    pk_i valid = lane < count;
    valid &= PK_FINITE(o[0]) & PK_FINITE(o[1]) & PK_FINITE(o[2]) & PK_FINITE(d[0]) & PK_FINITE(d[1]) & PK_FINITE(d[2]);
    valid &= (PK_ABS(dkz) >= TINY_F) & PK_FINITE(sz) & (t1 > t0);
    pk_f inv[3];
    pk_i clip = valid;
    for (int a = 0; a < 3; ++a) {
        pk_f r = one / d[a];
        inv[a] = (clip & (d[a] != zero) & PK_FINITE(r)) ? r : zero;
    }
    for (int a = 0; a < 3; ++a) {
        pk_i par = inv[a] == zero;
        valid &= ~(clip & par & ((o[a] < lo.c[a]) | (o[a] > hi.c[a])));
        pk_f ta = (lo.c[a] - o[a]) * inv[a];
        pk_f tb = (hi.c[a] - o[a]) * inv[a];
        pk_f mn = ta < tb ? ta : tb;
        pk_f mx = ta > tb ? ta : tb;
        pk_i upd = clip & ~par;
        t0 = (upd & (mn > t0)) ? mn : t0;
        t1 = (upd & (mx < t1)) ? mx : t1;
    }
    pk_f ao = PK_ABS(o[0]) > PK_ABS(o[1]) ? PK_ABS(o[0]) : PK_ABS(o[1]);
    ao = PK_ABS(o[2]) > ao ? PK_ABS(o[2]) : ao;
    pk_f te = (T_TOLERANCE_F * (scale + ao)) * PK_ABS(sz);
    pk_i live = valid & ~(t0 > t1 + te);
    /* the packet's lanes: child order (octant) per axis, inverse direction +-inf where parallel */
    pk_i oc = 0;
    for (int a = 0; a < 3; ++a) {
        pk_i side = (inv[a] != zero) ? ((inv[a] < zero) & 1) : ((d[a] > zero) & 1);
        oc |= side << a;
        PK_ST(PK_O + a * PK_LANES, o[a]);
        PK_ST(PK_IA + a * PK_LANES, (inv[a] != zero) ? inv[a] : ((side != 0) ? -inf_ : inf_));
    }
    PK_ST(PK_TE, te);
    PK_ST(PK_BT, tm);
    PK_ST(PK_S0, t0);
    PK_ST(PK_S1, t1);
    PK_ST(PK_KX, __builtin_convertvector(kx2, pk_f));
    PK_ST(PK_KX + PK_LANES, __builtin_convertvector(ky2, pk_f));
    PK_ST(PK_KX + 2 * PK_LANES, __builtin_convertvector(kz, pk_f));
    PK_ST(PK_SX, sx);
    PK_ST(PK_SX + PK_LANES, sy);
    PK_ST(PK_SX + 2 * PK_LANES, sz);
    PK_ST(PK_OCT, __builtin_convertvector(oc, pk_f));
    long long octants = (long long)__builtin_reduce_or(live ? (1 << oc) : 0);
    long long m = PK_MASK(live) | (octants << 20);
    return m;
}

int packet_octant(wp::array_t<float> s, int base, int oc)
{
#include "packet_lanes.h"
    PK_ST(PK_T0, PK_LD(PK_S0));
    PK_ST(PK_T1, PK_LD(PK_S1));
    int m = (int)PK_MASK(PK_LD(PK_OCT) == (float)oc);
    return m;
}

int leaf_simd(wp::array_t<float> refs, int first, int k, wp::vec3 o, int kx, int ky, int kz, float sx, float sy,
              float sz, float tlo, float best_t, int prim, int any_hit, wp::array_t<float> s, int base)
{
#include "../leaf8.h"
    if (found >= 0) {
        s.data[base + PK_HIT] = best;
        s.data[base + PK_HIT + 1] = (float)(ev_found / det_found);
        s.data[base + PK_HIT + 2] = (float)(ew_found / det_found);
    }
    return prim;
}
