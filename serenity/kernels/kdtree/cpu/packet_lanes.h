// A packet's lanes as clang vectors (cpu/packets.h): pk_f (PK_LANES floats), pk_b (PK_LANES bools),
// and the loads and stores of a lane vector at float offset off of the packet's workspace s from
// base (PK_LD, PK_ST), and a lane mask from a comparison (PK_MASK: bit r set where lane r holds).
// Included inside a native's body.
typedef float pk_f __attribute__((ext_vector_type(PK_LANES)));
typedef bool pk_b __attribute__((ext_vector_type(PK_LANES)));
#define PK_LD(off) ({ pk_f v_; __builtin_memcpy(&v_, &s.data[base + (off)], sizeof(pk_f)); v_; })
#define PK_ST(off, v) do { pk_f w_ = (v); __builtin_memcpy(&s.data[base + (off)], &w_, sizeof(pk_f)); } while (0)
#define PK_MASK(c)                                          \
    ({                                                      \
        pk_b b_ = __builtin_convertvector((c), pk_b);       \
        unsigned int r_ = 0;                                \
        __builtin_memcpy(&r_, &b_, sizeof(b_));             \
        (long long)r_;                                      \
    })
