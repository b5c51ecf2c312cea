"""The propagation's per-iteration bookkeeping on the device: after each iteration of the
per-iteration launches (``LightPropagationVolume.propagate`` where it does not run them in one
launch), which cascades go on — without bringing the cells' sums to the host each iteration, which
on CUDA is a copy and a wait per iteration. The one-launch loop (``propagate_kernel(loop=True)``)
applies the same rule inside its single thread."""

from __future__ import annotations

import warp as wp

from serenity.kernels.lpv.grid import Cascade


@wp.kernel(enable_backward=False)
def level_stop(
    change: wp.array(dtype=float),
    total: wp.array(dtype=float),
    levels: wp.array(dtype=Cascade),
    iters: wp.array(dtype=int),
    k: int,
    thresh: wp.float64,
    level_on: wp.array(dtype=int),
    done: wp.array(dtype=int),
):
    """One thread per cascade l, after iteration k ran over the cascades with level_on[l] = 1: counts
    it in done[l]; the cascade stops when it has run iters[l] iterations or (thresh > 0) when what it
    gathered in this one (Σ change over its cells, float64, in cell order) is at most thresh × its
    accumulated light (Σ total), or that is 0."""
    l = wp.tid()
    if level_on[l] == 0:
        return
    done[l] = done[l] + 1
    if iters[l] <= k + 1:
        level_on[l] = 0
        return
    if thresh > wp.float64(0.0):
        e = levels[l]
        c = wp.float64(0.0)
        t = wp.float64(0.0)
        for i in range(e.cell_base, e.cell_base + e.res * e.res * e.res):
            c = c + wp.float64(change[i])
            t = t + wp.float64(total[i])
        if c <= thresh * t or t <= wp.float64(0.0):
            level_on[l] = 0
