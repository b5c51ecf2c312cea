// DEINTERLEAVE16(out, ptr, V): 16 vec3 from the float pointer ptr (x, y, z of each in turn), loaded
// as three vectors of type V (16 float lanes) and split by shuffles into out[0], out[1], out[2]
// (x, y, z of every lane). Included inside a CPU-only native's body.
#define DEINTERLEAVE16(out, ptr, V)                                                                             \
    do {                                                                                                        \
        V v0_, v1_, v2_, t_;                                                                                    \
        const float* p_ = (ptr);                                                                                \
        __builtin_memcpy(&v0_, p_, sizeof(V));                                                                  \
        __builtin_memcpy(&v1_, p_ + 16, sizeof(V));                                                             \
        __builtin_memcpy(&v2_, p_ + 32, sizeof(V));                                                             \
        t_ = __builtin_shufflevector(v0_, v1_, 0, 3, 6, 9, 12, 15, 18, 21, 24, 27, 30, 0, 0, 0, 0, 0);          \
        out[0] = __builtin_shufflevector(t_, v2_, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 17, 20, 23, 26, 29);        \
        t_ = __builtin_shufflevector(v0_, v1_, 1, 4, 7, 10, 13, 16, 19, 22, 25, 28, 31, 0, 0, 0, 0, 0);         \
        out[1] = __builtin_shufflevector(t_, v2_, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 18, 21, 24, 27, 30);        \
        t_ = __builtin_shufflevector(v0_, v1_, 2, 5, 8, 11, 14, 17, 20, 23, 26, 29, 0, 0, 0, 0, 0, 0);          \
        out[2] = __builtin_shufflevector(t_, v2_, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 16, 19, 22, 25, 28, 31);        \
    } while (0)
