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
        centres of the clamped cells). (An earlier +1 in g let cells up to 1/4 cell behind count:
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
(constants T_* below; ``tests/kernels/test_lpv.py`` checks it against the explicit 5-face sum).
No clamping during propagation (linear, energy-exact; negative lobes are clamped at lookup).

Geometry volume (fuzzy occlusion, K&D 2010 §5.2): a surfel of area A and normal n adds a blocking
potential B(ω) = A/s²·(1/3 + 2/3·n·ω) — the L1 projection of the clamped cosine max(0, n·ω)
(0.25 + 0.5·n·ω) rescaled by 4/3 so a face-on fully covered cell blocks 1 — to the geometry cell
whose centre is the nearest cell **corner** (grid shifted by half a cell, (res+1)³ cells). Light
propagating along d through the face shared with the source is attenuated by
1 − clamp(B_face(−d), 0, 1), B_face the mean of the 4 geometry cells at the face's corners.
Two-sided walls: surfels of both sides sum to an isotropic 2/3 block (L1 cannot do better).

Cascades: ``fit_cascades`` — see its docstring. Skipped: cascades whose box misses the scene, and
(after injection) cascades that received no light: they are neither propagated nor looked up.
Every VPL is injected into every cascade it falls in; lookups take the finest cascade (blended
at its border, see "cascades" above).

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
    image vs the full reference): see the README's LPV section — together they took the
    courtyard's FLIP from 0.235 to 0.124 and the Cornell box's trimmed relMSE from 18 to 1.0.
    Default resolution 16³ (not the paper's 32³): at 32³ cells are finer than the propagation
    can cross in a frame's budget, and the sweep's error is lower at 16³ in both scenes.
Known error (measured, ``tests/kernels/test_lpv.py::test_self_illumination_of_a_lit_plane``): L1
lobes are wide, so light a lit plane's VPLs send sideways reaches the plane itself: a plane of
exitance M receives ≈ 0.5·M from itself (exact: 0). This, not leaking, is why lit surfaces and
their neighbours come out too bright (Cornell box: the short box's front face, ×2–3).

Early stop: per cascade, after each iteration the change Σ|ΔDC| is compared with
``early_stop``·Σ|DC accumulated|; in a closed lossless grid the ratio is 1/(k+1), so stopping is
driven by light leaving the grid or being blocked.

CPU note: Warp 1.19's CPU ``atomic_add`` is a plain read-modify-write (warp/native/builtin.h), not
atomic. The scatter (inject) kernels therefore write, on the CPU, into one private copy of the grid
per worker thread ("slots", chosen from the launch's ``offset``), summed by a gather kernel; on CUDA
they add straight into the grid with real atomics. Every launch goes through
``serenity.kernels.launch`` and is split over all CPU cores.
"""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import dataclass
from functools import cache

import numpy as np
import warp as wp

from serenity.config import LPV_MAX_CASCADES, LPVConfig
from serenity.device import cpu_threads, init_warp, resolve_device
from serenity.kernels.launch import chunk_ranges, launch

wp.set_module_options({"enable_backward": False})

# ----------------------------------------------------------------------------------------------
# constants
# ----------------------------------------------------------------------------------------------

SH_C0 = 0.5 / math.sqrt(math.pi)  # Y0
SH_C1 = math.sqrt(3.0) / (2.0 * math.sqrt(math.pi))  # Y1 / ω component
COS_LOBE_0 = math.sqrt(math.pi) / 2.0  # SH of max(0, n·ω): (COS_LOBE_0, COS_LOBE_1·n)
COS_LOBE_1 = math.sqrt(math.pi / 3.0)
VPL_K0 = COS_LOBE_0 / math.pi  # = SH_C0: a VPL of flux Φ has intensity SH Φ·(VPL_K0, VPL_K1·n)
VPL_K1 = COS_LOBE_1 / math.pi  # = 1/√(3π)
GV_K0 = 4.0 / 3.0 * COS_LOBE_0  # blocking SH per unit coverage: (GV_K0, GV_K1·n) → 1/3 + 2/3 n·ω
GV_K1 = 4.0 / 3.0 * COS_LOBE_1
SH_FLUX = 2.0 * math.sqrt(math.pi)  # flux (W) of an intensity SH = SH_FLUX·DC


def _rect_solid_angle(a0: float, a1: float, b0: float, b1: float, d: float) -> float:
    """Solid angle of the rectangle [a0,a1]×[b0,b1] in a plane at distance d, seen from the origin."""

    def corner(a, b):
        return math.atan(a * b / (d * math.sqrt(a * a + b * b + d * d)))

    return corner(a1, b1) - corner(a0, b1) - corner(a1, b0) + corner(a0, b0)


def face_solid_angles() -> tuple[float, float]:
    """(Δω_front, Δω_side) in sr, seen from the centre of a unit source cell (see module doc)."""
    return _rect_solid_angle(-0.5, 0.5, -0.5, 0.5, 1.5), _rect_solid_angle(-0.5, 0.5, 0.5, 1.5, 0.5)


W_FRONT, W_SIDE = face_solid_angles()  # 0.4006697, 0.4234314 sr
_INV_SQRT5 = 1.0 / math.sqrt(5.0)  # side-face centre direction (2d ± e)/√5
# sparse transfer of one neighbour direction d (module doc), source SH (s0, sv), sa = sv·d:
#   out0 = T_DC_DC·s0 + T_DC_AX·sa ;  out.xyz = d·(T_AX_DC·s0 + T_AX_AX·sa) + T_PERP·(sv − sa·d)
TRANSFER = {
    "DC_DC": VPL_K0 * (W_FRONT + 4.0 * W_SIDE) * SH_C0,
    "DC_AX": VPL_K0 * (W_FRONT + 8.0 * W_SIDE * _INV_SQRT5) * SH_C1,
    "AX_DC": VPL_K1 * W_FRONT * SH_C0,
    "AX_AX": VPL_K1 * W_FRONT * SH_C1,
    "PERP": VPL_K1 * 2.0 * W_SIDE * SH_C1 * _INV_SQRT5,
}
T_DC_DC = wp.constant(TRANSFER["DC_DC"])
T_DC_AX = wp.constant(TRANSFER["DC_AX"])
T_AX_DC = wp.constant(TRANSFER["AX_DC"])
T_AX_AX = wp.constant(TRANSFER["AX_AX"])
T_PERP = wp.constant(TRANSFER["PERP"])

C0 = wp.constant(SH_C0)
C1 = wp.constant(SH_C1)
K0 = wp.constant(VPL_K0)
K1 = wp.constant(VPL_K1)
G0 = wp.constant(GV_K0)
G1 = wp.constant(GV_K1)
E0 = wp.constant(COS_LOBE_0)  # irradiance: E = E0·l0 − E1·(l.xyz·n)
E1 = wp.constant(COS_LOBE_1)

MAX_CASCADES = LPV_MAX_CASCADES  # the kernels and the GLSL take up to this many cascades
MAX_SLOTS = 8  # private scatter grids on the CPU (one per worker thread, capped)


# ----------------------------------------------------------------------------------------------
# config and cascade geometry (plain Python)
# ----------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class CascadeGrid:
    """One cascade's grid: cell (x, y, z) covers origin + cell_size·[x, x+1) × [y, y+1) × [z, z+1)."""

    level: int
    """Cascade index in the config (0 = finest); kept when coarser/finer ones are skipped."""
    origin: tuple[float, float, float]
    """World position of the grid's min corner (m), a multiple of cell_size on each axis."""
    cell_size: float
    """Edge of a cubic cell (m)."""
    resolution: int
    """Cells per axis."""

    @property
    def extent(self) -> float:
        return self.cell_size * self.resolution

    def world_to_grid(self, p) -> np.ndarray:
        """Grid coordinates (cells, float) of world points (…,3)."""
        return (np.asarray(p, np.float64) - np.asarray(self.origin)) / self.cell_size

    def contains(self, p) -> np.ndarray:
        u = self.world_to_grid(p)
        return np.all((u >= 0) & (u < self.resolution), axis=-1)


def fit_cascades(camera_position, view_dir, scene_bounds, config: LPVConfig) -> list[CascadeGrid]:
    """Place the cascades for a camera.

    Extents: the outermost reaches D = min(view_distance, |scene diagonal|) ahead of the camera,
    extent_out = D / (0.5 + forward_shift); cascade c has extent_out / cascade_scale^(C−1−c),
    capped at the scene's largest side plus one cell each way ("whole"). A cascade within a factor
    √cascade_scale of "whole" is grown to "whole" and is the last one (a coarser cascade barely
    coarser than it would cost a full propagation for nothing).
    Cell sizes depend only on the config and the scene — never on the camera — so nothing swims.
    Placement: the box's min corner is camera + forward_shift·extent·view − extent/2, clipped
    per axis to the scene bounds padded by one cell (centred on the scene along an axis the box
    already spans), then snapped down to a multiple of the cell size: the box moves in whole
    cells, so the same camera cell gives the same grids. Skipped: a cascade whose box misses the
    scene bounds.
    """
    cam = np.asarray(camera_position, np.float64).reshape(3)
    view = np.asarray(view_dir, np.float64).reshape(3)
    view = view / max(float(np.linalg.norm(view)), 1e-12)
    b = np.asarray(scene_bounds, np.float64).reshape(2, 3)
    size = np.maximum(b[1] - b[0], 1e-6)
    reach = min(float(config.view_distance), float(np.linalg.norm(size)))
    outer = reach / (0.5 + config.forward_shift)
    grids: list[CascadeGrid] = []
    for c, res in enumerate(config.resolutions):
        extent = outer / config.cascade_scale ** (config.cascades - 1 - c)
        whole = float(size.max()) * res / (res - 2)  # the scene plus one cell each side
        holds_scene = extent * math.sqrt(config.cascade_scale) >= whole
        if holds_scene:
            extent = whole
        cell = extent / res
        lo, hi = b[0] - cell, b[1] + cell
        want = cam + config.forward_shift * extent * view - extent / 2
        mn = np.where(extent >= hi - lo, (lo + hi - extent) / 2, np.clip(want, lo, np.maximum(lo, hi - extent)))
        origin = np.floor(mn / cell) * cell
        if np.all(origin < b[1]) and np.all(origin + extent > b[0]):
            grids.append(CascadeGrid(c, tuple(float(v) for v in origin), float(cell), int(res)))
        if holds_scene:
            break
    return grids


# ----------------------------------------------------------------------------------------------
# VPLs and surfels from the G-buffer and the RSM (numpy, host side)
# ----------------------------------------------------------------------------------------------


def pixel_areas(positions, normals, camera_position, camera_forward, fov_y_deg: float, height: int,
                min_cos: float = 0.2) -> np.ndarray:
    """Surface area (m²) each pixel of a pinhole camera's G-buffer covers, (H, W) float32.

    A pixel spans h = 2·tan(fov_y/2)/height on the image plane at unit depth; at view depth z
    its cross-section perpendicular to the optical axis is (h·z)², perpendicular to its ray
    (h·z)²·cos α (α: ray to axis), and on the surface (h·z)²·cos α / |n·v| (v: the ray), with
    |n·v| clamped to ``min_cos`` (grazing pixels would otherwise claim unbounded area).
    """
    p = np.asarray(positions, np.float32)[..., :3]
    n = np.asarray(normals, np.float32)[..., :3]
    cam = np.asarray(camera_position, np.float32).reshape(3)
    fwd = np.asarray(camera_forward, np.float32).reshape(3)
    fwd = fwd / max(float(np.linalg.norm(fwd)), 1e-12)
    d = p - cam
    r = np.maximum(np.linalg.norm(d, axis=-1), 1e-9)
    z = np.maximum(d @ fwd, 0.0)
    h = 2.0 * math.tan(math.radians(fov_y_deg) / 2.0) / float(height)
    nn = np.maximum(np.linalg.norm(n, axis=-1), 1e-12)
    cos_nv = np.abs(np.einsum("...k,...k->...", n, d)) / (nn * r)
    return ((h * z) ** 2 * (z / r) / np.maximum(cos_nv, min_cos)).astype(np.float32)


def _gbuffer_blocks(shape, stride: int):
    """Block-centre pixel rows/cols of an (H, W) image cut into stride×stride blocks, and each
    block's pixel count (edge blocks may be partial): (rows, cols, counts (H', W'))."""
    h, w = shape[:2]
    y0, x0 = np.arange(0, h, stride), np.arange(0, w, stride)
    ys, xs = np.minimum(y0 + stride // 2, h - 1), np.minimum(x0 + stride // 2, w - 1)
    counts = np.minimum(stride, h - y0)[:, None] * np.minimum(stride, w - x0)[None, :]
    return ys, xs, counts.astype(np.float32)


def sky_vpls_from_gbuffer(position, normal, albedo, sky_irradiance, camera_position, camera_forward,
                          fov_y_deg: float, stride: int = 4, valid=None):
    """Sky-light VPLs (paper Fig. 11): the G-buffer, lit by the sky, used as a reflective shadow map.

    position (H,W,3|4) m (w = 0 marks an empty pixel when present), normal (H,W,3|4), albedo
    (H,W,3|4) linear, sky_irradiance (H,W,3) W/m² (the caller's sky lighting at each pixel, with
    whatever visibility it applies), camera position/forward and vertical fov (degrees). One VPL
    per ``stride``×``stride`` block (its centre pixel), flux = albedo·E_sky·A with A the block's
    surface area (``pixel_areas`` of the centre pixel × the block's pixel count). Returns
    (positions (N,3), normals (N,3), flux (N,3)) float32, only VPLs with positive flux.
    """
    pos = np.asarray(position, np.float32)
    height = pos.shape[0]
    ys, xs, counts = _gbuffer_blocks(pos.shape, stride)
    sel = np.ix_(ys, xs)
    p = pos[sel]
    n = np.asarray(normal, np.float32)[sel][..., :3]
    rho = np.asarray(albedo, np.float32)[sel][..., :3]
    e = np.asarray(sky_irradiance, np.float32)[sel][..., :3]
    ok = np.ones(p.shape[:2], bool) if valid is None else np.asarray(valid, bool)[sel]
    if p.shape[-1] == 4:
        ok &= p[..., 3] != 0
    area = pixel_areas(p, n, camera_position, camera_forward, fov_y_deg, height) * counts
    flux = rho * e * area[..., None]
    ok &= np.all(np.isfinite(flux), axis=-1) & (flux.max(axis=-1) > 0)
    return (np.ascontiguousarray(p[ok][:, :3]), np.ascontiguousarray(n[ok]), np.ascontiguousarray(flux[ok]))


def gbuffer_surfels(position, normal, camera_position, camera_forward, fov_y_deg: float, stride: int = 4,
                    valid=None):
    """Occluding surfels for the geometry volume from a G-buffer: (positions, normals, areas (M,))."""
    pos = np.asarray(position, np.float32)
    height = pos.shape[0]
    ys, xs, counts = _gbuffer_blocks(pos.shape, stride)
    sel = np.ix_(ys, xs)
    p = pos[sel]
    n = np.asarray(normal, np.float32)[sel][..., :3]
    ok = np.ones(p.shape[:2], bool) if valid is None else np.asarray(valid, bool)[sel]
    if p.shape[-1] == 4:
        ok &= p[..., 3] != 0
    area = pixel_areas(p, n, camera_position, camera_forward, fov_y_deg, height) * counts
    ok &= np.isfinite(area) & (area > 0)
    return (np.ascontiguousarray(p[ok][:, :3]), np.ascontiguousarray(n[ok]), np.ascontiguousarray(area[ok]))


def rsm_surfels(vpls, sun_direction, min_cos: float = 0.2):
    """Occluding surfels from RSM VPLs (``positions``, ``normals``, ``texel_area`` m² perpendicular
    to the sun): area on the surface = texel_area / max(n·l, min_cos)."""
    n = np.asarray(vpls.normals, np.float32)
    l_dir = np.asarray(sun_direction, np.float32).reshape(3)
    cos = np.maximum(np.abs(n @ l_dir) / np.maximum(np.linalg.norm(n, axis=-1), 1e-12), min_cos)
    area = (float(vpls.texel_area) / cos).astype(np.float32)
    return np.asarray(vpls.positions, np.float32), n, area


# ----------------------------------------------------------------------------------------------
# Warp functions
# ----------------------------------------------------------------------------------------------


@wp.func
def find_level(i: int, levels: wp.array(dtype=wp.vec4i), n_levels: int) -> int:
    """Config level whose cells [cell_base, cell_base + res³) hold global cell i (−1: none)."""
    found = int(-1)
    for l in range(n_levels):
        e = levels[l]
        if i >= e[2] and i < e[2] + e[0] * e[0] * e[0]:
            found = l
    return found


@wp.func
def slot_of(offset: int, slot_starts: wp.array(dtype=int)) -> int:
    """Private scatter grid of the launch chunk starting at ``offset`` (0 on CUDA: one launch)."""
    s = int(0)
    for k in range(slot_starts.shape[0]):
        if slot_starts[k] == offset:
            s = k
    return s


@wp.func
def gather_pair(out: wp.vec4, p: wp.vec4, m: wp.vec4, axis: int) -> wp.vec4:
    """Add what a cell gathers along one axis: ``p`` = (weighted) SH of the source at −e_axis
    (light travelling +e_axis), ``m`` = source at +e_axis (travelling −e_axis).

    The sparse transfer of the module doc for d = ±e_axis, summed for the pair: with σ = p + m,
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


@wp.func
def guard_weight(n: wp.vec3, us: wp.vec3, x: int, y: int, z: int) -> float:
    """g = clamp(4·n·(centre − us), 0, 1) of cell (x, y, z) for a surface at us (cells)."""
    c = wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
    return wp.clamp(4.0 * wp.dot(n, c - us), 0.0, 1.0)


@wp.func
def trilinear_sh(grid: wp.array(dtype=wp.vec4), base: int, res: int, u: wp.vec3, us: wp.vec3, n: wp.vec3,
                 guard: int) -> wp.vec4:
    """Trilinear SH at grid coordinate u (cells), cell centres at i + 0.5, clamp to edge (GL_LINEAR).
    With ``guard``, each of the 8 cells' weights is also multiplied by ``guard_weight`` for a surface
    at us with normal n and renormalised (module doc), plain trilinear where they sum below 1e-4."""
    p = u - wp.vec3(0.5, 0.5, 0.5)
    fx = wp.floor(p[0])
    fy = wp.floor(p[1])
    fz = wp.floor(p[2])
    tx = p[0] - fx
    ty = p[1] - fy
    tz = p[2] - fz
    x0 = wp.clamp(int(fx), 0, res - 1)
    y0 = wp.clamp(int(fy), 0, res - 1)
    z0 = wp.clamp(int(fz), 0, res - 1)
    x1 = wp.clamp(int(fx) + 1, 0, res - 1)
    y1 = wp.clamp(int(fy) + 1, 0, res - 1)
    z1 = wp.clamp(int(fz) + 1, 0, res - 1)
    plain = wp.vec4()
    acc = wp.vec4()
    wsum = float(0.0)
    for k in range(8):
        xi = x0
        wx = 1.0 - tx
        if k % 2 == 1:
            xi = x1
            wx = tx
        yi = y0
        wy = 1.0 - ty
        if (k // 2) % 2 == 1:
            yi = y1
            wy = ty
        zi = z0
        wz = 1.0 - tz
        if k // 4 == 1:
            zi = z1
            wz = tz
        w = wx * wy * wz
        s = grid[base + (zi * res + yi) * res + xi]
        plain += w * s
        if guard != 0:
            gw = w * guard_weight(n, us, xi, yi, zi)
            acc += gw * s
            wsum += gw
    if guard == 0 or wsum < 1.0e-4:
        return plain
    return acc / wsum


@wp.func
def sample_sh(grid: wp.array(dtype=wp.vec4), base: int, res: int, u: wp.vec3) -> wp.vec4:
    """Plain trilinear SH at grid coordinate u (``trilinear_sh`` without the guard)."""
    return trilinear_sh(grid, base, res, u, u, wp.vec3(), 0)


@wp.func
def cascade_weight(u: wp.vec3, res: int, margin: float, band: float, last: bool) -> float:
    """α of a cascade at grid coordinate u (module doc): smoothstep(margin, margin+band, d), step if
    band = 0; the last cascade clamp(d + 1, 0, 1). d = distance to the box border in cells."""
    fr = float(res)
    d = wp.min(wp.min(wp.min(u[0], u[1]), u[2]), wp.min(wp.min(fr - u[0], fr - u[1]), fr - u[2]))
    if last:
        return wp.clamp(d + 1.0, 0.0, 1.0)
    if band > 0.0:
        t = wp.clamp((d - margin) / band, 0.0, 1.0)
        return t * t * (3.0 - 2.0 * t)
    if d > margin:
        return 1.0
    return 0.0


@wp.func
def eval_irradiance(s: wp.vec4, n: wp.vec3, inv_area: float) -> float:
    """Irradiance (W/m²) on a surface of normal n from an intensity SH s of a cell of area 1/inv_area."""
    e = E0 * s[0] - E1 * (s[1] * n[0] + s[2] * n[1] + s[3] * n[2])
    return wp.max(e * inv_area, 0.0)


@wp.func
def eval_radiance(s: wp.vec4, w: wp.vec3, a1: float, inv_area: float) -> float:
    """Radiance (W·m⁻²·sr⁻¹) travelling along w, band 1 scaled by a1 (lobe prefilter), clamped ≥ 0."""
    e = C0 * s[0] + a1 * C1 * (s[1] * w[0] + s[2] * w[1] + s[3] * w[2])
    return wp.max(e * inv_area, 0.0)


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


@wp.kernel(enable_backward=False)
def inject_vpls(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    flux: wp.array(dtype=wp.vec3),
    cas_geom: wp.array(dtype=wp.vec4),
    cas_int: wp.array(dtype=wp.vec4i),
    n_cascades: int,
    shift: float,
    slot_starts: wp.array(dtype=int),
    slot_stride: int,
    # outputs
    grid: wp.array(dtype=wp.vec4),
    offset: int,
):
    """Add each VPL's clamped-cosine intensity lobe to the cell at p + shift·s·n of every cascade."""
    i = wp.tid() + offset
    n = normals[i]
    ln = wp.length(n)
    if not (ln > 0.0):
        return
    n = n / ln
    f = flux[i]
    lobe = wp.vec4(K0, K1 * n[0], K1 * n[1], K1 * n[2])
    sbase = slot_of(offset, slot_starts) * slot_stride
    for c in range(n_cascades):
        g = cas_geom[c]
        res = cas_int[c][0]
        u = (positions[i] - wp.vec3(g[0], g[1], g[2])) / g[3] + n * shift
        fr = float(res)
        if u[0] >= 0.0 and u[1] >= 0.0 and u[2] >= 0.0 and u[0] < fr and u[1] < fr and u[2] < fr:
            n3 = res * res * res
            cell = sbase + cas_int[c][1] + (int(u[2]) * res + int(u[1])) * res + int(u[0])
            wp.atomic_add(grid, cell, lobe * f[0])
            wp.atomic_add(grid, cell + n3, lobe * f[1])
            wp.atomic_add(grid, cell + 2 * n3, lobe * f[2])


@wp.kernel(enable_backward=False)
def inject_geometry(
    # inputs
    positions: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    areas: wp.array(dtype=float),
    cas_geom: wp.array(dtype=wp.vec4),
    cas_int: wp.array(dtype=wp.vec4i),
    n_cascades: int,
    slot_starts: wp.array(dtype=int),
    slot_stride: int,
    # outputs
    gv: wp.array(dtype=wp.vec4),
    offset: int,
):
    """Add each surfel's blocking lobe to the geometry cell centred on its nearest cell corner."""
    i = wp.tid() + offset
    n = normals[i]
    ln = wp.length(n)
    if not (ln > 0.0):
        return
    n = n / ln
    sbase = slot_of(offset, slot_starts) * slot_stride
    for c in range(n_cascades):
        g = cas_geom[c]
        res = cas_int[c][0]
        u = (positions[i] - wp.vec3(g[0], g[1], g[2])) / g[3] + wp.vec3(0.5, 0.5, 0.5)
        fr = float(res + 1)
        if u[0] >= 0.0 and u[1] >= 0.0 and u[2] >= 0.0 and u[0] < fr and u[1] < fr and u[2] < fr:
            r1 = res + 1
            cover = areas[i] / (g[3] * g[3])
            cell = sbase + cas_int[c][3] + (int(u[2]) * r1 + int(u[1])) * r1 + int(u[0])
            wp.atomic_add(gv, cell, wp.vec4(G0 * cover, G1 * cover * n[0], G1 * cover * n[1], G1 * cover * n[2]))


@wp.kernel(enable_backward=False)
def gather_slots(
    # inputs
    slots: wp.array(dtype=wp.vec4),
    n_slots: int,
    stride: int,
    # outputs
    grid: wp.array(dtype=wp.vec4),
    offset: int,
):
    """grid[i] += Σ_s slots[s·stride + i], and zero the slots (ready for the next injection)."""
    i = wp.tid() + offset
    acc = grid[i]
    for s in range(n_slots):
        acc += slots[s * stride + i]
        slots[s * stride + i] = wp.vec4()
    grid[i] = acc


@wp.kernel(enable_backward=False)
def measure_cells(
    # inputs
    grid: wp.array(dtype=wp.vec4),
    levels: wp.array(dtype=wp.vec4i),
    n_levels: int,
    # outputs
    total: wp.array(dtype=float),
    offset: int,
):
    """total[cell] = Σ_RGB |DC| of each cell (per-cascade sums say which cascades received light)."""
    i = wp.tid() + offset
    l = find_level(i, levels, n_levels)
    if l < 0:
        return
    e = levels[l]
    n3 = e[0] * e[0] * e[0]
    j = e[1] + i - e[2]
    total[i] = wp.abs(grid[j][0]) + wp.abs(grid[j + n3][0]) + wp.abs(grid[j + 2 * n3][0])


@wp.kernel(enable_backward=False)
def eval_face_transmittance(
    # inputs
    gv: wp.array(dtype=wp.vec4),
    levels: wp.array(dtype=wp.vec4i),
    n_levels: int,
    # outputs
    trans_pos: wp.array(dtype=wp.vec3),
    trans_neg: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Per receiving cell: transmittance of the face shared with the source at −d, for d = ±x, ±y, ±z."""
    i = wp.tid() + offset
    l = find_level(i, levels, n_levels)
    if l < 0:
        return
    e = levels[l]
    res = e[0]
    k = i - e[2]
    x = k % res
    y = (k // res) % res
    z = k // (res * res)
    r1 = res + 1
    b = e[3]
    tp = wp.vec3()
    tn = wp.vec3()
    tp[0] = eval_transmittance(gv_face(gv, b, r1, 0, x, y, z), 0, 1.0)
    tn[0] = eval_transmittance(gv_face(gv, b, r1, 0, x + 1, y, z), 0, -1.0)
    tp[1] = eval_transmittance(gv_face(gv, b, r1, 1, x, y, z), 1, 1.0)
    tn[1] = eval_transmittance(gv_face(gv, b, r1, 1, x, y + 1, z), 1, -1.0)
    tp[2] = eval_transmittance(gv_face(gv, b, r1, 2, x, y, z), 2, 1.0)
    tn[2] = eval_transmittance(gv_face(gv, b, r1, 2, x, y, z + 1), 2, -1.0)
    trans_pos[i] = tp
    trans_neg[i] = tn


@cache
def _propagate_kernel(geometry_volume: bool):
    """The propagation kernel (one launch covers every cascade), geometry volume compiled in or out."""

    @wp.kernel(enable_backward=False, module="unique")
    def propagate_lpv(
        # inputs
        src: wp.array(dtype=wp.vec4),
        acc_src: wp.array(dtype=wp.vec4),
        trans_pos: wp.array(dtype=wp.vec3),
        trans_neg: wp.array(dtype=wp.vec3),
        levels: wp.array(dtype=wp.vec4i),
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
        e = levels[l]
        res = e[0]
        k = i - e[2]
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
            j = e[1] + ch * n3 + k
            out = wp.vec4()
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
        change[i] = dc_change
        total[i] = dc_total

    return propagate_lpv


@wp.kernel(enable_backward=False)
def hand_over_far(
    # inputs
    far: wp.array(dtype=wp.vec4),
    cas_geom: wp.array(dtype=wp.vec4),
    cas_int: wp.array(dtype=wp.vec4i),
    n_cascades: int,
    c: int,
    # outputs
    accum: wp.array(dtype=wp.vec4),
    offset: int,
):
    """accum of active cascade c += Σ_{d>c} (s_c/s_d)²·far_d at each cell centre (trilinear): the
    light coarser cascades carried beyond the finer ones' reach (module doc, "Hand-over")."""
    i = wp.tid() + offset
    g = cas_geom[c]
    res = cas_int[c][0]
    n3 = res * res * res
    x = i % res
    y = (i // res) % res
    z = i // (res * res)
    centre = wp.vec3(g[0], g[1], g[2]) + g[3] * wp.vec3(float(x) + 0.5, float(y) + 0.5, float(z) + 0.5)
    add_r = wp.vec4()
    add_g = wp.vec4()
    add_b = wp.vec4()
    for d in range(c + 1, n_cascades):
        gd = cas_geom[d]
        rd = cas_int[d][0]
        u = (centre - wp.vec3(gd[0], gd[1], gd[2])) / gd[3]
        fr = float(rd)
        if u[0] >= 0.0 and u[1] >= 0.0 and u[2] >= 0.0 and u[0] < fr and u[1] < fr and u[2] < fr:
            scale = (g[3] / gd[3]) * (g[3] / gd[3])
            bd = cas_int[d][1]
            nd = rd * rd * rd
            add_r += scale * sample_sh(far, bd, rd, u)
            add_g += scale * sample_sh(far, bd + nd, rd, u)
            add_b += scale * sample_sh(far, bd + 2 * nd, rd, u)
    j = cas_int[c][1] + i
    accum[j] = accum[j] + add_r
    accum[j + n3] = accum[j + n3] + add_g
    accum[j + 2 * n3] = accum[j + 2 * n3] + add_b


@wp.func
def cascade_irradiance(grids: wp.array(dtype=wp.vec4), cas_geom: wp.array(dtype=wp.vec4),
                       cas_int: wp.array(dtype=wp.vec4i), c: int, n_cascades: int, p: wp.vec3, n: wp.vec3,
                       lookup_offset: float, leak_guard: int, margin: float, band: float, keep: float) -> wp.vec4:
    """Cascade c's share of the irradiance at p (normal n): (α·E_rgb, α), α its blend weight times
    what the finer cascades left (``keep``). The twin of lpv.glsl's lpv_cascade_irradiance."""
    g = cas_geom[c]
    res = cas_int[c][0]
    base = cas_int[c][1]
    cell = g[3]
    us = (p - wp.vec3(g[0], g[1], g[2])) / cell
    u = us + n * lookup_offset
    alpha = cascade_weight(u, res, margin, band, c == n_cascades - 1) * keep
    if alpha <= 0.0:
        return wp.vec4()
    inv_area = 1.0 / (cell * cell)
    n3 = res * res * res
    sr = trilinear_sh(grids, base, res, u, us, n, leak_guard)
    sg = trilinear_sh(grids, base + n3, res, u, us, n, leak_guard)
    sb = trilinear_sh(grids, base + 2 * n3, res, u, us, n, leak_guard)
    return wp.vec4(alpha * eval_irradiance(sr, n, inv_area), alpha * eval_irradiance(sg, n, inv_area),
                   alpha * eval_irradiance(sb, n, inv_area), alpha)


@wp.func
def cascade_radiance(grids: wp.array(dtype=wp.vec4), cas_geom: wp.array(dtype=wp.vec4),
                     cas_int: wp.array(dtype=wp.vec4i), c: int, n_cascades: int, q: wp.vec3, w: wp.vec3,
                     a1: float, margin: float, band: float, keep: float) -> wp.vec4:
    """Cascade c's share of the radiance travelling along w at q: (α·L_rgb, α), as above."""
    g = cas_geom[c]
    res = cas_int[c][0]
    base = cas_int[c][1]
    cell = g[3]
    u = (q - wp.vec3(g[0], g[1], g[2])) / cell
    alpha = cascade_weight(u, res, margin, band, c == n_cascades - 1) * keep
    if alpha <= 0.0:
        return wp.vec4()
    inv_area = 1.0 / (cell * cell)
    n3 = res * res * res
    return wp.vec4(alpha * eval_radiance(sample_sh(grids, base, res, u), w, a1, inv_area),
                   alpha * eval_radiance(sample_sh(grids, base + n3, res, u), w, a1, inv_area),
                   alpha * eval_radiance(sample_sh(grids, base + 2 * n3, res, u), w, a1, inv_area), alpha)


@wp.kernel(enable_backward=False)
def lookup_irradiance(
    # inputs
    points: wp.array(dtype=wp.vec3),
    normals: wp.array(dtype=wp.vec3),
    grids: wp.array(dtype=wp.vec4),
    cas_geom: wp.array(dtype=wp.vec4),
    cas_int: wp.array(dtype=wp.vec4i),
    n_cascades: int,
    lookup_offset: float,
    leak_guard: int,
    margin: float,
    band: float,
    # outputs
    out: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Irradiance (W/m², RGB) at points with unit normals, cascades blended finest first."""
    i = wp.tid() + offset
    p = points[i]
    n = wp.normalize(normals[i])
    e = wp.vec3()
    keep = float(1.0)
    for c in range(n_cascades):
        r = cascade_irradiance(grids, cas_geom, cas_int, c, n_cascades, p, n, lookup_offset, leak_guard, margin,
                               band, keep)
        e += wp.vec3(r[0], r[1], r[2])
        keep = keep - r[3]
    out[i] = e


@wp.kernel(enable_backward=False)
def lookup_glossy(
    # inputs
    points: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    shininess: wp.array(dtype=float),
    grids: wp.array(dtype=wp.vec4),
    cas_geom: wp.array(dtype=wp.vec4),
    cas_int: wp.array(dtype=wp.vec4i),
    n_cascades: int,
    steps: int,
    step_len: float,
    margin: float,
    band: float,
    # outputs
    out: wp.array(dtype=wp.vec3),
    offset: int,
):
    """Radiance (W·m⁻²·sr⁻¹, RGB) arriving at points from the reflected directions, marched (Fig. 10)."""
    i = wp.tid() + offset
    p = points[i]
    r = wp.normalize(directions[i])
    m = shininess[i]
    a1 = (m + 1.0) / (m + 2.0)
    w = -r
    acc = wp.vec3()
    for k in range(steps):
        q = p + r * (step_len * float(k + 1))
        keep = float(1.0)
        for c in range(n_cascades):
            s = cascade_radiance(grids, cas_geom, cas_int, c, n_cascades, q, w, a1, margin, band, keep)
            acc += wp.vec3(s[0], s[1], s[2])
            keep = keep - s[3]
    out[i] = acc / float(steps)


# ----------------------------------------------------------------------------------------------
# host class
# ----------------------------------------------------------------------------------------------


@dataclass
class _Level:
    """Offsets of one config level (cascade) in the shared arrays."""

    res: int
    base: int  # first vec4 of this level in the SH grids (3·res³ vec4: R, G, B blocks)
    cell_base: int  # first cell in the per-cell arrays (res³)
    gv_base: int  # first vec4 in the geometry volume ((res+1)³)

    @property
    def size(self) -> int:
        return 3 * self.res**3


class LightPropagationVolume:
    """Cascaded LPV on one device: fit → clear → inject (VPLs, surfels) → propagate → lookup.

    All buffers are allocated once in ``__init__`` (4 SH grids — injected, ping, pong, accumulated —
    of 3·res³ float4 per cascade, a (res+1)³ geometry volume, face transmittances, and on the CPU
    one private scatter grid per worker thread); numpy inputs are wrapped (CPU) or copied into
    grow-only staging arrays (CUDA). ``timings`` holds the last wall time of each stage in ms
    (the device is synchronised when ``sync_timings``).

    ``fitted``: the cascades placed by ``fit`` (by config level); ``grids``: those that received
    light at the last ``propagate`` (the ones looked up and exported; index 0 = finest).
    """

    def __init__(self, config: LPVConfig | None = None, device: str | None = None, threads: int | None = None,
                 sync_timings: bool = True):
        init_warp()
        self.config = config or LPVConfig()
        self.device = resolve_device(device)
        self.threads = threads
        self.sync_timings = sync_timings
        self.is_cuda = self.device.startswith("cuda")
        self.fitted: list[CascadeGrid] = []
        self.grids: list[CascadeGrid] = []
        self.timings: dict[str, float] = {}
        self.iterations_run: list[int] = []
        self._propagate = _propagate_kernel(bool(self.config.geometry_volume))
        dev = self.device
        self._levels: list[_Level] = []
        base = cbase = gbase = 0
        for r in self.config.resolutions:
            self._levels.append(_Level(r, base, cbase, gbase))
            base, cbase, gbase = base + 3 * r**3, cbase + r**3, gbase + (r + 1) ** 3
        self._n_vec, self._n_cells, self._n_gv = base, cbase, gbase
        self._inj = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._ping = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._pong = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._accum = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._far = wp.zeros(base, dtype=wp.vec4, device=dev)
        self._far_from = wp.zeros(len(self._levels), dtype=int, device=dev)
        self._gv = wp.zeros(gbase, dtype=wp.vec4, device=dev)
        self._trans_pos = wp.ones(cbase, dtype=wp.vec3, device=dev)
        self._trans_neg = wp.ones(cbase, dtype=wp.vec3, device=dev)
        self._change = wp.zeros(cbase, dtype=float, device=dev)
        self._total = wp.zeros(cbase, dtype=float, device=dev)
        lv = np.array([(v.res, v.base, v.cell_base, v.gv_base) for v in self._levels], np.int32)
        self._level_table = wp.array(lv, dtype=wp.vec4i, device=dev)
        self._level_on = wp.zeros(len(self._levels), dtype=int, device=dev)
        # injection tables (fitted cascades) and lookup tables (active cascades)
        self._fit_geom = wp.zeros(MAX_CASCADES, dtype=wp.vec4, device=dev)
        self._fit_int = wp.zeros(MAX_CASCADES, dtype=wp.vec4i, device=dev)
        self._cas_geom = wp.zeros(MAX_CASCADES, dtype=wp.vec4, device=dev)
        self._cas_int = wp.zeros(MAX_CASCADES, dtype=wp.vec4i, device=dev)
        # private scatter grids: one per CPU worker (Warp's CPU atomics are plain read-modify-writes)
        self._n_slots = 1 if self.is_cuda else max(1, min(MAX_SLOTS, self.threads or cpu_threads()))
        self._slots = self._gv_slots = None
        if self._n_slots > 1:
            self._slots = wp.zeros(self._n_slots * base, dtype=wp.vec4, device=dev)
            self._gv_slots = wp.zeros(self._n_slots * gbase, dtype=wp.vec4, device=dev)
        self._slots_used = 0  # slots holding un-gathered light (CPU)
        self._gv_slots_used = 0
        self._zero_starts = wp.zeros(1, dtype=int, device=dev)
        self._last_level: dict[int, wp.array] = {}
        self._staging: dict[str, wp.array] = {}
        self._state = None  # (grids, input key) of the last update that did work
        self._scene_size = 0.0  # largest side of the scene bounds given to ``fit`` (m)
        self._gv_dirty = True
        self._has_result = False

    # -- helpers ---------------------------------------------------------------------------------

    def _sync(self):
        if self.sync_timings and self.is_cuda:
            wp.synchronize_device(self.device)

    def _timed(self, name: str, t0: float):
        self._sync()
        self.timings[name] = (time.perf_counter() - t0) * 1e3

    def _input(self, a, slot: str, dtype, width: int) -> wp.array:
        """A device array for ``a`` (numpy or Warp); numpy is wrapped (CPU) or staged (CUDA)."""
        if isinstance(a, wp.array):
            if str(a.device) != self.device:
                raise ValueError(f"{slot}: array on {a.device}, volume on {self.device}")
            return a
        shape = (-1, width) if width > 1 else (-1,)
        arr = np.ascontiguousarray(np.asarray(a, dtype=np.float32).reshape(shape))
        host = wp.array(arr, dtype=dtype, device="cpu", copy=False)
        if not self.is_cuda:
            return host
        n = host.shape[0]
        buf = self._staging.get(slot)
        if buf is None or buf.shape[0] < n:
            buf = wp.empty(max(n, 1 << max(0, int(n - 1).bit_length())), dtype=dtype, device=self.device)
            self._staging[slot] = buf
        view = buf[:n]
        wp.copy(view, host, count=n)
        return view

    def _tables(self, grids, geom_arr, int_arr):
        geom = np.zeros((MAX_CASCADES, 4), np.float32)
        ints = np.zeros((MAX_CASCADES, 4), np.int32)
        for k, g in enumerate(grids):
            lv = self._levels[g.level]
            geom[k, :3], geom[k, 3] = g.origin, g.cell_size
            ints[k] = (lv.res, lv.base, lv.cell_base, lv.gv_base)
        geom_arr.assign(geom)
        int_arr.assign(ints)

    def _scatter(self, kernel, n: int, inputs: list, target: wp.array, slots, stride: int) -> int:
        """Launch a scatter kernel over n items into ``target`` (CUDA, or one CPU thread) or into the
        private slots (CPU, one per chunk of ``launch``'s split). Returns the number of slots used."""
        if n <= 0:
            return 0
        threads = 1 if self.is_cuda else min(self._n_slots, self.threads or cpu_threads())
        chunks = chunk_ranges(n, threads)
        if slots is None or len(chunks) == 1:
            launch(kernel, n, [*inputs, self._zero_starts, 0, target], device=self.device, threads=1)
            return 0
        starts = wp.array(np.array([s for s, _ in chunks], np.int32), dtype=int, device=self.device)
        launch(kernel, n, [*inputs, starts, stride, slots], device=self.device, threads=threads)
        return len(chunks)

    def _gather(self):
        """Sum the CPU's private scatter grids into the injected grid and the geometry volume."""
        if self._slots_used:
            launch(gather_slots, self._n_vec, [self._slots, self._slots_used, self._n_vec, self._inj],
                   device=self.device, threads=self.threads)
            self._slots_used = 0
        if self._gv_slots_used:
            launch(gather_slots, self._n_gv, [self._gv_slots, self._gv_slots_used, self._n_gv, self._gv],
                   device=self.device, threads=self.threads)
            self._gv_slots_used = 0

    def _level_sums(self, a: wp.array, levels=None) -> np.ndarray:
        """Σ of a per-cell array over each config level's cells (float64; 0 for levels not in
        ``levels`` when given — the early-stop test sums only the cascades still iterating)."""
        h = a.numpy()  # a view on the CPU; one copy from CUDA
        out = np.zeros(len(self._levels))
        for k, v in enumerate(self._levels):
            if levels is None or k in levels:
                out[k] = np.sum(h[v.cell_base:v.cell_base + v.res**3], dtype=np.float64)
        return out

    # -- stages --------------------------------------------------------------------------------

    def fit(self, camera, scene_bounds) -> bool:
        """Place the cascades for ``camera`` (a Camera, or (position, view_dir)); True if any moved."""
        t0 = time.perf_counter()
        if hasattr(camera, "position"):
            pos, view = camera.position, camera.forward
        else:
            pos, view = camera
        grids = fit_cascades(pos, view, scene_bounds, self.config)
        b = np.asarray(scene_bounds, np.float64).reshape(2, 3)
        self._scene_size = float(np.max(b[1] - b[0]))
        moved = grids != self.fitted
        self.fitted = grids
        if moved:
            self._tables(grids, self._fit_geom, self._fit_int)
        self._timed("fit", t0)
        return moved

    def clear(self) -> None:
        """Zero the injected grids and the geometry volume (call before injecting a new frame's lights)."""
        t0 = time.perf_counter()
        self._inj.zero_()
        self._gv.zero_()
        if self._slots_used:
            self._slots.zero_()
            self._slots_used = 0
        if self._gv_slots_used:
            self._gv_slots.zero_()
            self._gv_slots_used = 0
        self._gv_dirty = True
        self._has_result = False
        self._timed("clear", t0)

    def inject(self, positions, normals, flux) -> None:
        """Add VPLs (positions (N,3) m, normals (N,3), flux (N,3) W) to every fitted cascade."""
        t0 = time.perf_counter()
        p = self._input(positions, "vpl_p", wp.vec3, 3)
        n = self._input(normals, "vpl_n", wp.vec3, 3)
        f = self._input(flux, "vpl_f", wp.vec3, 3)
        if not (p.shape[0] == n.shape[0] == f.shape[0]):
            raise ValueError(f"VPL arrays differ in length: {p.shape[0]}, {n.shape[0]}, {f.shape[0]}")
        inputs = [p, n, f, self._fit_geom, self._fit_int, len(self.fitted), float(self.config.injection_offset)]
        used = self._scatter(inject_vpls, p.shape[0], inputs, self._inj, self._slots, self._n_vec)
        self._slots_used = max(self._slots_used, used)
        self._timed("inject", t0)

    def inject_geometry(self, positions, normals, areas) -> None:
        """Add occluding surfels (positions (M,3) m, normals (M,3), areas (M,) m²) to the geometry volume."""
        t0 = time.perf_counter()
        p = self._input(positions, "gv_p", wp.vec3, 3)
        n = self._input(normals, "gv_n", wp.vec3, 3)
        a = self._input(areas, "gv_a", float, 1)
        if not (p.shape[0] == n.shape[0] == a.shape[0]):
            raise ValueError(f"surfel arrays differ in length: {p.shape[0]}, {n.shape[0]}, {a.shape[0]}")
        inputs = [p, n, a, self._fit_geom, self._fit_int, len(self.fitted)]
        used = self._scatter(inject_geometry, p.shape[0], inputs, self._gv, self._gv_slots, self._n_gv)
        self._gv_slots_used = max(self._gv_slots_used, used)
        self._gv_dirty = True
        self._timed("inject_geometry", t0)

    def propagate(self, iterations: int | None = None, early_stop: float | None = None) -> list[int]:
        """Propagate every fitted cascade that received light; return the iterations run per fitted
        cascade (0 for a skipped one). Restarts from the injected grids each call (so it may be
        re-run, e.g. with other settings). ``iterations`` overrides the config for every cascade
        (and turns off ``cross_scene``'s extension)."""
        t0 = time.perf_counter()
        cfg = self.config
        nl = len(self._levels)
        iters = np.array(cfg.iteration_counts if iterations is None else (int(iterations),) * nl, np.int64)
        if iterations is None and cfg.cross_scene and self.fitted:
            g = self.fitted[-1]
            iters[g.level] = max(iters[g.level], min(g.resolution, math.ceil(self._scene_size / g.cell_size)))
        thresh = cfg.early_stop if early_stop is None else float(early_stop)
        dev = self.device
        self._gather()
        # skip cascades that received nothing: not propagated, not looked up
        launch(measure_cells, self._n_cells, [self._inj, self._level_table, nl, self._total], device=dev,
               threads=self.threads)
        injected = self._level_sums(self._total)
        fitted = {g.level for g in self.fitted}
        on = np.array([1 if (lv in fitted and injected[lv] > 0.0 and iters[lv] > 0) else 0 for lv in range(nl)],
                      np.int32)
        self.grids = [g for g in self.fitted if injected[g.level] > 0.0]
        self._tables(self.grids, self._cas_geom, self._cas_int)
        if cfg.geometry_volume and self._gv_dirty:
            launch(eval_face_transmittance, self._n_cells, [self._gv, self._level_table, nl, self._trans_pos,
                                                            self._trans_neg], device=dev, threads=self.threads)
            self._gv_dirty = False
        # hand-over: a cascade's iterations past the finer one's reach (in its own cells) go to "far"
        far_from = np.full(nl, 1 << 30, np.int32)
        hand_over = cfg.handover and len(self.grids) > 1
        if hand_over:
            for fine, coarse in zip(self.grids, self.grids[1:], strict=False):
                reach = iters[fine.level] * fine.cell_size / coarse.cell_size
                far_from[coarse.level] = max(1, math.ceil(reach - 1e-6))
            self._far.zero_()
        self._far_from.assign(far_from)
        done = np.zeros(nl, np.int64)
        last = {lv: self._inj for lv in range(nl)}
        bufs = (self._ping, self._pong)
        wp.copy(self._accum, self._inj)
        for k in range(int(iters.max(initial=0))):
            on = on & (iters > k)
            if not on.any():
                break
            src = self._inj if k == 0 else bufs[(k - 1) % 2]
            dst = bufs[k % 2]
            self._level_on.assign(on)
            # threads only for the cells of the cascades still iterating (the coarsest may run on alone)
            active = [self._levels[lv] for lv in np.flatnonzero(on)]
            lo = min(v.cell_base for v in active)
            dim = max(v.cell_base + v.res**3 for v in active) - lo
            launch(self._propagate, dim,
                   [src, self._accum, self._trans_pos, self._trans_neg, self._level_table, nl, self._level_on,
                    self._far_from, k + 1, dst, self._accum, self._far, self._change, self._total], device=dev,
                   threads=self.threads, start=lo)
            for lv in np.flatnonzero(on):
                done[lv] += 1
                last[int(lv)] = dst
            if thresh > 0.0:
                live = set(np.flatnonzero(on).tolist())
                change, total = self._level_sums(self._change, live), self._level_sums(self._total, live)
                on = on & ~((change <= thresh * total) | (total <= 0.0))
        if hand_over:
            for c in range(len(self.grids) - 1):
                launch(hand_over_far, self._levels[self.grids[c].level].res ** 3,
                       [self._far, self._cas_geom, self._cas_int, len(self.grids), c, self._accum], device=dev,
                       threads=self.threads)
        self._last_level = last
        self.iterations_run = [int(done[g.level]) for g in self.fitted]
        self._has_result = True
        self._timed("propagate", t0)
        return self.iterations_run

    def input_key(self, vpls, surfels=None):
        """A cheap fingerprint of the injection inputs (shapes + CRC32 of the bytes), or None when it
        cannot be had cheaply (callables, device arrays on CUDA): then every update re-injects."""
        parts = []
        for sets in (vpls, surfels):
            if sets is None:
                parts.append(None)
                continue
            if callable(sets):
                return None
            for s in sets:
                for a in s:
                    if isinstance(a, wp.array):
                        if a.device.is_cuda:
                            return None
                        a = a.numpy()
                    a = np.ascontiguousarray(a)
                    parts.append((a.shape, a.dtype.str, zlib.crc32(a.view(np.uint8).reshape(-1))))
        return tuple(parts)

    def invalidate(self) -> None:
        """Forget the last update's inputs: the next ``update`` re-injects and propagates."""
        self._state = None

    def update(self, camera, scene_bounds, vpls, surfels=None, key=None) -> bool:
        """One frame: refit; re-inject and propagate only when the inputs or a cascade's cells changed.

        ``vpls``: a sequence of (positions, normals, flux) sets (sun RSM, sky-lit G-buffer, …), or a
        zero-argument callable returning one (called only when work is needed); ``surfels`` likewise
        with (positions, normals, areas). ``key``: any hashable that changes when the inputs do (sun
        direction, scene version, …); None → ``input_key`` fingerprints the arrays. Returns True
        when it re-injected and propagated.
        """
        t0 = time.perf_counter()
        self.fit(camera, scene_bounds)
        ikey = key if key is not None else self.input_key(vpls, surfels)
        state = (tuple(self.fitted), ikey)
        if self._has_result and ikey is not None and state == self._state:
            self.timings["update"] = (time.perf_counter() - t0) * 1e3
            return False
        self.clear()
        t_inj = t_gv = 0.0
        for s in vpls() if callable(vpls) else vpls:
            self.inject(*s)
            t_inj += self.timings["inject"]
        if surfels is not None and self.config.geometry_volume:
            for s in surfels() if callable(surfels) else surfels:
                self.inject_geometry(*s)
                t_gv += self.timings["inject_geometry"]
        self.timings["inject"], self.timings["inject_geometry"] = t_inj, t_gv
        self.propagate()
        self._state = state
        self._timed("update", t0)
        return True

    # -- lookup --------------------------------------------------------------------------------

    def irradiance(self, points, normals, blend: bool = True) -> np.ndarray:
        """Diffuse irradiance (W/m², (N,3) float32) at points (N,3) m with normals (N,3), ≥ 0.

        ``blend=False`` switches cascades hard at their borders (for measuring the seam).
        """
        t0 = time.perf_counter()
        p = self._input(points, "lk_p", wp.vec3, 3)
        n = self._input(normals, "lk_n", wp.vec3, 3)
        out = self._output(p.shape[0])
        cfg = self.config
        launch(lookup_irradiance, p.shape[0],
               [p, n, self._accum, self._cas_geom, self._cas_int, len(self.grids), float(cfg.lookup_offset),
                int(bool(cfg.leak_guard)), float(cfg.edge_margin), float(cfg.blend_cells if blend else 0.0), out],
               device=self.device, threads=self.threads)
        res = out.numpy().copy()
        self._timed("lookup", t0)
        return res

    def glossy_step_length(self) -> float:
        """Spacing (m) of the glossy march: glossy_step cells of the finest active cascade."""
        return self.config.glossy_step * (self.grids[0].cell_size if self.grids else 1.0)

    def glossy(self, points, directions, shininess) -> np.ndarray:
        """Radiance (W·m⁻²·sr⁻¹, (N,3)) arriving at points from ``directions`` (reflected view rays),
        prefiltered by a normalised Phong lobe of exponent ``shininess`` (scalar or (N,))."""
        t0 = time.perf_counter()
        p = self._input(points, "gl_p", wp.vec3, 3)
        d = self._input(directions, "gl_d", wp.vec3, 3)
        m = np.broadcast_to(np.asarray(shininess, np.float32), (p.shape[0],))
        s = self._input(m, "gl_m", float, 1)
        out = self._output(p.shape[0])
        cfg = self.config
        launch(lookup_glossy, p.shape[0],
               [p, d, s, self._accum, self._cas_geom, self._cas_int, len(self.grids), int(cfg.glossy_steps),
                float(self.glossy_step_length()), float(cfg.edge_margin), float(cfg.blend_cells), out],
               device=self.device, threads=self.threads)
        res = out.numpy().copy()
        self._timed("glossy", t0)
        return res

    def _output(self, n: int) -> wp.array:
        buf = self._staging.get("out")
        if buf is None or buf.shape[0] < n:
            buf = wp.empty(max(n, 1 << max(0, int(n - 1).bit_length())), dtype=wp.vec3, device=self.device)
            self._staging["out"] = buf
        return buf[:n]

    # -- export --------------------------------------------------------------------------------

    def textures(self, cascade: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Accumulated intensity SH of active cascade ``cascade`` (index into ``grids``) for GL upload:
        R, G, B, each float32 (Z, Y, X, 4), RGBA = (Y0, x, y, z) in W/sr; origin and cell size in
        ``grids[cascade]``."""
        g = self.level_grid(self.grids[cascade].level, "accum")
        return g[0].copy(), g[1].copy(), g[2].copy()

    def level_grid(self, level: int, which: str = "accum") -> np.ndarray:
        """A config level's grid as numpy: (3, res, res, res, 4) float32 (RGB, z, y, x, SH) for
        ``accum``, ``inj`` or ``last`` (the last iteration's wavefront); (res+1, res+1, res+1, 4)
        for ``gv``."""
        lv = self._levels[level]
        if which == "gv":
            self._gather()
            r1 = lv.res + 1
            return self._gv.numpy()[lv.gv_base:lv.gv_base + r1**3].reshape(r1, r1, r1, 4)
        if which == "inj":
            self._gather()
        arr = {"accum": self._accum, "inj": self._inj}.get(which)
        if which == "last":
            arr = self._last_level.get(level, self._inj)
        if arr is None:
            raise ValueError(f"unknown grid {which!r}")
        return arr.numpy()[lv.base:lv.base + lv.size].reshape(3, lv.res, lv.res, lv.res, 4)

    def flux(self, level: int, which: str = "last") -> np.ndarray:
        """Total flux (W, RGB) held by a config level's grid: SH_FLUX·Σ DC (the SH integral)."""
        g = self.level_grid(level, which)
        return SH_FLUX * g[..., 0].astype(np.float64).reshape(3, -1).sum(axis=1)


__all__ = [
    "LPVConfig",
    "CascadeGrid",
    "LightPropagationVolume",
    "fit_cascades",
    "face_solid_angles",
    "pixel_areas",
    "sky_vpls_from_gbuffer",
    "gbuffer_surfels",
    "rsm_surfels",
    "SH_C0",
    "SH_C1",
    "SH_FLUX",
    "TRANSFER",
    "W_FRONT",
    "W_SIDE",
]
