"""LPV propagation (package docstring, "Propagation", "Geometry volume", "Reach"): the faces'
transmittance and openness from the geometry volume, the gather of each cell from its 6 neighbours
(the paper's linear transfer or the clamped faces), compiled per setting by ``propagate_kernel``, and
the hand-over of the coarser cascades' far light into the finer ones.

Arrays (Warp, on the volume's device): the SH grids (vec4 per cell and channel, the package's
layout); per-cell arrays: ``trans_pos`` / ``trans_neg`` (vec3 over x, y, z) the transmittance of the
face through which a cell gathers from its neighbour at −axis / +axis, the openness of its high faces
and where their blockers lie (vec3), the cells' |DC| sums (float); the level table (``grid.Cascade``,
offsets only) and the cascade table (origin and cell size too).
"""

from __future__ import annotations

import warp as wp

from serenity.kernels.factory import kernel_factory
from serenity.kernels.lpv.basis import (
    C0,
    C1,
    INV_SQRT5,
    K0,
    K1,
    T_AX_AX,
    T_AX_DC,
    T_DC_AX,
    T_DC_DC,
    T_PERP,
    W_FRONT_C,
    W_SIDE_C,
)
from serenity.kernels.lpv.grid import Cascade, find_level, grid_coord, inside, sample_sh

wp.set_module_options({"enable_backward": False})


@wp.func
def gather_pair(out: wp.vec4, p: wp.vec4, m: wp.vec4, axis: int) -> wp.vec4:
    """Add what a cell gathers along one axis: ``p`` = (weighted) SH of the source at −e_axis
    (light travelling +e_axis), ``m`` = source at +e_axis (travelling −e_axis).

    The sparse transfer (``basis.TRANSFER``) for d = ±e_axis, summed for the pair: with σ = p + m,
    δ = p − m: out0 += T_DC_DC·σ0 + T_DC_AX·δ_a, out_a += T_AX_DC·δ0 + T_AX_AX·σ_a,
    out_⟂ += T_PERP·σ_⟂.
    """
    s = p + m
    d = p - m
    if axis == 0:
        return out + wp.vec4(T_DC_DC * s[0] + T_DC_AX * d[1], T_AX_DC * d[0] + T_AX_AX * s[1],
                             T_PERP * s[2], T_PERP * s[3])
    if axis == 1:
        return out + wp.vec4(T_DC_DC * s[0] + T_DC_AX * d[2], T_PERP * s[1],
                             T_AX_DC * d[0] + T_AX_AX * s[2], T_PERP * s[3])
    return out + wp.vec4(T_DC_DC * s[0] + T_DC_AX * d[3], T_PERP * s[1], T_PERP * s[2],
                         T_AX_DC * d[0] + T_AX_AX * s[3])


@wp.func
def face_emit(out: wp.vec4, phi: float, axis: int, sign: float) -> wp.vec4:
    """out + the clamped-cosine lobe of flux phi facing sign·e_axis: phi·(K0, K1·sign·e_axis)."""
    if axis == 0:
        return out + wp.vec4(K0 * phi, K1 * sign * phi, 0.0, 0.0)
    if axis == 1:
        return out + wp.vec4(K0 * phi, 0.0, K1 * sign * phi, 0.0)
    return out + wp.vec4(K0 * phi, 0.0, 0.0, K1 * sign * phi)


@wp.func
def gather_clamped(out: wp.vec4, s: wp.vec4, axis: int, sign: float) -> wp.vec4:
    """What a cell gathers from a source of SH s at −d, d = sign·e_axis, with every face's flux
    clamped at 0: Φ_f = Δω_f·max(0, I_s(ω_f)) (package doc, "Clamped faces"). The explicit 5-face sum
    of the package docstring, which ``gather_pair`` collapses to a linear 4×4 transfer without the clamp."""
    sd = sign * s[axis + 1]
    if s[0] >= 0.0 and C0 * C0 * s[0] * s[0] >= C1 * C1 * (s[1] * s[1] + s[2] * s[2] + s[3] * s[3]):
        # I_s ≥ 0 in every direction (C0·s0 ≥ C1·|s_xyz|, squared: no square root on this hot path):
        # no face is clamped, the linear transfer is exact (and cheaper)
        lin = wp.vec4(T_DC_DC * s[0] + T_DC_AX * sd, T_PERP * s[1], T_PERP * s[2], T_PERP * s[3])
        lin[axis + 1] = sign * (T_AX_DC * s[0] + T_AX_AX * sd)
        return out + lin
    i_front = C0 * s[0] + C1 * sd
    out = face_emit(out, W_FRONT_C * wp.max(i_front, 0.0), axis, sign)
    for k in range(2):
        e = (axis + 1 + k) % 3
        se = s[e + 1]
        base = C0 * s[0] + C1 * INV_SQRT5 * 2.0 * sd
        out = face_emit(out, W_SIDE_C * wp.max(base + C1 * INV_SQRT5 * se, 0.0), e, 1.0)
        out = face_emit(out, W_SIDE_C * wp.max(base - C1 * INV_SQRT5 * se, 0.0), e, -1.0)
    return out


@wp.func
def gv_at(gv: wp.array(dtype=wp.vec4), base: int, r1: int, x: int, y: int, z: int) -> wp.vec4:
    return gv[base + (z * r1 + y) * r1 + x]


@wp.func
def gv_face(gv: wp.array(dtype=wp.vec4), base: int, r1: int, axis: int, x: int, y: int, z: int) -> wp.vec4:
    """Mean blocking SH of the 4 geometry cells at the corners of the face ⟂ axis whose low corner is (x,y,z)."""
    if axis == 0:
        return 0.25 * (gv_at(gv, base, r1, x, y, z) + gv_at(gv, base, r1, x, y + 1, z)
                       + gv_at(gv, base, r1, x, y, z + 1) + gv_at(gv, base, r1, x, y + 1, z + 1))
    if axis == 1:
        return 0.25 * (gv_at(gv, base, r1, x, y, z) + gv_at(gv, base, r1, x + 1, y, z)
                       + gv_at(gv, base, r1, x, y, z + 1) + gv_at(gv, base, r1, x + 1, y, z + 1))
    return 0.25 * (gv_at(gv, base, r1, x, y, z) + gv_at(gv, base, r1, x + 1, y, z)
                   + gv_at(gv, base, r1, x, y + 1, z) + gv_at(gv, base, r1, x + 1, y + 1, z))


@wp.func
def eval_transmittance(b: wp.vec4, axis: int, sign: float) -> float:
    """1 − clamp(B(−d)) for light travelling along d = sign·e_axis through a face of blocking SH b."""
    blk = C0 * b[0] - sign * C1 * b[axis + 1]
    return 1.0 - wp.clamp(blk, 0.0, 1.0)



@wp.kernel(enable_backward=False)
def eval_face_transmittance(
    # inputs
    gv: wp.array(dtype=wp.vec4),
    levels: wp.array(dtype=Cascade),
    n_levels: int,
    # outputs
    trans_pos: wp.array(dtype=wp.vec3),
    trans_neg: wp.array(dtype=wp.vec3),
    opn: wp.array(dtype=wp.vec3),
    plane: wp.array(dtype=wp.vec3),
    planes: int,
    flags: int,
    offset: int,
):
    """Per receiving cell: transmittance of the face shared with the source at −d, for d = ±x, ±y, ±z;
    and the openness of its three high faces (+x, +y, +z) for the lookup occlusion: 1 − clamp(B(d) or
    B(−d), whichever blocks more) = 1 − clamp(C0·b0 + C1·|b_axis|, 0, 1). With ``planes`` (the offset
    of the blockers' moments in ``gv``, 0: none) and ``flags`` & 2 (lookup planes) also where each high
    face's blocker lies (``plane``), and the openness is at most 1 − clamp(Σ w_axis) (projected
    coverage); with ``flags`` & 1 the transmittances are too (package doc, "Coverage blocking")."""
    i = wp.tid() + offset
    l = find_level(i, levels, n_levels)
    if l < 0:
        return
    e = levels[l]
    res = e.res
    k = i - e.cell_base
    x = k % res
    y = (k // res) % res
    z = k // (res * res)
    r1 = res + 1
    b = e.gv_base
    tp = wp.vec3()
    tn = wp.vec3()
    tp[0] = eval_transmittance(gv_face(gv, b, r1, 0, x, y, z), 0, 1.0)
    tn[0] = eval_transmittance(gv_face(gv, b, r1, 0, x + 1, y, z), 0, -1.0)
    tp[1] = eval_transmittance(gv_face(gv, b, r1, 1, x, y, z), 1, 1.0)
    tn[1] = eval_transmittance(gv_face(gv, b, r1, 1, x, y + 1, z), 1, -1.0)
    tp[2] = eval_transmittance(gv_face(gv, b, r1, 2, x, y, z), 2, 1.0)
    tn[2] = eval_transmittance(gv_face(gv, b, r1, 2, x, y, z + 1), 2, -1.0)
    if planes > 0 and flags % 2 == 1:
        # an opaque face blocks light from either side: at most 1 − its projected coverage Σ A·n_a²/s²
        c2 = b + 2 * planes
        tp[0] = wp.min(tp[0], 1.0 - wp.clamp(gv_face(gv, c2, r1, 0, x, y, z)[0], 0.0, 1.0))
        tn[0] = wp.min(tn[0], 1.0 - wp.clamp(gv_face(gv, c2, r1, 0, x + 1, y, z)[0], 0.0, 1.0))
        tp[1] = wp.min(tp[1], 1.0 - wp.clamp(gv_face(gv, c2, r1, 1, x, y, z)[1], 0.0, 1.0))
        tn[1] = wp.min(tn[1], 1.0 - wp.clamp(gv_face(gv, c2, r1, 1, x, y + 1, z)[1], 0.0, 1.0))
        tp[2] = wp.min(tp[2], 1.0 - wp.clamp(gv_face(gv, c2, r1, 2, x, y, z)[2], 0.0, 1.0))
        tn[2] = wp.min(tn[2], 1.0 - wp.clamp(gv_face(gv, c2, r1, 2, x, y, z + 1)[2], 0.0, 1.0))
    trans_pos[i] = tp
    trans_neg[i] = tn
    o = wp.vec3()
    bx = gv_face(gv, b, r1, 0, x + 1, y, z)
    by = gv_face(gv, b, r1, 1, x, y + 1, z)
    bz = gv_face(gv, b, r1, 2, x, y, z + 1)
    o[0] = 1.0 - wp.clamp(C0 * bx[0] + C1 * wp.abs(bx[1]), 0.0, 1.0)
    o[1] = 1.0 - wp.clamp(C0 * by[0] + C1 * wp.abs(by[2]), 0.0, 1.0)
    o[2] = 1.0 - wp.clamp(C0 * bz[0] + C1 * wp.abs(bz[3]), 0.0, 1.0)
    opn[i] = o
    if planes > 0 and flags >= 2:
        # where the blocker of each high face lies, relative to the face (cells, in [−½, ½]; 0: none)
        t = wp.vec3()
        px = gv_face(gv, b + planes, r1, 0, x + 1, y, z)
        wx = gv_face(gv, b + 2 * planes, r1, 0, x + 1, y, z)
        py = gv_face(gv, b + planes, r1, 1, x, y + 1, z)
        wy = gv_face(gv, b + 2 * planes, r1, 1, x, y + 1, z)
        pz = gv_face(gv, b + planes, r1, 2, x, y, z + 1)
        wz = gv_face(gv, b + 2 * planes, r1, 2, x, y, z + 1)
        if wx[0] > 1.0e-6:
            t[0] = wp.clamp(px[0] / wx[0], -0.5, 0.5)
        if wy[1] > 1.0e-6:
            t[1] = wp.clamp(py[1] / wy[1], -0.5, 0.5)
        if wz[2] > 1.0e-6:
            t[2] = wp.clamp(pz[2] / wz[2], -0.5, 0.5)
        # quantised to 1/254 cell: what the GL twin unpacks (LightPropagationVolume.openness)
        for a in range(3):
            t[a] = wp.round((t[a] + 0.5) * 254.0) / 254.0 - 0.5
        plane[i] = t
        # a lookup is blocked by a face's projected coverage Σ A·n_a²/s² too, whichever side the surfels
        # face (two-sided, the L1 blocking above is only 2/3)
        o[0] = wp.min(o[0], 1.0 - wp.clamp(wx[0], 0.0, 1.0))
        o[1] = wp.min(o[1], 1.0 - wp.clamp(wy[1], 0.0, 1.0))
        o[2] = wp.min(o[2], 1.0 - wp.clamp(wz[2], 0.0, 1.0))
        opn[i] = o


@kernel_factory(geometry_volume=(False, True), clamp_faces=(False, True), loop=(False, True))
def propagate_kernel(geometry_volume: bool, clamp_faces: bool = False, loop: bool = False):
    """The propagation kernel, geometry volume and the face clamp (package doc, "Clamped faces")
    compiled in or out. ``loop=False``: one iteration, one thread per cell (one launch covers every
    cascade). ``loop=True``: every iteration in one single-threaded launch, cascades stopping as
    their counts or the early stop say (``LightPropagationVolume.propagate``: on the CPU, a launch
    per iteration cost more Python than the few thousand cells of a 12³ cascade cost to compute)."""

    @wp.func
    def propagate_cell(
        i: int,
        l: int,
        src: wp.array(dtype=wp.vec4),
        acc_src: wp.array(dtype=wp.vec4),
        trans_pos: wp.array(dtype=wp.vec3),
        trans_neg: wp.array(dtype=wp.vec3),
        levels: wp.array(dtype=Cascade),
        far_from: wp.array(dtype=int),
        iteration: int,
        dst: wp.array(dtype=wp.vec4),
        accum: wp.array(dtype=wp.vec4),
        far: wp.array(dtype=wp.vec4),
    ) -> wp.vec2:
        """Cell i (of level l) gathers one iteration from its 6 neighbours in ``src``: written to
        ``dst``, added to ``accum`` (and to ``far`` past the level's hand-over iteration); returns
        (Σ_RGB |DC| of what it gathered, Σ_RGB |DC| of its accumulated light)."""
        e = levels[l]
        res = e.res
        k = i - e.cell_base
        x = k % res
        y = (k // res) % res
        z = k // (res * res)
        n3 = res * res * res
        rr = res * res
        tp = wp.vec3(1.0, 1.0, 1.0)
        tn = wp.vec3(1.0, 1.0, 1.0)
        if wp.static(geometry_volume):
            tp = trans_pos[i]
            tn = trans_neg[i]
        dc_change = float(0.0)
        dc_total = float(0.0)
        to_far = iteration >= far_from[l]
        for ch in range(3):
            j = e.base + ch * n3 + k
            out = wp.vec4()
            if wp.static(clamp_faces):
                if x > 0:
                    out = gather_clamped(out, tp[0] * src[j - 1], 0, 1.0)
                if x < res - 1:
                    out = gather_clamped(out, tn[0] * src[j + 1], 0, -1.0)
                if y > 0:
                    out = gather_clamped(out, tp[1] * src[j - res], 1, 1.0)
                if y < res - 1:
                    out = gather_clamped(out, tn[1] * src[j + res], 1, -1.0)
                if z > 0:
                    out = gather_clamped(out, tp[2] * src[j - rr], 2, 1.0)
                if z < res - 1:
                    out = gather_clamped(out, tn[2] * src[j + rr], 2, -1.0)
            else:
                # x pair: p = source at x−1 (light travelling +x), m = source at x+1
                p = wp.vec4()
                m = wp.vec4()
                if x > 0:
                    p = tp[0] * src[j - 1]
                if x < res - 1:
                    m = tn[0] * src[j + 1]
                out = gather_pair(out, p, m, 0)
                p = wp.vec4()
                m = wp.vec4()
                if y > 0:
                    p = tp[1] * src[j - res]
                if y < res - 1:
                    m = tn[1] * src[j + res]
                out = gather_pair(out, p, m, 1)
                p = wp.vec4()
                m = wp.vec4()
                if z > 0:
                    p = tp[2] * src[j - rr]
                if z < res - 1:
                    m = tn[2] * src[j + rr]
                out = gather_pair(out, p, m, 2)
            dst[j] = out
            a = acc_src[j] + out
            accum[j] = a
            if to_far:
                far[j] = far[j] + out
            dc_change += wp.abs(out[0])
            dc_total += wp.abs(a[0])
        return wp.vec2(dc_change, dc_total)

    if not loop:

        @wp.kernel(enable_backward=False, module="unique")
        def propagate_lpv(
            # inputs
            src: wp.array(dtype=wp.vec4),
            acc_src: wp.array(dtype=wp.vec4),
            trans_pos: wp.array(dtype=wp.vec3),
            trans_neg: wp.array(dtype=wp.vec3),
            levels: wp.array(dtype=Cascade),
            n_levels: int,
            level_on: wp.array(dtype=int),
            far_from: wp.array(dtype=int),
            iteration: int,
            # outputs
            dst: wp.array(dtype=wp.vec4),
            accum: wp.array(dtype=wp.vec4),
            far: wp.array(dtype=wp.vec4),
            change: wp.array(dtype=float),
            total: wp.array(dtype=float),
            offset: int,
        ):
            i = wp.tid() + offset
            l = find_level(i, levels, n_levels)
            if l < 0:
                return
            if level_on[l] == 0:
                return
            ct = propagate_cell(i, l, src, acc_src, trans_pos, trans_neg, levels, far_from, iteration, dst, accum,
                                far)
            change[i] = ct[0]
            total[i] = ct[1]

        return propagate_lpv

    @wp.kernel(enable_backward=False, module="unique")
    def propagate_lpv_loop(
        # inputs
        inj: wp.array(dtype=wp.vec4),
        trans_pos: wp.array(dtype=wp.vec3),
        trans_neg: wp.array(dtype=wp.vec3),
        levels: wp.array(dtype=Cascade),
        n_levels: int,
        iters: wp.array(dtype=int),
        far_from: wp.array(dtype=int),
        n_iter: int,
        lo: int,
        hi: int,
        thresh: wp.float64,
        # in/out
        level_on: wp.array(dtype=int),
        ping: wp.array(dtype=wp.vec4),
        pong: wp.array(dtype=wp.vec4),
        accum: wp.array(dtype=wp.vec4),
        far: wp.array(dtype=wp.vec4),
        # outputs
        done: wp.array(dtype=int),
        sums: wp.array(dtype=wp.float64),
        offset: int,
    ):
        """Iterations k = 0 … n_iter−1 over cells [lo, hi) of the levels still on: iteration k reads
        ``inj`` (k = 0) or the ping-pong buffer k−1 wrote and writes buffer k % 2 (ping, pong); a level
        stops after iters[l] iterations, or (thresh > 0) once what it gathered in an iteration is at most
        thresh × its accumulated light (Σ over its cells, float64). done[l]: the iterations it ran."""
        for l in range(n_levels):
            done[l] = 0
        for k in range(n_iter):
            live = int(0)
            for l in range(n_levels):
                if level_on[l] != 0 and iters[l] <= k:
                    level_on[l] = 0
                live += level_on[l]
                sums[2 * l] = wp.float64(0.0)
                sums[2 * l + 1] = wp.float64(0.0)
            if live == 0:
                break
            for i in range(lo, hi):
                l = find_level(i, levels, n_levels)
                if l >= 0:
                    if level_on[l] != 0:
                        ct = wp.vec2()
                        if k == 0:
                            ct = propagate_cell(i, l, inj, accum, trans_pos, trans_neg, levels, far_from, k + 1,
                                                ping, accum, far)
                        elif k % 2 == 0:
                            ct = propagate_cell(i, l, pong, accum, trans_pos, trans_neg, levels, far_from, k + 1,
                                                ping, accum, far)
                        else:
                            ct = propagate_cell(i, l, ping, accum, trans_pos, trans_neg, levels, far_from, k + 1,
                                                pong, accum, far)
                        sums[2 * l] = sums[2 * l] + wp.float64(ct[0])
                        sums[2 * l + 1] = sums[2 * l + 1] + wp.float64(ct[1])
            for l in range(n_levels):
                if level_on[l] != 0:
                    done[l] = done[l] + 1
                    if thresh > wp.float64(0.0):
                        c = sums[2 * l]
                        t = sums[2 * l + 1]
                        if c <= thresh * t or t <= wp.float64(0.0):
                            level_on[l] = 0

    return propagate_lpv_loop


@wp.kernel(enable_backward=False)
def hand_over_far(
    # inputs
    far: wp.array(dtype=wp.vec4),
    cascades: wp.array(dtype=Cascade),
    n_cascades: int,
    c: int,
    # outputs
    accum: wp.array(dtype=wp.vec4),
    offset: int,
):
    """accum of active cascade c += Σ_{d>c} (s_c/s_d)²·far_d at each cell centre (trilinear): the
    light coarser cascades carried beyond the finer ones' reach (package doc, "Hand-over")."""
    i = wp.tid() + offset
    g = cascades[c]
    res = g.res
    n3 = res * res * res
    x = i % res
    y = (i // res) % res
    z = i // (res * res)
    centre = g.origin + g.cell * wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
    add_r = wp.vec4()
    add_g = wp.vec4()
    add_b = wp.vec4()
    for d in range(c + 1, n_cascades):
        gd = cascades[d]
        rd = gd.res
        u = grid_coord(gd, centre)
        if inside(u, rd):
            scale = (g.cell / gd.cell) * (g.cell / gd.cell)
            nd = rd * rd * rd
            add_r += scale * sample_sh(far, gd.base, rd, u)
            add_g += scale * sample_sh(far, gd.base + nd, rd, u)
            add_b += scale * sample_sh(far, gd.base + 2 * nd, rd, u)
    j = g.base + i
    accum[j] = accum[j] + add_r
    accum[j + n3] = accum[j + n3] + add_g
    accum[j + 2 * n3] = accum[j + 2 * n3] + add_b
