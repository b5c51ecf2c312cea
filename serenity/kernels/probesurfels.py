"""What the traced probes (``serenity.kernels.probegather``) make of their rays' hits, on the host:
surfels (the hits merged into cubes by :class:`SurfelMerge`, numbered along z, then y, then x), each
surfel's shadow-ray origin (:func:`shadow_origins`), and the probes' depth moments (:class:`MomentWeights`)
laid out as the lookup's visibility atlas (:func:`visibility_atlas`, read by
``serenity.kernels.skylookup.probe_visibility``).

Shapes: hits (N, 3) float32 positions, normals and albedo; surfels (S, 3) float64 mean positions,
normals and albedo; moments (P, VIS_OCT², 2) float32 (mean distance, mean squared distance, m, m²).
"""

from __future__ import annotations

import numpy as np

from serenity.kernels.skylookup import VIS_OCT, VIS_TILE

#: each depth-moment texel averages the rays' hit distances d and d² weighted by max(0, cos)^VIS_POWER
#: around its direction
VIS_POWER = 16.0
#: host work over every probe ray (millions) runs in slices of this many, so that no temporary
#: spans them all
SLICE = 1 << 20

SURFEL_SHADOW_SPREAD = 0.5
"""Where in its square a surfel's shadow ray may start (``shadow_origins``), as a fraction of the
square's side around its mean position: far enough apart that a straight shadow edge crosses a row of
surfels one at a time, near enough the mean that the one ray stands for the surfel (FLIP of
``traced-probes`` at 320×180: the full square 0.0571 courtyard / 0.0433 Cornell box, half 0.0565 /
0.0430, the mean itself 0.0560 / 0.0426)."""


def oct_decode_np(uv: np.ndarray) -> np.ndarray:
    """(N, 3) unit directions of octahedral coordinates (N, 2) in [-1, 1]² (inverse of oct_encode)."""
    u, v = uv[:, 0].astype(np.float64), uv[:, 1].astype(np.float64)
    y = 1.0 - np.abs(u) - np.abs(v)
    x, z = u.copy(), v.copy()
    low = y < 0
    x[low] = (1.0 - np.abs(v[low])) * np.where(u[low] >= 0, 1.0, -1.0)
    z[low] = (1.0 - np.abs(u[low])) * np.where(v[low] >= 0, 1.0, -1.0)
    d = np.stack([x, y, z], axis=1)
    return d / np.linalg.norm(d, axis=1, keepdims=True)




def oct_texel_directions(size: int) -> np.ndarray:
    """(size², 3) the directions of an octahedral map's texel centres, row-major (v, u)."""
    c = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    v, u = np.meshgrid(c, c, indexing="ij")
    return oct_decode_np(np.stack([u.ravel(), v.ravel()], axis=1))


def shadow_ray_offsets(normals: np.ndarray, size: float) -> np.ndarray:
    """(S, 3) float64: where in its square each surfel's shadow ray starts, relative to its mean
    position: surfel i's point of the R2 low-discrepancy sequence (Roberts 2018), frac(½ + i·(1/g, 1/g²))
    with g the plastic number, on the size × size square across its normal. The surfels' centres lie
    on a grid; from the centres, a roof's straight shadow edge moving with the sun crossed a whole row
    of them in one frame and the gathered light popped (``docs/stability.md``). Surfels are numbered
    along the grid's z, then y, then x (``_make_surfels``), so the surfels of a row get points spread
    evenly across the square, and the edge crosses them one at a time."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    g = 1.32471795724474602596
    i = np.arange(len(n), dtype=np.float64)[:, None]
    uv = ((0.5 + i * np.array([[1.0 / g, 1.0 / (g * g)]])) % 1.0 - 0.5) * float(size)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-12)
    t2 = np.cross(n, t1)
    return uv[:, :1] * t1 + uv[:, 1:] * t2


def shadow_origins(positions: np.ndarray, surfel: np.ndarray, means: np.ndarray, normals: np.ndarray,
                   size: float) -> np.ndarray:
    """(S, 3) float64: where each surfel's shadow ray starts: of the hits ``positions`` (N, 3) that
    make surfel ``surfel`` (N,), the one nearest the surfel's point (``means`` + ``SURFEL_SHADOW_SPREAD``
    × :func:`shadow_ray_offsets`). A hit lies on the surface, where a point of the square may not: at
    a corner or an edge it lies inside the wall beside the surfel or beyond the edge."""
    pos = np.asarray(positions).reshape(-1, 3)
    inv = np.asarray(surfel).reshape(-1)
    means = np.asarray(means, np.float64)
    target = (means + SURFEL_SHADOW_SPREAD * shadow_ray_offsets(normals, size)).astype(np.float32)

    def d2(a):  # the squared distances of hits a .. a + SLICE to their surfel's point
        diff = pos[a:a + SLICE].astype(np.float32) - target[inv[a:a + SLICE]]
        return np.einsum("ij,ij->i", diff, diff)

    # in slices, twice (the nearest, then which hit it is): millions of hits as float64 (N, 3) cost
    # a GB, and even one float per hit is tens of MB
    nearest = np.full(len(means), np.inf, np.float32)
    for a in range(0, len(pos), SLICE):
        np.minimum.at(nearest, inv[a:a + SLICE], d2(a))  # O(N): a sort of millions of hits cost seconds
    idx = np.concatenate([np.flatnonzero(d2(a) == nearest[inv[a:a + SLICE]]) + a
                          for a in range(0, len(pos), SLICE)] or [np.zeros(0, np.int64)])
    # (a tie keeps the last of its hits)
    out = means.copy()
    out[inv[idx]] = pos[idx]
    return out



def hit_distances(hits: dict, origins: np.ndarray, rays: int, cap: float) -> np.ndarray:
    """(P, R) float32 the distance of each ray's hit (front or back face) in ``hits`` (P·R rays,
    probe-major) from its probe at ``origins`` (P, 3); a miss or a hit beyond ``cap`` at ``cap``."""
    diff = hits["position"].reshape(-1, rays, 3) - origins[:, None, :].astype(np.float32)
    d = np.sqrt(np.einsum("prc,prc->pr", diff, diff))
    any_hit = (hits["hit"] | hits["back"]).reshape(-1, rays)
    return np.where(any_hit, np.minimum(d, np.float32(cap)), np.float32(cap)).astype(np.float32)


class MomentWeights:
    """The probes' depth moments (module constants) as a matrix product per direction set: texel t of
    a probe of set s is Σ_r W[s, t, r]·(d_r, d_r²) / Σ_r W[s, t, r], W = max(0, ω_t·ω_r)^VIS_POWER,
    the same for every probe of the set."""

    def __init__(self, dirs: np.ndarray):
        texels = oct_texel_directions(VIS_OCT).astype(np.float32).astype(np.float64)
        c = np.einsum("tc,src->str", texels, np.asarray(dirs, np.float64))
        self.weights = np.where(c > 0.0, np.maximum(c, 0.0) ** VIS_POWER, 0.0).astype(np.float32)  # (S, T, R)
        self.norm = np.maximum(self.weights.sum(axis=2, dtype=np.float64), 1e-12).astype(np.float32)  # (S, T)

    def moments(self, dist: np.ndarray, sets: np.ndarray) -> np.ndarray:
        """(P, T, 2) float32 the moments of P probes' ray distances ``dist`` (P, R) of sets ``sets`` (P,)."""
        out = np.empty((len(dist), self.weights.shape[1], 2), np.float32)
        for k in np.unique(sets):
            i = np.flatnonzero(sets == k)
            d = dist[i]
            w = self.weights[k].T
            out[i, :, 0] = (d @ w) / self.norm[k]
            out[i, :, 1] = ((d * d) @ w) / self.norm[k]
        return out


def surfel_keys(positions: np.ndarray, normals: np.ndarray, anchor: np.ndarray, size: float) -> np.ndarray:
    """(N,) int64 the surfel of each hit: its cube of ``size`` metres counted from ``anchor`` and the
    dominant axis and sign of its normal (sorted by key: along z, then y, then x)."""
    axis = np.argmax(np.abs(normals), axis=1)
    side = normals[np.arange(len(normals)), axis] > 0
    key = axis.astype(np.int64) * 2 + side
    for c, prime in ((2, 1), (1, 1_000_033), (0, 1_000_033 * 1_000_003)):
        key += np.floor((positions[:, c] - anchor[c]) / size).astype(np.int64) * (6 * prime)
    return key


class SurfelMerge:
    """Ray hits merged into surfels chunk by chunk (``surfel_keys``): each chunk's hits are summed
    per surfel as they come, ``finish`` merges the chunks' sums; only the hits' positions (for the
    shadow rays' origins) and each ray's surfel outlive their chunk."""

    def __init__(self, rays: int, anchor: np.ndarray, size: float):
        if rays >= 2**31:
            raise ValueError(f"{rays} probe rays: at most 2**31 - 1")
        self.anchor, self.size = np.asarray(anchor, np.float64), float(size)
        self.surfel = np.full(rays, -1, np.int32)  # per ray: a chunk's surfel (``merged``), -2 a back face
        self.keys, self.sums = np.zeros(0, np.int64), np.zeros((0, 10))  # the surfels so far, sorted by key
        self.merged = np.zeros(0, np.int32)  # each chunk's surfel (numbered across chunks): its index in keys
        self.hit_positions = np.empty((rays, 3), np.float32)  # filled from the front (pages as written)
        self.hit_surfel = np.empty(rays, np.int32)
        self.hits = 0

    def add(self, rows, hit, back, positions, normals, albedo) -> None:
        """The rays ``rows`` (a slice or indices, probe-major) with their hit and back-face masks and hits;
        the rays of neither mask are left as they are."""
        idx = np.flatnonzero(hit)
        p, n = positions[idx], normals[idx]
        keys, inv = np.unique(surfel_keys(p, n, self.anchor, self.size), return_inverse=True)
        inv = inv.reshape(-1)
        m = len(keys)
        sums = np.empty((m, 10))
        sums[:, 0] = np.bincount(inv, minlength=m)
        for j, a in enumerate((p, n, albedo[idx])):
            for c in range(3):
                sums[:, 1 + 3 * j + c] = np.bincount(inv, a[:, c], m)
        # merged into the surfels so far (tens of thousands): their sums, and where each moved
        old = len(self.keys)
        self.keys, both = np.unique(np.concatenate([self.keys, keys]), return_inverse=True)
        both = both.reshape(-1).astype(np.int32)
        every = np.concatenate([self.sums, sums])
        self.sums = np.stack([np.bincount(both, every[:, c], len(self.keys)) for c in range(10)], axis=1)
        local = (inv + len(self.merged)).astype(np.int32)
        self.merged = np.concatenate([both[:old][self.merged], both[old:]])
        rays = self.surfel[rows]
        if isinstance(rows, slice):  # a view: written in place
            rays[idx] = local
            rays[back] = -2
        else:
            rays[idx] = local
            rays[back] = -2
            self.surfel[rows] = rays
        h = self.hits
        self.hit_positions[h:h + len(idx)] = p
        self.hit_surfel[h:h + len(idx)] = local
        self.hits += len(idx)

    def means(self) -> tuple[np.ndarray, np.ndarray]:
        """The surfels so far: mean positions and (unit) mean normals, float64 (S, 3) each."""
        cnt = np.maximum(self.sums[:, :1], 1.0)
        sn = self.sums[:, 4:7] / cnt
        sn /= np.maximum(np.linalg.norm(sn, axis=1, keepdims=True), 1e-12)
        return self.sums[:, 1:4] / cnt, sn

    def finish(self):
        """(surfel per ray (N,) int32: ≥ 0, −1 a miss, −2 a back face; the surfels' mean positions,
        normals and albedo, float64 (S, 3) each; their shadow rays' origins, ``shadow_origins``)."""
        total, inv = self.sums, self.merged
        sp, sn = self.means()
        sa = total[:, 7:10] / np.maximum(total[:, :1], 1.0)
        surfel, hit_surfel = self.surfel, self.hit_surfel[:self.hits]
        for a in range(0, len(surfel), SLICE):  # in place, in slices: no temporaries of every ray
            s = surfel[a:a + SLICE]
            hit = s >= 0
            s[hit] = inv[s[hit]]
            h = hit_surfel[a:a + SLICE]
            h[:] = inv[h]
        origins = shadow_origins(self.hit_positions[:self.hits], hit_surfel, sp, sn, self.size)
        self.surfel = self.hit_positions = self.hit_surfel = None
        return surfel, sp, sn, sa, origins


def visibility_atlas(moments: np.ndarray, resolution) -> np.ndarray:
    """The probes' depth moments ((P, VIS_OCT², 2), storage order z, y, x) as one (Z·T, Y, X·T, 2)
    float32 array (T = VIS_TILE): probe (x, y, z)'s tile at [z·T : z·T + T, y, x·T : x·T + T], its map
    inside a one-texel border copied by the octahedral map's wrap (an edge texel's neighbour across
    the edge is the mirrored texel of the same edge; a corner's is the opposite corner), so that a
    bilinear tap inside the tile filters across the map's seams."""
    x, y, z = (int(a) for a in resolution)
    o, t = VIS_OCT, VIS_TILE
    m = np.asarray(moments, np.float32).reshape(z, y, x, o, o, 2)  # (..., v, u)
    tile = np.empty((z, y, x, t, t, 2), np.float32)
    tile[:, :, :, 1:-1, 1:-1] = m
    tile[:, :, :, 0, 1:-1] = m[:, :, :, 0, ::-1]
    tile[:, :, :, -1, 1:-1] = m[:, :, :, -1, ::-1]
    tile[:, :, :, 1:-1, 0] = m[:, :, :, ::-1, 0]
    tile[:, :, :, 1:-1, -1] = m[:, :, :, ::-1, -1]
    tile[:, :, :, 0, 0] = m[:, :, :, -1, -1]
    tile[:, :, :, 0, -1] = m[:, :, :, -1, 0]
    tile[:, :, :, -1, 0] = m[:, :, :, 0, -1]
    tile[:, :, :, -1, -1] = m[:, :, :, 0, 0]
    # (z, y, x, v, u) -> (z, v, y, x, u) -> (Z·T, Y, X·T)
    return np.ascontiguousarray(tile.transpose(0, 3, 1, 2, 4, 5).reshape(z * t, y, x * t, 2))

