"""Occlusion quads (paper §7, Fig. 6): the two-sided rectangles that stand in for the scene's
buildings when the sky volume's probes test their rays. ``model.OcclusionQuad`` holds one
(centre, unit up and right axes, half extents along them, metres); ``quads_arrays`` packs a list of
them as float32 arrays, ``intersect_quads`` is the Warp test the probe integrations use and
``occluded_np`` its numpy twin.
"""

from __future__ import annotations

import numpy as np
import warp as wp

wp.set_module_options({"enable_backward": False})

# ---------------------------------------------------------------------------------------------
# funcs


@wp.func
def intersect_quads(o: wp.vec3, d: wp.vec3, centers: wp.array(dtype=wp.vec3), ups: wp.array(dtype=wp.vec3),
                    rights: wp.array(dtype=wp.vec3), halves: wp.array(dtype=wp.vec2), count: int) -> bool:
    """Whether the ray o + t·d (t > 0) hits any two-sided occlusion quad."""
    for q in range(count):
        up = ups[q]
        right = rights[q]
        n = wp.cross(right, up)
        denom = wp.dot(d, n)
        if wp.abs(denom) > 1.0e-12:
            oc = centers[q] - o
            t = wp.dot(oc, n) / denom
            if t > 1.0e-5:
                h = d * t - oc
                hw = halves[q]
                if wp.abs(wp.dot(h, up)) <= hw[0] and wp.abs(wp.dot(h, right)) <= hw[1]:
                    return True
    return False


# ---------------------------------------------------------------------------------------------
# host


def quads_arrays(quads) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(centers, ups, rights, halves (Q,2) = (half_up, half_right)) float32 of OcclusionQuads."""
    if not quads:
        z = np.zeros((0, 3), np.float32)
        return z, z, z, np.zeros((0, 2), np.float32)
    c = np.array([q.center for q in quads], np.float32)
    u = np.array([q.up for q in quads], np.float32)
    r = np.array([q.right for q in quads], np.float32)
    h = np.array([[q.half_up, q.half_right] for q in quads], np.float32)
    return c, u, r, h


def occluded_np(origins, directions, quads) -> np.ndarray:
    """(N,) bool: rays (N,3)/(N,3) (or one origin (3,)) blocked by any quad (twin of ``intersect_quads``)."""
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    o = np.broadcast_to(np.asarray(origins, np.float64), d.shape)
    hit = np.zeros(len(d), bool)
    for q in quads:
        n = np.cross(q.right, q.up)
        denom = d @ n
        oc = q.center[None] - o
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (oc @ n) / denom
        ok = (np.abs(denom) > 1e-12) & (t > 1e-5)
        h = d * np.where(ok, t, 0.0)[:, None] - oc
        hit |= ok & (np.abs(h @ q.up) <= q.half_up) & (np.abs(h @ q.right) <= q.half_right)
    return hit
