"""LPV basis and transfer constants (package docstring: SH convention, propagation).

L1 SH stored as (Y0, x, y, z) with Y(ω) = (SH_C0, SH_C1·ω) (``SH_C0``, ``SH_C1`` from
``serenity.kernels.sh``). The clamped cosine max(0, n·ω) is (COS_LOBE_0, COS_LOBE_1·n); a VPL of
flux Φ has intensity SH Φ·(VPL_K0, VPL_K1·n); a surfel's blocking potential per unit coverage is
(GV_K0, GV_K1·n) → 1/3 + 2/3·n·ω. ``TRANSFER``: the sparse 4×4 transfer of one propagation
direction (the 5-face sum of the package docstring), with ``W_FRONT``/``W_SIDE`` the face solid
angles. The ``wp.constant`` twins (T_*, C0, C1, K0, K1, G0, G1, E0, E1) are what the kernels use.
"""

from __future__ import annotations

import math

import warp as wp

from serenity.config import LPV_MAX_CASCADES
from serenity.kernels.sh import SH_C0, SH_C1

COS_LOBE_0 = math.sqrt(math.pi) / 2.0  # SH of max(0, n·ω): (COS_LOBE_0, COS_LOBE_1·n)
COS_LOBE_1 = math.sqrt(math.pi / 3.0)
VPL_K0 = COS_LOBE_0 / math.pi  # = SH_C0: a VPL of flux Φ has intensity SH Φ·(VPL_K0, VPL_K1·n)
VPL_K1 = COS_LOBE_1 / math.pi  # = 1/√(3π)
GV_K0 = 4.0 / 3.0 * COS_LOBE_0  # blocking SH per unit coverage: (GV_K0, GV_K1·n) → 1/3 + 2/3 n·ω
GV_K1 = 4.0 / 3.0 * COS_LOBE_1
SH_FLUX = 2.0 * math.sqrt(math.pi)  # flux (W) of an intensity SH = SH_FLUX·DC

MAX_CASCADES = LPV_MAX_CASCADES  # the kernels and the GLSL take up to this many cascades


def _rect_solid_angle(a0: float, a1: float, b0: float, b1: float, d: float) -> float:
    """Solid angle of the rectangle [a0,a1]×[b0,b1] in a plane at distance d, seen from the origin."""

    def corner(a, b):
        return math.atan(a * b / (d * math.sqrt(a * a + b * b + d * d)))

    return corner(a1, b1) - corner(a0, b1) - corner(a1, b0) + corner(a0, b0)


def face_solid_angles() -> tuple[float, float]:
    """(Δω_front, Δω_side) in sr, seen from the centre of a unit source cell (package docstring)."""
    return _rect_solid_angle(-0.5, 0.5, -0.5, 0.5, 1.5), _rect_solid_angle(-0.5, 0.5, 0.5, 1.5, 0.5)


W_FRONT, W_SIDE = face_solid_angles()  # 0.4006697, 0.4234314 sr
_INV_SQRT5 = 1.0 / math.sqrt(5.0)  # side-face centre direction (2d ± e)/√5
# sparse transfer of one neighbour direction d (package doc), source SH (s0, sv), sa = sv·d:
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
W_FRONT_C = wp.constant(W_FRONT)  # the clamped 5-face gather (``propagate.gather_clamped``)
W_SIDE_C = wp.constant(W_SIDE)
INV_SQRT5 = wp.constant(_INV_SQRT5)

C0 = wp.constant(SH_C0)
C1 = wp.constant(SH_C1)
K0 = wp.constant(VPL_K0)
K1 = wp.constant(VPL_K1)
G0 = wp.constant(GV_K0)
G1 = wp.constant(GV_K1)
E0 = wp.constant(COS_LOBE_0)  # irradiance: E = E0·l0 − E1·(l.xyz·n)
E1 = wp.constant(COS_LOBE_1)
