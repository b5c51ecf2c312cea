"""Sky visibility transfer for the sky lighting irradiance volume: every probe re-lit from a new sky
in one cheap pass, instead of re-integrating one layer of probes per frame (beyond the paper §7).

The paper integrates, per probe and per frame layer, L_k = ∫ V(ω) L(ω) Y_k(ω) dω by casting rays
against the occlusion quads and sampling the sky map. The quads (the visibility V) do not move when
the sun does; only the sky L does. So, as in precomputed radiance transfer (Sloan, Kautz & Snyder
2002), the visibility is integrated once per probe into a transfer matrix and the sky is projected
once per sky bake onto an orthonormal real SH basis S_j of bands 0..B−1 (B = ``bands``, B² functions):

    f_j = ∫ L̃(ω) S_j(ω) dω                         (L̃: the sky, mirrored below the horizon)
    T_kj = ∫_{ω.y≥0} V(ω) Y_k(ω) S_j(ω) dω           (k < 9: the volume's L2 basis, sh.py)
    G_k  = ∫_{ω.y<0} V(ω) Y_k(ω) dω                   (the ground, a constant radiance L_g)
    L_k ≈ Σ_j T_kj f_j + G_k L_g,    E_k = Â_l·w_l·L_k   (the irradiance coefficients stored)

The horizon is in T and G exactly (their integrals stop there), so only the sky's own detail above
band B−1 is lost — the mirror extension makes the sky continuous across the horizon, which keeps
that residual small. Exact when L̃ lies in the span of the S_j.
``tests/kernels/test_skytransfer.py`` bounds the error against the per-ray integration.

Shapes and units: ``transfer`` (P, B² + 1) of vec9 (over k), sr (SH products integrated over
solid angle; the last column is G); ``f`` (B² + 1, 3) W·m⁻²·sr⁻¹·sr (the last row is L_g, per sr of
G); output coefficients (P, 27) W·m⁻², the layout of
``skylayers.integrate_sky_layer``. Probe order, ray directions (the same QMC set and per-probe
decorrelation) and the occlusion test are those of ``skylayers`` (the quads: ``occlusion``).

``TransferMethod`` is the sky volume's ``"transfer"`` method (``serenity.kernels.skymethod``): after a
rebake of the sky map the probes are re-lit from the new sky — every probe at once with
``SkyConfig.transfer_layers`` = 0, else that many layers per update in a continuous cycle (a volume
never lit is lit whole); nothing to do while every layer is current.

Cost on the 2-core CPU machine (courtyard, 15 000 probes, B = 4): the transfer is built once
per scene (about the cost of one full per-ray rebuild), then a sky change costs one matrix-vector
product per probe and channel — a few milliseconds for the whole volume, against ~200 ms for one
layer of the per-ray method.
"""

from __future__ import annotations

import functools

import numpy as np
import warp as wp

from serenity.config import SKY_SEQUENCES, SKY_TRANSFER_MAX_BANDS
from serenity.kernels.atmosphere_ref import sky_map_directions, sky_map_solid_angles
from serenity.kernels.factory import kernel_factory
from serenity.kernels.launch import launch
from serenity.kernels.occlusion import intersect_quads
from serenity.kernels.sampling import cp_rotation, hash_u32, sample_probe_direction
from serenity.kernels.sh import eval_sh9, sh_basis, vec9
from serenity.kernels.skylookup import ProbeGrid, probe_grid
from serenity.kernels.skymethod import SkyVolumeMethod

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants


vec25 = wp.types.vector(length=25, dtype=wp.float32)


# ---------------------------------------------------------------------------------------------
# funcs


@wp.func
def eval_sh25(d: wp.vec3) -> vec25:
    """Orthonormal real SH of bands 0–4 at unit ``d`` (the first 9 are ``sh.eval_sh9``'s)."""
    x = d[0]
    y = d[1]
    z = d[2]
    x2 = x * x
    y2 = y * y
    z2 = z * z
    b = eval_sh9(d)
    out = vec25()
    for i in range(9):
        out[i] = b[i]
    out[9] = 0.5900435899266435 * y * (3.0 * x2 - y2)
    out[10] = 2.890611442640554 * x * y * z
    out[11] = 0.4570457994644658 * y * (5.0 * z2 - 1.0)
    out[12] = 0.3731763325901154 * z * (5.0 * z2 - 3.0)
    out[13] = 0.4570457994644658 * x * (5.0 * z2 - 1.0)
    out[14] = 1.445305721320277 * z * (x2 - y2)
    out[15] = 0.5900435899266435 * x * (x2 - 3.0 * y2)
    out[16] = 2.5033429417967046 * x * y * (x2 - y2)
    out[17] = 1.7701307697799304 * y * z * (3.0 * x2 - y2)
    out[18] = 0.9461746957575601 * x * y * (7.0 * z2 - 1.0)
    out[19] = 0.6690465435572892 * y * z * (7.0 * z2 - 3.0)
    out[20] = 0.10578554691520431 * (35.0 * z2 * z2 - 30.0 * z2 + 3.0)
    out[21] = 0.6690465435572892 * x * z * (7.0 * z2 - 3.0)
    out[22] = 0.47308734787878004 * (x2 - y2) * (7.0 * z2 - 1.0)
    out[23] = 1.7701307697799304 * x * z * (x2 - 3.0 * y2)
    out[24] = 0.6258357354491761 * (x2 * (x2 - 3.0 * y2) - y2 * (3.0 * x2 - y2))
    return out


# ---------------------------------------------------------------------------------------------
# kernels


@kernel_factory(sequence=(0, 1))
def _integrate_transfer_kernel(sequence: int):
    """The transfer integration, specialised on the QMC sequence (0 Hammersley, 1 Owen-Sobol')."""
    @wp.kernel(enable_backward=False, module="unique")
    def integrate_transfer(
        # inputs
        grid: ProbeGrid,
        centers: wp.array(dtype=wp.vec3),
        ups: wp.array(dtype=wp.vec3),
        rights: wp.array(dtype=wp.vec3),
        halves: wp.array(dtype=wp.vec2),
        quad_count: int,
        base_points: wp.array(dtype=wp.vec2),
        rays: int,
        salt: wp.uint32,
        functions: int,
        # outputs
        transfer: wp.array2d(dtype=vec9),
        offset: int,
    ):
        probe = wp.tid() + offset
        res_x = grid.res[0]
        res_y = grid.res[1]
        cell = grid.cell
        x = probe % res_x
        y = (probe // res_x) % res_y
        z = probe // (res_x * res_y)
        p = grid.origin + wp.vec3(float(x) * cell[0], float(y) * cell[1], float(z) * cell[2])
        seed = hash_u32(wp.uint32(probe) ^ salt)
        rot = cp_rotation(seed)
        w = 4.0 * wp.pi / float(rays)
        for r in range(rays):
            d = sample_probe_direction(r, base_points, rot, seed, wp.static(sequence == 0))
            if not intersect_quads(p, d, centers, ups, rights, halves, quad_count):
                yk = eval_sh9(d) * w
                if d[1] >= 0.0:
                    # the sky, mirror-extended below the horizon (see project_sky)
                    sj = eval_sh25(d)
                    for j in range(functions):
                        transfer[probe, j] = transfer[probe, j] + yk * sj[j]
                else:
                    transfer[probe, functions] = transfer[probe, functions] + yk

    return integrate_transfer


@wp.kernel
def apply_transfer(
    # inputs
    transfer: wp.array2d(dtype=vec9),
    sky_sh: wp.array(dtype=wp.vec3),
    scale: vec9,
    grid: ProbeGrid,
    first_layer: int,
    layers: int,
    # outputs
    coeffs: wp.array2d(dtype=float),
    offset: int,
):
    """Re-light the probes of ``layers`` consecutive y-layers from ``first_layer`` (probes in
    (z, y, x) storage order; one item per probe of the slab)."""
    i = wp.tid() + offset
    x = grid.res[0]
    y = grid.res[1]
    slab = layers * x
    z = i // slab
    rest = i - z * slab
    probe = (z * y + first_layer + rest // x) * x + rest % x
    r = vec9()
    g = vec9()
    b = vec9()
    for j in range(sky_sh.shape[0]):  # B² sky functions, then the ground
        t = transfer[probe, j]
        f = sky_sh[j]
        r += t * f[0]
        g += t * f[1]
        b += t * f[2]
    for k in range(9):
        s = scale[k]
        coeffs[probe, 3 * k + 0] = r[k] * s
        coeffs[probe, 3 * k + 1] = g[k] * s
        coeffs[probe, 3 * k + 2] = b[k] * s


# ---------------------------------------------------------------------------------------------
# host


def sh_basis25(directions) -> np.ndarray:
    """(N, 25) float64 twin of :func:`eval_sh25`."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    x2, y2, z2 = x * x, y * y, z * z
    hi = [0.5900435899266435 * y * (3 * x2 - y2), 2.890611442640554 * x * y * z,
          0.4570457994644658 * y * (5 * z2 - 1), 0.3731763325901154 * z * (5 * z2 - 3),
          0.4570457994644658 * x * (5 * z2 - 1), 1.445305721320277 * z * (x2 - y2),
          0.5900435899266435 * x * (x2 - 3 * y2),
          2.5033429417967046 * x * y * (x2 - y2), 1.7701307697799304 * y * z * (3 * x2 - y2),
          0.9461746957575601 * x * y * (7 * z2 - 1), 0.6690465435572892 * y * z * (7 * z2 - 3),
          0.10578554691520431 * (35 * z2 * z2 - 30 * z2 + 3), 0.6690465435572892 * x * z * (7 * z2 - 3),
          0.47308734787878004 * (x2 - y2) * (7 * z2 - 1), 1.7701307697799304 * x * z * (x2 - 3 * y2),
          0.6258357354491761 * (x2 * (x2 - 3 * y2) - y2 * (3 * x2 - y2))]
    return np.concatenate([sh_basis(d), np.stack(hi, axis=1)], axis=1)


@functools.cache
def _sky_map_projection(size: int, functions: int) -> tuple[np.ndarray, np.ndarray]:
    """(texel indices (M,), weights (M, B²)): S_j(ω) + S_j(ω mirrored) times the solid angle of
    each texel of a size² paraboloid map that covers the upper hemisphere."""
    d = sky_map_directions(size).reshape(-1, 3)
    w = sky_map_solid_angles(size).reshape(-1)
    keep = np.flatnonzero(w > 0)
    up = d[keep]
    basis = (sh_basis25(up) + sh_basis25(up * np.array([1.0, -1.0, 1.0])))[:, :functions]
    return keep, np.ascontiguousarray((basis * w[keep, None]).astype(np.float32))


def project_sky(sky_map: np.ndarray, ground_radiance, functions: int) -> np.ndarray:
    """(B² + 1, 3) float32: f_j of the paraboloid sky map mirrored below the horizon, then the
    ground radiance L_g (the row the transfer's ground column multiplies)."""
    keep, weights = _sky_map_projection(int(sky_map.shape[0]), int(functions))
    f = weights.T @ np.asarray(sky_map, np.float32).reshape(-1, 3)[keep]
    return np.concatenate([f, np.asarray(ground_radiance, np.float32).reshape(1, 3)]).astype(np.float32)


class SkyTransfer:
    """Per-probe transfer matrices of a sky volume's grid (built once), and their application to a
    sky. ``quads_wp``: the four arrays of ``occlusion.quads_arrays`` as Warp arrays, and their
    count; ``base``: the Hammersley base points; ``bands`` B (1–5)."""

    def __init__(self, quads_wp, quad_count: int, base, rays: int, sequence: int, seed: int, bands: int,
                 device: str):
        if not 1 <= bands <= SKY_TRANSFER_MAX_BANDS:
            raise ValueError(f"transfer bands must be in 1..{SKY_TRANSFER_MAX_BANDS}, got {bands}")
        self.functions = bands * bands
        self.device = device
        self._args = [*quads_wp, int(quad_count), base, int(rays), wp.uint32(seed & 0xFFFFFFFF), self.functions]
        self._kernel = _integrate_transfer_kernel(int(sequence))
        self._sky = wp.zeros(self.functions + 1, dtype=wp.vec3, device=device)
        self.transfer = None
        self.grid = None

    def build(self, origin, cell, resolution) -> None:
        """Integrate the visibility of every probe of the grid into its transfer matrix (once per
        scene, or when the grid moved)."""
        x, y, z = resolution
        probes = x * y * z
        if self.transfer is None or self.transfer.shape[0] != probes:
            self.transfer = wp.zeros((probes, self.functions + 1), dtype=vec9, device=self.device)
        else:
            self.transfer.zero_()
        launch(self._kernel, probes, [probe_grid(origin, cell, resolution), *self._args, self.transfer],
               device=self.device)
        self.grid = (tuple(np.asarray(origin, np.float64)), tuple(np.asarray(cell, np.float64)), tuple(resolution))

    def apply(self, origin, cell, resolution, sky_sh: np.ndarray, scale, coeffs, first_layer: int = 0,
              layers: int | None = None) -> None:
        """Write the irradiance coefficients (P, 27) of the probes in y-layers ``first_layer`` ..
        ``first_layer + layers - 1`` (default: every probe) for ``project_sky``'s (B² + 1, 3),
        building the transfer first if the grid is new."""
        grid = (tuple(np.asarray(origin, np.float64)), tuple(np.asarray(cell, np.float64)), tuple(resolution))
        if grid != self.grid:
            self.build(origin, cell, resolution)
        x, y, z = (int(v) for v in resolution)
        layers = y - int(first_layer) if layers is None else int(layers)
        if not (0 <= first_layer and layers >= 0 and first_layer + layers <= y):
            raise ValueError(f"layers {first_layer}..{first_layer + layers - 1} outside the grid's {y}")
        self._sky.assign(np.ascontiguousarray(sky_sh, np.float32))
        grid = probe_grid(origin, cell, resolution)
        launch(apply_transfer, z * layers * x,
               [self.transfer, self._sky, scale, grid, int(first_layer), layers, coeffs], device=self.device)


class TransferMethod(SkyVolumeMethod):
    """``"transfer"``: the sky volume's probes re-lit through their transfer matrices (module docstring)."""

    def __init__(self, volume):
        super().__init__(volume)
        cfg = volume.config
        self.transfer = SkyTransfer(volume.quads_wp, len(volume.quads), volume.base_points, cfg.rays_per_probe,
                                    SKY_SEQUENCES.index(cfg.sequence), cfg.seed, cfg.transfer_bands, volume.device)
        #: (sky version, :func:`project_sky`'s result) of the sky the probes were last re-lit from
        self.projected: tuple[int, np.ndarray] | None = None

    def apply(self, first: int = 0, count: int | None = None) -> None:
        """Re-light y-layers ``first`` .. ``first + count - 1`` (default: all) from the current sky."""
        v = self.volume
        count = v.resolution[1] - first if count is None else count
        if self.projected is None or self.projected[0] != v.sky_version:
            sky = v.sky_map()
            if v.constant_sky:  # the 2×2 map is too coarse a quadrature for the projection
                sky = np.broadcast_to(sky[:1, :1], (64, 64, 3))
            self.projected = (v.sky_version, project_sky(sky, v.ground_radiance, self.transfer.functions))
        self.transfer.apply(v.grid_origin, v.cell_size, v.resolution, self.projected[1], v.scale, v.coeffs_wp,
                            first, count)
        v.mark_lit(first, count)

    def update(self, sun, sky_map, layers: int) -> bool:
        v = self.volume
        if not v.pending_layers:
            return False
        per_update = v.config.transfer_layers
        if per_update <= 0 or np.any(v.layer_versions < 0):  # all at once, or never lit
            self.apply()
            return True
        for start, n in v.next_slabs(per_update):
            self.apply(start, n)
        return True

    def rebuild(self, sun, sky_map) -> None:
        self.apply()
