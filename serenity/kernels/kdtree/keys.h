// The Morton spreads of keys.py's ray_sort_key: one BMI2 pdep where the CPU has it (the module is
// compiled for the host CPU), else shifts and masks (spread.h: CUDA, other CPUs). As loops over
// the bits they took 15 ms for the keys of a 0.92 M-ray batch on one thread, pdep 10 ms: clang
// turned the loops into chains of vector shuffles. ORIGIN_MASK and DIRECTION_MASK (the low
// SORT_ORIGIN_BITS and SORT_DIRECTION_BITS bits) come from keys.py.

int spread_bits(int q)
{
#if defined(__BMI2__) && !defined(__CUDA_ARCH__)
    return (int)__builtin_ia32_pdep_si((unsigned int)q & ORIGIN_MASK, 0x49249249u);
#else
#include "spread.h"
    unsigned int x = (unsigned int)q & ORIGIN_MASK;
    SPREAD3(x);
    return (int)x;
#endif
}

int spread_bits2(int q)
{
#if defined(__BMI2__) && !defined(__CUDA_ARCH__)
    return (int)__builtin_ia32_pdep_si((unsigned int)q & DIRECTION_MASK, 0x55555555u);
#else
#include "spread.h"
    unsigned int x = (unsigned int)q & DIRECTION_MASK;
    SPREAD2(x);
    return (int)x;
#endif
}
