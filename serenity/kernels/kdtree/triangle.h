// The one-ray leaf test's SIMD half (triangle.py's leaf_pick): leaf8.h's 8-lane test on the CPU;
// on CUDA -2, for which intersect_leaf runs its loop over the leaf's triangles.

int leaf_pick(wp::array_t<float> refs, int first, int k, wp::vec3 o, int kx, int ky, int kz, float sx, float sy,
              float sz, float tlo, float best_t, int prim, int any_hit)
{
#if defined(__CUDA_ARCH__)
    return -2;
#else
#include "leaf8.h"
    return found;
#endif
}
