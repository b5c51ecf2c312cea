"""Light propagation volumes: VPL injection, geometry volume, propagation, lookup (paper §8).

Follows Kaplanyan 2009 ("Light Propagation Volumes in CryEngine 3") and Kaplanyan & Dachsbacher
2010 ("Cascaded Light Propagation Volumes for Real-Time Indirect Illumination"), as the paper's
§8 uses them: the sun's reflective shadow map and the sky-lit G-buffer (paper Fig. 11) are both
just arrays of virtual point lights (VPLs); they are injected into up to 3 nested grids around the
camera, propagated, and looked up for diffuse irradiance and glossy reflections (paper Fig. 10).

Inputs (numpy or Warp arrays on the volume's device; float32):
    VPLs:    positions (N,3) m, world space; normals (N,3) unit; flux (N,3) W per VPL per RGB channel
             (the light a Lambertian patch re-emits: ρ·E·A for a patch of area A). Built by
             ``serenity.raster.rsm.RSMPass.read`` (sun) and ``sky_vpls_from_gbuffer`` (sky, Fig. 11).
    Surfels: positions (M,3) m; normals (M,3) unit; areas (M,) m² (the surface area an RSM or
             G-buffer texel covers), for the geometry volume: ``rsm_surfels``, ``gbuffer_surfels``.

SH convention (shared with ``serenity/raster/glsl/lpv.glsl`` — mirror it exactly):
    Real L1 spherical harmonics, orthonormal, **stored in the order (Y0, x, y, z)** — not the
    l²+l+m order: basis Y(ω) = (C0, C1·ω.x, C1·ω.y, C1·ω.z), C0 = 1/(2√π), C1 = √3/(2√π).
    ω is the direction light **travels** (a VPL with normal n emits along ω with n·ω > 0; a
    surface with normal n receives light travelling along ω with n·ω < 0).

What is stored (per cascade, per cell, per RGB channel, 4 float32):
    the radiant intensity I(ω) in W/sr of the cell as SH, accumulated over the injection and all
    propagation iterations (Kaplanyan: the light that passes through the cell). A VPL of flux Φ
    and normal n adds I(ω) = Φ/π·max(0, n·ω), i.e. Φ·(C0, n/√(3π)) — its SH integrates to Φ.
    Device layout: one float4 array for all cascades; cascade level l starts at vec4 index
    3·Σ_{k<l} res_k³, then channel-major (R block, G block, B block), then z, y, x.

Lookup (units):
    radiance  L(ω) = I(ω)/s²  (W·m⁻²·sr⁻¹; s = cell size in m: the cell seen as a face of area s²)
    irradiance E(n) = ∫ L(ω)·max(0, -n·ω) dω = max(0, √π/2·l0 − √(π/3)·(l.xyz·n))  (W/m²),
        with l = L's SH, trilinear between cell centres (clamp to edge, = GL_LINEAR +
        CLAMP_TO_EDGE with texcoord u/res, u = (p − origin)/s in cells), taken at
        u = (p − origin)/s + lookup_offset·n. **Negative values are clamped to 0 per cascade and
        channel** (L1 ringing behind a lobe), so irradiance is never negative.
        Leak guard (``leak_guard``, on by default): the 8 trilinear cells i get weights
        w_i·g_i / Σ w_i·g_i instead of w_i, g_i = clamp(4·n·(c_i − u_s), 0, 1), c_i the cell
        centre and u_s the surface point (without the offset), both in cells: a cell whose centre
        lies behind the surface's plane does not light it, one 1/4 cell or more in front counts
        fully (plain trilinear if Σ w_i·g_i < 1e-4). Clamp to edge as above (indices clamped,
        centres of the clamped cells). Lookup occlusion (``lookup_occlusion``, with the leak guard and
        the geometry volume; default on): each cell's weight is also multiplied, for every axis on
        which it differs from the home cell h = ⌊u_s + n/4⌋, by the openness 1 − clamp(C0·b0 +
        C1·|b_axis|, 0, 1) of the geometry volume's face between them (taken in h's row): the light
        above a sunlit roof no longer reaches the top of the wall under the ceiling (the bright
        lines along the Cornell box's ceiling edges). Lookup planes (``lookup_planes``, default on):
        a blocker in a cell's lower half blocks the face below it, so a point between that face
        and the blocker shared the far side's cell. The geometry volume therefore also keeps,
        per geometry cell and axis a, Σ w_a·d_a and Σ w_a (w_a = A/s²·n_a², d_a the surfel's
        offset from the cell's corner, in [−½, ½)); a face's blocker lies t_a = Σ d_a·w_a / Σ w_a
        (mean over its 4 corners; quantised to 1/254 cell, as the GL twin reads it) from the face.
        The home cell h moves one cell down axis a when h's low face there is blocked and its
        blocker lies inside h beyond q = u_s + n/4 (t_a > q_a − h_a), up when its high face is
        and q lies beyond that blocker. The face's openness for lookups is also at most
        1 − clamp(Σ w_a, 0, 1) (projected coverage, whichever side the surfels face; the L1
        blocking of a two-sided slab is only 2/3). (An earlier +1 in g let cells up to 1/4 cell behind count:
        in the Cornell box that lit the ceiling's underside with the sunlit roof's VPLs, relMSE
        of the indirect image 467 → 260 at 32³ when removed.)
    glossy    mean over k = 1..glossy_steps of max(0, C0·l0 + A1·C1·(l.xyz·(−r))) at
        p + k·glossy_step·s0·r (r = unit reflected direction, s0 = finest active cell size),
        A1 = (m+1)/(m+2) the band-1 attenuation of a normalised Phong lobe of exponent m
        (W·m⁻²·sr⁻¹: the radiance arriving at p from around r, prefiltered by the lobe).
    cascades  finest first; d_c = distance of u to cascade c's box border in c's cells (< 0 outside);
        α_c = smoothstep(margin, margin + band, d_c) (band = 0: step(margin, d_c)) for all but
        the last active cascade, which has α = clamp(d_c + 1, 0, 1) (whole box, fading over one
        cell outside: there is nothing coarser to hand over to); E = Σ_c α_c·Π_{j<c}(1 − α_j)·E_c.

Propagation (Kaplanyan & Dachsbacher 2010 §5.1): each cell gathers from its 6 neighbours; light
from a neighbour in direction d is split onto the 5 faces of the receiving cell that are not shared
with the source — face flux Φ_f = Δω_f·I_src(ω_f), ω_f the direction from the source centre to
the face centre — and each face is re-emitted as a VPL at the receiving cell's centre facing the
face's outward normal (a clamped-cosine lobe of flux Φ_f). Solid angles seen from the source
centre (cell size 1): the face opposite the shared one, a 1×1 square at distance 1.5,
Δω_front = 4·asin(1/10) = 0.4006697 sr; each side face (1×1 at distance 0.5, offset 0.5..1.5
along d), Δω_side = 0.4234314 sr (exact rectangle formula, ``face_solid_angles``). 5 faces ×
6 neighbours cover the whole sphere: Δω_front + 4·Δω_side = 2π/3, so flux is conserved exactly
(the transfer is linear in the SH and the DC term's weights sum to 4π); light sent across the
grid's outer faces is lost. The 5-face sum collapses to a sparse 4×4 transfer per direction
(constants T_* in ``basis``; ``tests/kernels/test_lpv.py`` checks it against the explicit 5-face sum).
That linear transfer is the paper's (``clamp_faces=False``). Clamped faces (``clamp_faces``, default
on): an L1 lobe is negative behind it (a VPL's (1 + 2 cos θ)/4π for cos θ < −1/2), and the linear
transfer carries that negative light on: in the Cornell box the cells under the ceiling ended with
negative DC and the ceiling got nothing. With the clamp each face's flux is Δω_f·max(0, I_src(ω_f)),
the explicit 5-face sum (``propagate.gather_clamped``); no cell ever holds negative light, and flux is
no longer exactly conserved (what the clamp drops was negative). Propagation is diffusive either
way: at each step 0.8 of a beam's flux turns into side lobes, so light covers about √N cells in N
iterations, not N (a 4 m lit patch under 32³ × 30 iterations of 1 m cells: irradiance 8 cells above
0.29 of the exact value, 16 cells above 0.001). Hence the scene-fitted coarsest cascade below.

Geometry volume (fuzzy occlusion, K&D 2010 §5.2): a surfel of area A and normal n adds a blocking
potential B(ω) = A/s²·(1/3 + 2/3·n·ω) — the L1 projection of the clamped cosine max(0, n·ω)
(0.25 + 0.5·n·ω) rescaled by 4/3 so a face-on fully covered cell blocks 1 — to the geometry cell
whose centre is the nearest cell **corner** (grid shifted by half a cell, (res+1)³ cells). Light
propagating along d through the face shared with the source is attenuated by
1 − clamp(B_face(−d), 0, 1), B_face the mean of the 4 geometry cells at the face's corners.
Two-sided walls: surfels of both sides sum to an isotropic 2/3 block (L1 cannot do better).

Coverage blocking (``coverage_blocking``, off by default): the transmittance of a face is also at most
1 − clamp(Σ w_a) (the projected coverage of the lookup planes, either side), so a two-sided wall
thinner than a cell blocks all of the light, not 2/3 (thin-wall leak 0.095 → 0.006 of the lit side).
Off because in the Cornell box most of the ceiling's LPV light was the sunlit roof's, crossing the
two-sided ceiling: without it the ceiling gets 0.17× the reference (``bench_lpv_room.py``).

Cascades: ``fit_cascades`` — see its docstring (``scene_cells``: the cascade that holds the whole
scene has at most that many cells across it, default 6, so light crosses a closed room). Skipped:
cascades whose box misses the scene, and (after injection) cascades that received no light: they
are neither propagated nor looked up.
Every VPL is injected into every cascade it falls in; lookups take the finest cascade (blended
at its border, see "cascades" above).

Injection (``inject.inject_vpls``): a VPL at p with normal n goes to the point u = (p − origin)/s +
``injection_offset``·n (cells); along the normal's dominant axis it stays in the one layer of cells
holding u, and across the other two axes its lobe is split bilinearly between the 4 cells whose centres
surround u (clamped to the grid). Put in the single cell holding u, a regular grid of VPLs (an RSM's
texels on a flat ground) moved across the cell borders a whole row at a time as the sun moved, and
under a sun sinking 0.05° per frame the image popped (``docs/stability.md``); split, a VPL's light
moves between cells as smoothly as the VPL does. Along the normal nothing is split, so no light is put behind the
surface it leaves.

Temporal blend (``LPVConfig.temporal_blend`` = α, ``LightPropagationVolume.update``'s ``blend``): what
lookups read moves a fraction α per update from what they read after the last update to the newest
propagation, per cascade and in world space (a cascade whose box moved by whole cells is blended where
the old and new boxes overlap, the rest is the newest light), and after ``blend_updates(α)`` updates
(under 1 % of the change left) it is the newest light exactly. A staggered cascade's refresh and the
VPL sampling's remaining frame-to-frame noise are blended in over a few frames instead of switched;
the light lags a moving sun by about (1 − α)/α frames. A still scene ends exactly where no blending
gets, ``blend_updates(α)`` updates after its inputs stopped changing.

Reach. N iterations carry light about N cells, so on its own the finest cascade would only see
light from sources within N of its (small) cells. Two measures, both on by default:
    cross_scene: the coarsest fitted cascade runs max(N, ⌈largest scene side / its cell⌉)
        iterations (≤ its resolution), so light crosses the whole scene at the coarse scale;
    hand-over: with cascades c (finer) and c+1 active, c+1 adds the wavefronts of its iterations
        k ≥ m = ⌈N_c·s_c / s_{c+1}⌉ — light that travelled beyond the finer cascade's reach
        N_c·s_c — into a "far" grid; after propagation every finer cascade's accumulated grid gets
        Σ_{d>c} (s_c/s_d)²·far_d, trilinear at its cell centres (intensity scales with the cell's
        face area for the same radiance). The finer cascade then holds near light at its own
        resolution plus far light at the coarser ones', with no light counted twice (each far
        wavefront is beyond the reach of every finer grid it is added to). Still missing: light
        from sources outside a finer cascade's box within its reach of the border (the finer grid
        never had them and their coarse wavefronts are still "near"); the blend band hides the step.
    Measured (Cornell box, indirect only, 160×90, ``benchmarks/bench_lpv.py``; courtyard full
    image vs the full reference): together they take the courtyard's FLIP from 0.235 to 0.124
    and the Cornell box's trimmed relMSE from 18 to 1.0.
    Default resolution 12³ (not the paper's 32³): at 32³ cells are finer than the propagation
    can cross in a frame's budget; over several views of both scenes
    (``benchmarks/experiments/bench_lpv_views.py``) 12³ has a lower error than 16³ in both, for
    about half the update.
Known error (measured, ``tests/kernels/test_lpv.py::test_self_illumination_of_a_lit_plane`` and
``benchmarks/bench_lpv_room.py``): L1 lobes are wide and propagation is diffusive, so light a lit
plane's VPLs send sideways reaches the plane itself: a plane of exitance M receives 0.5–0.6·M from
itself with the paper's transfer and no geometry volume, 0.33–0.41·M with its surfels in the geometry
volume and the defaults (0.20–0.41·M without the lookup planes, where the home cell drops the cells
above a plane lying at 0.6 of a cell; exact: 0). With the faces next to a lit patch that share its
cells, this is most of the Cornell box's error without the damping below (``lpv_room.json``). No choice of
injection offset fixes it (0.33 at best over 0.5–1 cell): the cells above the plane hold mostly isotropic
light after a step or two of propagation, whose downward half lights the plane.

Self-illumination damping (``LPVConfig.self_damping`` = d cells, 2.5 by default; Kaplanyan & Dachsbacher
2010's remedy, gradient along the normal): an irradiance lookup's SH, per cascade and channel, is scaled
by 1 − o·(1 − min(1, DC(u + d·n) / DC)^p), DC the looked-up (guarded) SH's, DC(u + d·n) plain trilinear
d cells further along the normal, p = ``self_damping_power``: in front of a lit surface its own light falls
off along the normal (a lit plane's cells: DC 41, 36, 16, 6, 1.7 going up), light from something in front
grows towards it and is kept. o (with the lookup occlusion; else 1) is the product of the openness of the
⌈d⌉ faces met going from the home cell along the normal's dominant axis: the far sample is trusted only as
far as the space in front is open (under an overhang one cell above the ground it would read below the
ground and damp everything: the courtyard's undersides read 0.17 of the reference without o, 0.47
with it, 0.54 undamped). Measured (``bench_lpv_room.py``): the lit plane 0.33–0.42 → 0.02–0.05 at
d = 2.5, but it also takes light the LPV gets right in the courtyard (docs/techniques.md, "Light
propagation volumes").

Stagger (``LPVConfig.stagger``, on in the ``lpv-fast`` preset): an update re-injects and
propagates one cascade, the next in turn, instead of all; the others keep the grids (boxes) and the
light of their last update, and lookups read each at its own box, so nothing is inconsistent, only
up to ``cascades`` updates old. Each level keeps its own accumulated light; what lookups read is
that plus the far light handed over from the coarser cascades, rebuilt from their last far grids
after every propagation (so a refreshed fine cascade sees the coarse ones' light, and a refreshed
coarse one reaches the fine ones at once). With still inputs the cascades catch up in at most
``cascades`` updates and end where refreshing all of them gets (``update``'s ``pending_levels``).

Early stop: per cascade, after each iteration the change Σ|ΔDC| is compared with
``early_stop``·Σ|DC accumulated|; in a closed lossless grid the ratio is 1/(k+1), so stopping is
driven by light leaving the grid or being blocked.
Files: ``basis`` (SH and transfer constants), ``cascades`` (placement, numpy), ``inputs`` (VPLs and
surfels from the G-buffer and the RSM, numpy), the Warp code by stage — ``grid`` (a ``Cascade`` struct
per cascade and the functions every stage reads a grid with), ``inject``, ``propagate`` (and
``early_stop``: the per-iteration launches' stop, decided on the device), ``lookup`` — and ``volume``
(the host class). The injection is a scatter: on the CPU, where Warp's ``atomic_add`` is not atomic, it
goes through ``serenity.kernels.launch``'s ``ScatterGrid`` (one private grid per worker thread, summed
after); every launch is split over all CPU cores by ``serenity.kernels.launch``. The propagation is the
exception where that split does not pay: a 3 × 12³ LPV's cells are too few to hand to a second thread,
and a launch per iteration cost more Python than its cells cost to compute, so on the CPU every
iteration (early stop included) runs in one single-threaded launch (``propagate_kernel(loop=True)``; bit
for bit the per-iteration result).
"""

from serenity.kernels.lpv.basis import (
    COS_LOBE_0,
    COS_LOBE_1,
    GV_K0,
    GV_K1,
    MAX_CASCADES,
    SH_C0,
    SH_C1,
    SH_FLUX,
    TRANSFER,
    VPL_K0,
    VPL_K1,
    W_FRONT,
    W_SIDE,
    face_solid_angles,
)
from serenity.kernels.lpv.cascades import CascadeGrid, fit_cascades
from serenity.kernels.lpv.inputs import (
    GBufferSamples,
    gbuffer_surfels,
    pixel_areas,
    rsm_surfels,
    sample_gbuffer,
    sky_vpls_from_gbuffer,
    sky_vpls_from_samples,
    surfels_from_samples,
)
from serenity.kernels.lpv.volume import LightPropagationVolume

__all__ = [
    "CascadeGrid",
    "LightPropagationVolume",
    "fit_cascades",
    "face_solid_angles",
    "pixel_areas",
    "sample_gbuffer",
    "GBufferSamples",
    "sky_vpls_from_gbuffer",
    "sky_vpls_from_samples",
    "gbuffer_surfels",
    "surfels_from_samples",
    "rsm_surfels",
    "COS_LOBE_0",
    "COS_LOBE_1",
    "GV_K0",
    "GV_K1",
    "MAX_CASCADES",
    "SH_C0",
    "SH_C1",
    "SH_FLUX",
    "TRANSFER",
    "VPL_K0",
    "VPL_K1",
    "W_FRONT",
    "W_SIDE",
]
