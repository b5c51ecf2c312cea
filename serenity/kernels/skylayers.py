"""The paper's per-layer ray casting (``SkyConfig.method = "layers"``, paper §7, Fig. 6–9): each probe
of the sky volume integrates the sky map through the occlusion quads, one y-layer per update.

Per probe (``integrate_sky_layer_kernel(sequence)``, the sequence compiled in): ``rays_per_probe``
directions ωᵢ over the sphere, a QMC set (:mod:`serenity.kernels.sampling`) — Hammersley with a
per-probe Cranley–Patterson rotation (default) or Owen-scrambled Sobol' with a per-probe seed —
mapped equal-area to the sphere (pdf 1/4π), decorrelated between probes by hashing the probe's
index. Each ray from the probe is tested against every occlusion quad (two-sided rectangle,
``model.OcclusionQuad``, paper Fig. 6); an unoccluded ray gets

    ω.y ≥ 0: the sky map, bilinear in the paraboloid map (``atmosphere.sample_sky_map``);
    ω.y < 0: the ground, a Lambertian plane of albedo ``ground_albedo`` lit by the sky only:
             L_g = ρ_g/π·E_sky↓ (``SkyVolume.ground_radiance``),

and is projected onto real L2 SH (:mod:`serenity.kernels.sh`): L_k = 4π/N·Σ L(ωᵢ)Y_k(ωᵢ), then
convolved with the clamped cosine and windowed: E_k = Â_l·w_l·L_k (W·m⁻², the volume's
coefficients (P, 27)).

Updating: the next ``layers`` layers of a continuous cycle over the volume are integrated against
the newest sky map, so with the sun moving every frame each layer is at most ceil(Y / layers)
updates old; once every layer has seen the current sky, nothing is done. Probe results are
deterministic (fixed per-probe seeds), so a layer-by-layer sweep equals a rebuild bit for bit.
"""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from serenity.config import SKY_SEQUENCES
from serenity.kernels.atmosphere import sample_sky_map
from serenity.kernels.factory import kernel_factory
from serenity.kernels.launch import launch
from serenity.kernels.occlusion import intersect_quads
from serenity.kernels.sampling import cp_rotation, hash_u32, sample_probe_direction
from serenity.kernels.sh import eval_sh9, vec9
from serenity.kernels.skylookup import ProbeGrid
from serenity.kernels.skymethod import SkyVolumeMethod

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# constants

_FOUR_PI = wp.constant(4.0 * math.pi)


# ---------------------------------------------------------------------------------------------
# kernels


@kernel_factory(sequence=SKY_SEQUENCES)
def integrate_sky_layer_kernel(sequence: str):
    """The probe-integration kernel for one direction ``sequence`` (``SkyConfig.sequence``), compiled
    in: Hammersley points Cranley–Patterson rotated per probe, or Owen-scrambled Sobol' per probe."""
    if sequence not in SKY_SEQUENCES:
        raise ValueError(f"sequence must be one of {SKY_SEQUENCES}, got {sequence!r}")
    hammersley = sequence == "hammersley"

    @wp.kernel(enable_backward=False, module="unique")
    def integrate_sky_layer(
        # inputs
        grid: ProbeGrid,
        first_layer: int,
        centers: wp.array(dtype=wp.vec3),
        ups: wp.array(dtype=wp.vec3),
        rights: wp.array(dtype=wp.vec3),
        halves: wp.array(dtype=wp.vec2),
        quad_count: int,
        sky_map: wp.array2d(dtype=wp.vec3),
        ground: wp.vec3,
        base_points: wp.array(dtype=wp.vec2),
        rays: int,
        salt: wp.uint32,
        scale: vec9,
        # outputs
        coeffs: wp.array2d(dtype=float),
        offset: int,
    ):
        t = wp.tid() + offset
        res_x = grid.res[0]
        res_y = grid.res[1]
        res_z = grid.res[2]
        cell = grid.cell
        slab = res_x * res_z
        y = first_layer + t // slab
        rem = t - (t // slab) * slab
        z = rem // res_x
        x = rem - z * res_x
        probe = (z * res_y + y) * res_x + x
        p = grid.origin + wp.vec3(float(x) * cell[0], float(y) * cell[1], float(z) * cell[2])
        seed = hash_u32(wp.uint32(probe) ^ salt)
        rot = cp_rotation(seed)
        acc_r = vec9()
        acc_g = vec9()
        acc_b = vec9()
        for k in range(rays):
            d = sample_probe_direction(k, base_points, rot, seed, wp.static(hammersley))
            if not intersect_quads(p, d, centers, ups, rights, halves, quad_count):
                radiance = ground
                if d[1] >= 0.0:
                    radiance = sample_sky_map(sky_map, d)
                b = eval_sh9(d)
                acc_r += b * radiance[0]
                acc_g += b * radiance[1]
                acc_b += b * radiance[2]
        w = _FOUR_PI / float(rays)
        for k in range(9):
            s = scale[k] * w
            coeffs[probe, 3 * k + 0] = acc_r[k] * s
            coeffs[probe, 3 * k + 1] = acc_g[k] * s
            coeffs[probe, 3 * k + 2] = acc_b[k] * s

    return integrate_sky_layer


# ---------------------------------------------------------------------------------------------
# host


class LayersMethod(SkyVolumeMethod):
    """``"layers"``: the paper's per-layer integration (module docstring)."""

    def integrate(self, sky_map, first: int, count: int) -> None:
        """Integrate y-layers ``first`` .. ``first + count - 1`` against ``sky_map`` (Warp)."""
        v = self.volume
        cfg = v.config
        x, _, z = v.resolution
        c, u, r, h = v.quads_wp
        launch(integrate_sky_layer_kernel(cfg.sequence), count * x * z,
               [v.probe_grid(), int(first), c, u, r, h, len(v.quads), sky_map,
                wp.vec3(*v.ground_radiance.astype(np.float32)), v.base_points, int(cfg.rays_per_probe),
                wp.uint32(cfg.seed & 0xFFFFFFFF), v.scale, v.coeffs_wp],
               device=v.device)

    def update(self, sun, sky_map, layers: int) -> bool:
        v = self.volume
        if layers <= 0 or v.pending_layers == 0:
            return False
        for start, n in v.next_slabs(layers):
            self.integrate(sky_map, start, n)
            v.mark_lit(start, n)
        return True

    def rebuild(self, sun, sky_map) -> None:
        v = self.volume
        y = v.resolution[1]
        self.integrate(sky_map, 0, y)
        v.mark_lit(0, y)
        v.restart_cycle()
