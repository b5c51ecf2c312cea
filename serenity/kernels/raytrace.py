"""Ray-traced G-buffers for reflections and refractions (paper §9, Fig. 14).

The ray-casting buffer (``raster/raycast.py``) gives, for the pixels whose visible surface
reflects or refracts, a ray origin, a reflected and a refracted direction and a ray cone. Only
those rays are traced here, through the scene's kd-tree (:mod:`serenity.kernels.kdtree`), and the
surface each one hits is written into a G-buffer with **the same layout as the rasterised one**
(``raster/glsl/gbuffer.glsl``), so the deferred pass lights both the same way:

    albedo   (N,4) float32: rgb = linear albedo = material albedo × texture (trilinear, mip from the
             ray cone), a = material index.
    normal   (N,4): xyz = interpolated vertex normal (unit), flipped to face the ray's origin;
             w = Phong specular strength k_s.
    position (N,4): xyz = world position of the hit (m, interpolated from the triangle's vertices);
             w = 1 where the ray hit something (coverage), 0 on a miss.
    material (N,4): (Phong exponent, reflectivity, transparency, index of refraction).
    ray_dir  (N,4): xyz = the unit ray direction — on a miss the direction in which the deferred
             pass looks up the sky; w = hit distance in m (0 on a miss). A ray with a zero, NaN or
             infinite direction (e.g. no refraction under total internal reflection) gets all
             zeros everywhere: "not traced", as the deferred pass reads ``ray_dir``.
    eye      (N,4): xyz = where the last segment of the ray starts: the viewer of the hit (the ray's
             origin, or the last transparent interface it passed); w = the sun's visibility at the
             hit when a sun direction is given (1 = lit, 0 = blocked), else 0.
Misses write zeros to albedo, normal, position and material.

Materials (``scene.model.Material``): a cut-out's hits (``alpha_cutoff``) go through the alpha test
(:func:`covered`: coverage × the albedo texture's alpha, bilinear at level 0) and a rejected hit is
not there — the ray, the sun's shadow ray and the probes' rays go on beyond it
(:func:`trace_scene`; the tree's own host queries do the same, ``KdTree.set_alpha_test``). A
normal-mapped material's normal is read from its tangent-space map at level 0 (bilinear) in the
frame of the interpolated normal and the per-vertex tangent (:func:`mapped_normal`), then turned
with the triangle's side towards the ray. Textures are read at the uvs through the material's uv
transforms (KHR_texture_transform).

Transmission (beyond the paper, whose tracer stops at the first hit, §12): with ``transmissions``
= K > 0 a ray that hits a transparent material (transparency > 0) is bent there instead of
shaded — refracted by Snell's law with the material's index (entering where the interpolated
normal faces the ray, leaving where it faces away; air outside), or mirrored under total internal
reflection — and traced on, up to K times; ``ray_dir``/``eye`` then describe the last segment
and ``ray_dir.w`` the whole path length. Refraction rays use it so that a glass solid shows what
lies behind it rather than its own back face; the interfaces after the first (which the GL
composite shades, Fresnel and tint) are taken as lossless.

Sun visibility (beyond the paper, which lights the hits with overlapped shadow maps, §9): with a
``sun_direction`` every hit also traces one shadow ray towards the sun's centre (any hit in
(tmin, inf), glass included — it casts a shadow as in the shadow maps and the reference), a hard
shadow. The shadow maps around the camera are too coarse for what a reflection or refraction shows
up close: a wall 5 cm behind a window pane 26 m away falls in a 40 cm texel of the largest
512-texel map, and the bias of a texel or more lit it through the glass (2.4× the reference's
luminance on the courtyard's glass).

Texture filtering: ray cones (Akenine-Möller et al., "Texture Level of Detail Strategies for
Real-Time Ray Tracing", Ray Tracing Gems ch. 20). The cone's width at the hit is
``cone_width + cone_spread · t`` (m; ``cone_width`` at the ray origin, ``cone_spread`` in rad, t in
m), and the level of detail is λ = log2(width / |n_g·d| · sqrt(t_a / p_a)), with t_a the
triangle's area in texels of level 0 (uv area × W × H) and p_a its world area. λ is clamped to the
mip chain and filtered trilinearly (bilinear in two levels, GL's LINEAR_MIPMAP_LINEAR; repeat
wrap; uv with v up, texture rows stored top first, as ``scene/texture.py`` defines). The texels of
every level are stored as 8-bit RGBA (``texels.pack_mip_chains``: rgb sRGB-encoded for albedo maps,
linear for normal maps, alpha linear) and decoded to linear before they are filtered, as a GPU
filters an sRGB8 texture: a quarter of float32 RGBA's memory and loads; an 8-bit image's level 0
decodes to exactly the scene's float values, the box-filtered mips to within half an 8-bit step.

Inputs to :meth:`RayTracer.trace`: origins (N,3) m, directions (N,3) (any length, normalised
here), cone_width (N,) or scalar m, cone_spread (N,) or scalar rad. Host class
:class:`RayTracer` packs the merged scene (geometry, materials and every texture's mip chain) into
Warp arrays once — the geometry is static — and owns the kd-tree. On the CPU launches are split
over all cores (:func:`serenity.kernels.launch.launch`); big incoherent batches are traced in a
reordered order and scattered back into the caller's (``sort``, as :meth:`KdTree.intersect` does).
"""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager

try:
    import fcntl
except ImportError:  # pragma: no cover - Windows: builds are not serialised
    fcntl = None
import numpy as np
import warp as wp

from serenity.config import KdBuildConfig
from serenity.device import init_warp, resolve_device
from serenity.errors import SerenityError
from serenity.gbuffer_layout import RT_GBUFFER_KEYS
from serenity.kernels.kdtree import (
    TRACE_MODULE_OPTIONS,
    KdTree,
    KdTreeData,
    buffers_like,
    finite,
    gather_in_order,
    ray_order,
    scatter_in_order,
    trace_kd,
)
from serenity.kernels.kdtree_build import CACHE_MIN_TRIANGLES
from serenity.kernels.launch import launch
from serenity.kernels.texels import lut8, pack_mip_chains
from serenity.scene.cache import cache_dir
from serenity.scene.model import normal_map_frame, used_vertices

wp.set_module_options(TRACE_MODULE_OPTIONS)  # no FMA contraction: watertight on CUDA too (kdtree/layout.py)

# ----------------------------------------------------------------------------------------------
# constants
# ----------------------------------------------------------------------------------------------

RAY_EPSILON_REL = 1e-4  # default tmin: this fraction of the scene's bounding-box diagonal (m)
MIN_COSINE = 1e-4  # |n·d| floor in the LOD formula (grazing hits get the coarsest mips, not inf)
#: a ray goes on through at most this many rejected cut-out hits (``trace_scene``), then counts as a miss
MAX_CUTOUT_LAYERS = 64
_INF_RT = wp.constant(float("inf"))

# ----------------------------------------------------------------------------------------------
# structs
# ----------------------------------------------------------------------------------------------


@wp.struct
class SceneData:
    """The merged scene on one device (vertex attributes, faces, materials, texture mips)."""

    tree: KdTreeData
    normals: wp.array(dtype=wp.vec3)  # (V,) unit vertex normals
    uvs: wp.array(dtype=wp.vec2)  # (V,) texture coordinates
    faces: wp.array(dtype=wp.vec3i)  # (F,) vertex indices
    face_material: wp.array(dtype=wp.int32)  # (F,)
    mat_albedo: wp.array(dtype=wp.vec3)  # (M,) linear
    mat_specular: wp.array(dtype=float)  # (M,) k_s
    mat_params: wp.array(dtype=wp.vec4)  # (M,) shininess, reflectivity, transparency, ior
    mat_texture: wp.array(dtype=wp.int32)  # (M,) texture index or -1
    tex_first_level: wp.array(dtype=wp.int32)  # (T,) index into the level tables
    tex_levels: wp.array(dtype=wp.int32)  # (T,) number of mip levels
    level_offset: wp.array(dtype=wp.int32)  # (L,) first texel of each level in ``texels``
    level_size: wp.array(dtype=wp.vec2i)  # (L,) (width, height)
    texels: wp.array(dtype=wp.uint32)  # all levels of all textures, row-major, top row first, RGBA8 packed
    level_srgb: wp.array(dtype=wp.int32)  # (L,) 1: the level's rgb is sRGB-encoded (albedo), 0: linear
    lut8: wp.array(dtype=float)  # (512,) an 8-bit value decoded: [0, 256) from sRGB, [256, 512) linear
    mat_alpha: wp.array(dtype=wp.vec2)  # (M,) coverage factor, alpha cutoff (< 0: not a cut-out)
    mat_uv: wp.array(dtype=wp.vec3)  # (4M,) rows of the albedo's, then the normal map's (2, 3) uv transform
    mat_normal_tex: wp.array(dtype=wp.int32)  # (M,) normal map's texture index or -1
    mat_normal: wp.array(dtype=wp.vec4)  # (M,) normal_map_frame (row-major 2x2) x normal_scale
    tangents: wp.array(dtype=wp.vec4)  # (V,) xyz, handedness w (one dummy entry without normal maps)
    cutouts: int  # 1 when some material is a cut-out (the alpha test runs on hits of those materials)


# ----------------------------------------------------------------------------------------------
# functions
# ----------------------------------------------------------------------------------------------


@wp.func
def wrap_index(i: int, n: int) -> int:
    r = i % n
    if r < 0:
        r += n
    return r


@wp.func
def sample_bilinear(scene: SceneData, level: int, uv: wp.vec2) -> wp.vec3:
    """Bilinear lookup of one mip level with repeat wrap (GL_LINEAR, GL_REPEAT)."""
    c = sample_bilinear4(scene, level, uv)
    return wp.vec3(c[0], c[1], c[2])


@wp.func
def texel(scene: SceneData, i: int, srgb: int) -> wp.vec4:
    """Texel ``i`` decoded to linear RGBA: rgb from sRGB where ``srgb`` is 1, alpha always linear
    (``pack_mip_chains``), each channel one load from ``lut8`` (exact: the float decode of an 8-bit
    image, as ``scene.texture`` stores it)."""
    v = scene.texels[i]
    base = wp.where(srgb != 0, 0, 256)
    m = wp.uint32(255)
    r = scene.lut8[base + int(v & m)]
    g = scene.lut8[base + int((v >> wp.uint32(8)) & m)]
    b = scene.lut8[base + int((v >> wp.uint32(16)) & m)]
    return wp.vec4(r, g, b, scene.lut8[256 + int(v >> wp.uint32(24))])


@wp.func
def sample_bilinear4(scene: SceneData, level: int, uv: wp.vec2) -> wp.vec4:
    """:func:`sample_bilinear` with the alpha channel."""
    size = scene.level_size[level]
    w = size[0]
    h = size[1]
    off = scene.level_offset[level]
    fu = uv[0] - wp.floor(uv[0])
    fv = uv[1] - wp.floor(uv[1])
    x = fu * float(w) - 0.5
    y = (1.0 - fv) * float(h) - 0.5  # rows are stored top first; v points up
    x0 = wp.floor(x)
    y0 = wp.floor(y)
    tx = x - x0
    ty = y - y0
    c0 = wrap_index(int(x0), w)
    c1 = wrap_index(int(x0) + 1, w)
    r0 = wrap_index(int(y0), h)
    r1 = wrap_index(int(y0) + 1, h)
    srgb = scene.level_srgb[level]
    t00 = texel(scene, off + r0 * w + c0, srgb)
    t01 = texel(scene, off + r0 * w + c1, srgb)
    t10 = texel(scene, off + r1 * w + c0, srgb)
    t11 = texel(scene, off + r1 * w + c1, srgb)
    top = t00 * (1.0 - tx) + t01 * tx
    bottom = t10 * (1.0 - tx) + t11 * tx
    return top * (1.0 - ty) + bottom * ty


@wp.func
def sample_trilinear(scene: SceneData, tex: int, uv: wp.vec2, lod: float) -> wp.vec3:
    """Trilinear lookup (GL_LINEAR_MIPMAP_LINEAR) at level of detail ``lod`` (clamped)."""
    first = scene.tex_first_level[tex]
    n = scene.tex_levels[tex]
    lam = wp.clamp(lod, 0.0, float(n - 1))
    l0 = int(wp.floor(lam))
    f = lam - float(l0)
    c = sample_bilinear(scene, first + l0, uv)
    if f > 0.0 and l0 + 1 < n:
        c = c * (1.0 - f) + sample_bilinear(scene, first + l0 + 1, uv) * f
    return c


@wp.func
def eval_texture_lod(scene: SceneData, tex: int, p0: wp.vec3, p1: wp.vec3, p2: wp.vec3, uv0: wp.vec2,
                     uv1: wp.vec2, uv2: wp.vec2, cone: float, cos_theta: float) -> float:
    """Ray-cone level of detail (RTG ch. 20): log2(cone / |cos| · sqrt(texel area / world area))."""
    size = scene.level_size[scene.tex_first_level[tex]]
    e1 = uv1 - uv0
    e2 = uv2 - uv0
    t_a = wp.abs(e1[0] * e2[1] - e1[1] * e2[0]) * float(size[0]) * float(size[1])
    p_a = wp.length(wp.cross(p1 - p0, p2 - p0))
    lod = float(-1.0e30)
    if t_a > 0.0 and p_a > 0.0 and cone > 0.0:
        lod = wp.log2(cone / wp.max(cos_theta, MIN_COSINE) * wp.sqrt(t_a / p_a))
    return lod


@wp.func
def uv_transform(scene: SceneData, row: int, uv: wp.vec2) -> wp.vec2:
    """``uv`` through the (2, 3) transform whose rows are ``mat_uv[row]``, ``mat_uv[row + 1]``."""
    r0 = scene.mat_uv[row]
    r1 = scene.mat_uv[row + 1]
    return wp.vec2(r0[0] * uv[0] + r0[1] * uv[1] + r0[2], r1[0] * uv[0] + r1[1] * uv[1] + r1[2])


@wp.func
def covered(scene: SceneData, prim: int, u: float, v: float) -> bool:
    """The alpha test at a hit: False where a cut-out material's coverage (factor × its albedo
    texture's alpha, bilinear at level 0, through the albedo uv transform) is below its cutoff."""
    m = scene.face_material[prim]
    ac = scene.mat_alpha[m]
    if ac[1] < 0.0:
        return True
    a = ac[0]
    tex = scene.mat_texture[m]
    if tex >= 0:
        f = scene.faces[prim]
        uv = (1.0 - u - v) * scene.uvs[f[0]] + u * scene.uvs[f[1]] + v * scene.uvs[f[2]]
        a = a * sample_bilinear4(scene, scene.tex_first_level[tex], uv_transform(scene, 4 * m, uv))[3]
    return a >= ac[1]


@wp.func
def trace_scene(scene: SceneData, o: wp.vec3, d: wp.vec3, tmin: float, tmax: float, any_hit: bool):
    """:func:`~serenity.kernels.kdtree.trace_kd` with the cut-outs' alpha test: a hit the test
    rejects is not there, and the ray goes on beyond it (traced again from its t, up to
    ``MAX_CUTOUT_LAYERS`` times). An any-hit query that first lands on a rejected hit goes on as a
    closest-hit search (an any hit is not the nearest, so tracing on beyond it could skip a nearer
    one). In a scene without cut-outs this is trace_kd."""
    prim, t, u, v = trace_kd(scene.tree, o, d, tmin, tmax, any_hit)
    if scene.cutouts == 0 or prim < 0:
        return prim, t, u, v
    if covered(scene, prim, u, v):
        return prim, t, u, v
    lo = tmin
    if not any_hit:
        lo = t
    for _layer in range(MAX_CUTOUT_LAYERS):
        prim, t, u, v = trace_kd(scene.tree, o, d, lo, tmax, False)
        if prim < 0:
            return prim, t, u, v
        if covered(scene, prim, u, v):
            return prim, t, u, v
        lo = t
    return int(-1), float(_INF_RT), float(0.0), float(0.0)


@wp.func
def mapped_normal(scene: SceneData, m: int, n: wp.vec3, f: wp.vec3i, u: float, v: float, uv: wp.vec2) -> wp.vec3:
    """The shading normal from material ``m``'s tangent-space normal map at mesh uv ``uv`` (its
    texture at level 0, bilinear), in the frame of the interpolated normal ``n`` and tangent; ``n``
    where the material has none or the tangent is degenerate."""
    ntex = scene.mat_normal_tex[m]
    if ntex < 0:
        return n
    b0 = 1.0 - u - v
    tg = b0 * scene.tangents[f[0]] + u * scene.tangents[f[1]] + v * scene.tangents[f[2]]
    t3 = wp.vec3(tg[0], tg[1], tg[2])
    t3 = t3 - n * wp.dot(n, t3)
    lt = wp.length(t3)
    if lt <= 1.0e-8:
        return n
    t3 = t3 / lt
    w = float(1.0)
    if tg[3] < 0.0:
        w = -1.0
    b = wp.cross(n, t3) * w
    c = sample_bilinear(scene, scene.tex_first_level[ntex], uv_transform(scene, 4 * m + 2, uv)) * 2.0 \
        - wp.vec3(1.0, 1.0, 1.0)
    fr = scene.mat_normal[m]
    x = fr[0] * c[0] + fr[1] * c[1]
    y = fr[2] * c[0] + fr[3] * c[1]
    nm = t3 * x + b * y + n * c[2]
    ln = wp.length(nm)
    if ln <= 1.0e-6:
        return n
    return nm / ln


# ----------------------------------------------------------------------------------------------
# kernels
# ----------------------------------------------------------------------------------------------


@wp.func
def bend(d: wp.vec3, n_out: wp.vec3, ior: float) -> wp.vec3:
    """Direction after the interface of normal ``n_out`` (pointing out of the medium of index
    ``ior``, air outside): refracted (Snell), or mirrored under total internal reflection."""
    nn = n_out
    eta = 1.0 / ior
    if wp.dot(n_out, d) > 0.0:  # leaving the medium
        nn = -n_out
        eta = ior
    c = -wp.dot(nn, d)
    k = 1.0 - eta * eta * (1.0 - c * c)
    if k < 0.0:
        return wp.normalize(d + 2.0 * c * nn)
    return wp.normalize(eta * d + (eta * c - wp.sqrt(k)) * nn)


@wp.kernel(enable_backward=False)
def trace_gbuffer(
    # inputs
    scene: SceneData,
    origins: wp.array(dtype=wp.vec3),
    directions: wp.array(dtype=wp.vec3),
    cone_width: wp.array(dtype=float),
    cone_spread: wp.array(dtype=float),
    tmin: float,
    tmax: float,
    transmissions: int,
    sun: wp.vec3,
    sun_shadows: int,
    # outputs
    out_albedo: wp.array(dtype=wp.vec4),
    out_normal: wp.array(dtype=wp.vec4),
    out_position: wp.array(dtype=wp.vec4),
    out_material: wp.array(dtype=wp.vec4),
    out_ray: wp.array(dtype=wp.vec4),
    out_eye: wp.array(dtype=wp.vec4),
    out_back: wp.array(dtype=wp.int32),  # empty, or 1 where the hit is a triangle's back face
    offset: int,
):
    i = wp.tid() + offset  # the ray's index in the traced order (inputs and outputs)
    zero = wp.vec4(0.0, 0.0, 0.0, 0.0)
    out_albedo[i] = zero
    out_normal[i] = zero
    out_position[i] = zero
    out_material[i] = zero
    out_ray[i] = zero
    out_eye[i] = zero
    report_back = out_back.shape[0] > 0
    if report_back:
        out_back[i] = 0
    d = directions[i]
    len_d = wp.length(d)
    if not (finite(len_d) and len_d > 0.0):
        return
    dn = d / len_d
    o = origins[i]
    travelled = float(0.0)
    # pass through up to ``transmissions`` transparent interfaces, then shade the hit
    for k in range(transmissions + 1):
        prim, t, u, v = trace_scene(scene, o, dn, tmin, tmax, False)
        out_eye[i] = wp.vec4(o[0], o[1], o[2], 0.0)
        if prim < 0:
            out_ray[i] = wp.vec4(dn[0], dn[1], dn[2], 0.0)
            return
        f = scene.faces[prim]
        b0 = 1.0 - u - v
        p0 = scene.tree.tri_verts[3 * prim]
        p1 = scene.tree.tri_verts[3 * prim + 1]
        p2 = scene.tree.tri_verts[3 * prim + 2]
        p = b0 * p0 + u * p1 + v * p2
        ng = wp.normalize(wp.cross(p1 - p0, p2 - p0))
        n = b0 * scene.normals[f[0]] + u * scene.normals[f[1]] + v * scene.normals[f[2]]
        ln = wp.length(n)
        if ln > 0.0:
            n = n / ln
        else:
            n = ng
        m = scene.face_material[prim]
        prm = scene.mat_params[m]
        if k < transmissions and prm[2] > 0.0 and prm[3] > 0.0:
            dn = bend(dn, n, prm[3])
            o = p
            travelled += t
            continue
        t_all = travelled + t
        out_ray[i] = wp.vec4(dn[0], dn[1], dn[2], t_all)
        if report_back and wp.dot(ng, dn) > 0.0:
            out_back[i] = 1
        flip = wp.dot(n, dn) > 0.0  # two-sided: face the viewer of this ray, as the G-buffer pass does
        uv0 = scene.uvs[f[0]]
        uv1 = scene.uvs[f[1]]
        uv2 = scene.uvs[f[2]]
        if scene.mat_normal_tex[m] >= 0:
            n = mapped_normal(scene, m, n, f, u, v, b0 * uv0 + u * uv1 + v * uv2)
        if flip:
            n = -n
        albedo = scene.mat_albedo[m]
        tex = scene.mat_texture[m]
        if tex >= 0:
            r = 4 * m
            uv = uv_transform(scene, r, b0 * uv0 + u * uv1 + v * uv2)
            cone = cone_width[i] + cone_spread[i] * t_all
            lod = eval_texture_lod(scene, tex, p0, p1, p2, uv_transform(scene, r, uv0), uv_transform(scene, r, uv1),
                                   uv_transform(scene, r, uv2), cone, wp.abs(wp.dot(ng, dn)))
            albedo = wp.cw_mul(albedo, sample_trilinear(scene, tex, uv, lod))
        out_albedo[i] = wp.vec4(albedo[0], albedo[1], albedo[2], float(m))
        out_normal[i] = wp.vec4(n[0], n[1], n[2], scene.mat_specular[m])
        out_position[i] = wp.vec4(p[0], p[1], p[2], 1.0)
        out_material[i] = prm
        if sun_shadows != 0:
            vis = float(1.0)
            s_prim, s_t, s_u, s_v = trace_scene(scene, p, sun, tmin, float(1.0e30), True)
            if s_prim >= 0:
                vis = 0.0
            out_eye[i] = wp.vec4(o[0], o[1], o[2], vis)
        return


# ----------------------------------------------------------------------------------------------
# host
# ----------------------------------------------------------------------------------------------


def _coverage_test(materials, fmat: np.ndarray, faces: np.ndarray, uvs: np.ndarray):
    """The alpha test on the host for :meth:`KdTree.set_alpha_test`: (prim, u, v) → (N,) bool covered
    (``Material.coverage`` at the hit's interpolated uv), the host twin of :func:`covered`."""
    def test(prim: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        f = faces[prim]
        b0 = (1.0 - u - v)[:, None]
        uv = b0 * uvs[f[:, 0]] + u[:, None] * uvs[f[:, 1]] + v[:, None] * uvs[f[:, 2]]
        out = np.ones(len(prim), bool)
        mats = fmat[prim]
        for mi in np.unique(mats):
            sel = mats == mi
            out[sel] = materials[int(mi)].coverage(uv[sel])
        return out
    return test


@contextmanager
def _build_lock(cached: bool) -> Iterator[None]:
    """One kd-tree build at a time across processes where the tree is cached (``cache_dir()/kdtree.lock``):
    the renderer and its tracer process start on the same scene together, and the second one then
    reads the tree the first one built and cached instead of building it again beside it."""
    if not cached or fcntl is None:
        yield
        return
    try:
        folder = cache_dir()
        folder.mkdir(parents=True, exist_ok=True)
        f = open(folder / "kdtree.lock", "a")  # noqa: SIM115 - held for the block
    except OSError:  # an unwritable cache: no cache, nothing to share
        yield
        return
    with f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


class RayTracer:
    """Traces rays into G-buffers (module docstring) for one static scene on one device.

    ``RayTracer(scene, device=None)`` builds (or loads from the disk cache) the kd-tree of
    ``scene.merged()``; geometry, materials and all texture mips are uploaded once, on the first
    :meth:`trace` (``data``).
    """

    def __init__(self, scene, device: str | None = None, *, tree_config: KdBuildConfig | None = None,
                 cache: bool | None = None, progress: bool | None = None, ray_epsilon: float | None = None):
        self.device = resolve_device(device)
        init_warp()
        pos, _, uv, faces, fmat = scene.merged()
        if len(faces) == 0:
            raise SerenityError(f"scene {getattr(scene, 'name', '?')!r} has no triangles to ray trace")
        with _build_lock(cache is True or (cache is None and len(faces) >= CACHE_MIN_TRIANGLES)):
            self.tree = KdTree.build(pos, faces, config=tree_config, cache=cache, progress=progress)
        used = pos[used_vertices(faces, len(pos))]
        lo, hi = used.min(axis=0), used.max(axis=0)
        del used
        #: (2, 3) float32 the bounding box of the triangles' vertices (lower, upper corner), m
        self.bounds = np.stack([lo, hi])
        diag = float(np.linalg.norm(hi.astype(np.float64) - lo))
        self.ray_epsilon = float(ray_epsilon) if ray_epsilon is not None else RAY_EPSILON_REL * max(diag, 1e-6)

        mats = scene.materials
        cut = np.array([m.alpha_tested for m in mats], bool)
        if cut.any():  # the tree's own queries (probe visibility, sun rays) run the same alpha test
            self.tree.set_alpha_test(cut[fmat], _coverage_test(scene.materials, fmat, faces, uv))
        self._scene = scene
        self._data: SceneData | None = None
        self._upload_lock = threading.Lock()

    @property
    def data(self) -> SceneData:
        """The scene on the device (geometry, materials, every texture's mips), uploaded on first use:
        a tracer that answers only its tree's own queries (``tree.occluded``: the probes' shadow rays
        where the traced probes come from the disk cache) never needs it."""
        if self._data is None:
            with self._upload_lock:
                if self._data is None:
                    self._data = self._upload(self._scene)
        return self._data

    def _upload(self, scene) -> SceneData:
        wp_ = init_warp()
        _, nrm, uv, faces, fmat = scene.merged()
        textures, tex_index, mat_tex, mat_ntex = [], {}, [], []

        def texture_index(t) -> int:
            if t is None:
                return -1
            if id(t) not in tex_index:
                tex_index[id(t)] = len(textures)
                textures.append(t)
            return tex_index[id(t)]

        for m in scene.materials:
            mat_tex.append(texture_index(m.albedo_texture))
            mat_ntex.append(texture_index(m.normal_texture))
        normal_maps = {id(m.normal_texture) for m in scene.materials if m.normal_texture is not None}
        first, nlev, offs, sizes, level_srgb, texels = pack_mip_chains(
            textures, [id(t) not in normal_maps for t in textures], self.device)
        mats = scene.materials
        dev = self.device
        s = SceneData()
        s.tree = self.tree.device_data(dev)
        s.normals = wp_.array(nrm, dtype=wp.vec3, device=dev)
        s.uvs = wp_.array(uv, dtype=wp.vec2, device=dev)
        s.faces = wp_.array(faces, dtype=wp.vec3i, device=dev)
        s.face_material = wp_.array(fmat, dtype=wp.int32, device=dev)
        s.mat_albedo = wp_.array(np.array([m.albedo for m in mats], np.float32), dtype=wp.vec3, device=dev)
        s.mat_specular = wp_.array(np.array([m.specular for m in mats], np.float32), dtype=float, device=dev)
        s.mat_params = wp_.array(np.array([[m.shininess, m.reflectivity, m.transparency, m.ior] for m in mats],
                                          np.float32), dtype=wp.vec4, device=dev)
        s.mat_texture = wp_.array(np.array(mat_tex, np.int32), dtype=wp.int32, device=dev)
        s.tex_first_level = wp_.array(first, dtype=wp.int32, device=dev)
        s.tex_levels = wp_.array(nlev, dtype=wp.int32, device=dev)
        s.level_offset = wp_.array(offs, dtype=wp.int32, device=dev)
        s.level_size = wp_.array(sizes, dtype=wp.vec2i, device=dev)
        s.texels = texels
        s.level_srgb = wp_.array(level_srgb, dtype=wp.int32, device=dev)
        s.lut8 = wp_.array(lut8(), dtype=float, device=dev)
        s.mat_alpha = wp_.array(np.array([[m.alpha, m.alpha_cutoff if m.alpha_tested else -1.0] for m in mats],
                                         np.float32), dtype=wp.vec2, device=dev)
        s.mat_uv = wp_.array(np.concatenate([np.concatenate([m.albedo_uv_transform, m.normal_uv_transform])
                                             for m in mats]).astype(np.float32), dtype=wp.vec3, device=dev)
        s.mat_normal_tex = wp_.array(np.array(mat_ntex, np.int32), dtype=wp.int32, device=dev)
        s.mat_normal = wp_.array(np.array([(normal_map_frame(m.normal_uv_transform) * m.normal_scale).reshape(4)
                                           for m in mats], np.float32), dtype=wp.vec4, device=dev)
        tangents = scene.merged_tangents() if scene.has_normal_maps else np.zeros((1, 4), np.float32)
        s.tangents = wp_.array(tangents, dtype=wp.vec4, device=dev)
        s.cutouts = int(any(m.alpha_tested for m in mats))
        self.textures = textures
        return s

    def trace(self, origins, directions, cone_width=0.0, cone_spread=0.0, *, tmin: float | None = None,
              tmax: float = np.inf, threads: int | None = None, transmissions: int = 0,
              sort: bool | None = None, sun_direction=None, backfaces: bool = False) -> dict[str, np.ndarray]:
        """Trace N rays; returns the G-buffer as a dict of (N,4) float32 arrays (``RT_GBUFFER_KEYS``).

        ``tmin`` (m) defaults to ``ray_epsilon`` (hits closer than that are ignored: rays start on
        the reflecting surface). ``transmissions``: how many transparent interfaces a ray is bent
        through (module doc) before the hit it reports; 0 = the first hit, as the paper does.
        ``sort``: ray reordering (:func:`serenity.kernels.kdtree.ray_order`; None = big incoherent
        batches only); the results are the same either way, in the caller's order.
        ``sun_direction``: (3,) towards the sun; when given, ``eye[:, 3]`` is the sun's visibility at
        each hit (one shadow ray; module doc). ``backfaces``: also ``"backface"``, (N,) bool, True
        where the ray hit a triangle from behind its geometric normal (wound v0, v1, v2)."""
        dev = self.device
        o = np.ascontiguousarray(np.asarray(origins, np.float32).reshape(-1, 3))
        d = np.ascontiguousarray(np.asarray(directions, np.float32).reshape(-1, 3))
        n = len(o)
        if len(d) != n:
            raise SerenityError(f"{n} ray origins but {len(d)} directions")
        cw = np.ascontiguousarray(np.broadcast_to(np.asarray(cone_width, np.float32), (n,)))
        cs = np.ascontiguousarray(np.broadcast_to(np.asarray(cone_spread, np.float32), (n,)))
        outs = [wp.empty(n, dtype=wp.vec4, device=dev) for _ in RT_GBUFFER_KEYS]
        back = wp.empty(n if backfaces else 0, dtype=wp.int32, device=dev)
        sun = np.zeros(3, np.float32)
        if sun_direction is not None:
            sun = np.asarray(sun_direction, np.float64).reshape(-1)
            norm = float(np.linalg.norm(sun)) if sun.shape == (3,) else 0.0
            if not (np.isfinite(norm) and norm > 0.0):
                raise SerenityError(f"sun_direction must be a finite non-zero 3-vector, got {sun_direction!r}")
            sun = (sun / norm).astype(np.float32)
        if n:
            rays = [wp.array(o, dtype=wp.vec3, device=dev), wp.array(d, dtype=wp.vec3, device=dev),
                    wp.array(cw, dtype=float, device=dev), wp.array(cs, dtype=float, device=dev)]
            tree = self.data.tree
            buffers = self.tree.workspace(dev)  # the tree's grow-only buffers for this thread
            order = ray_order(tree.box_lo, tree.box_hi, rays[0], rays[1], n, sort, dev, threads, buffers)
            reordered = order.shape[0] > 0
            if reordered:
                rays = gather_in_order(order, rays, dev, threads, buffers)
            # a reordered batch is traced into working arrays in its order, then scattered back
            traced = buffers_like([*outs, back], "traced", dev, buffers) if reordered else [*outs, back]
            args = [self.data, *rays, float(self.ray_epsilon if tmin is None else tmin), float(tmax),
                    int(max(0, transmissions)), wp.vec3(*(float(x) for x in sun)),
                    int(sun_direction is not None), *traced]
            launch(trace_gbuffer, n, args, device=dev, threads=threads, balanced=True)
            if reordered:
                scatter_in_order(order, traced, [*outs, back], dev, threads)
        out = {k: a.numpy().reshape(n, 4) for k, a in zip(RT_GBUFFER_KEYS, outs, strict=True)}
        if backfaces:
            out["backface"] = back.numpy().astype(bool)
        return out

    def trace_casting_buffer(self, buffer, threads: int | None = None, transmissions: int = 0,
                             sun_direction=None) -> dict[str, dict[str, np.ndarray]]:
        """Both G-buffers of a ray-casting buffer (``raster.raycast.RayCastingBuffer`` or anything
        with its fields): ``{"reflection": {...}, "refraction": {...}}``, each (N,4) per key in the
        buffer's ray order. Rays whose flag is not set (refraction without TRACE_REFRACTION) come
        back as "not traced" (all zeros). ``transmissions`` applies to the refraction rays;
        ``sun_direction`` to both (:meth:`trace`)."""
        flags = np.asarray(buffer.flags)
        refl = np.where((flags & 1)[:, None] > 0, buffer.reflect_dirs, 0.0)
        refr = np.where((flags & 2)[:, None] > 0, buffer.refract_dirs, 0.0)
        return {
            "reflection": self.trace(buffer.origins, refl, buffer.cone_width, buffer.cone_spread, threads=threads,
                                     sun_direction=sun_direction),
            "refraction": self.trace(buffer.origins, refr, buffer.cone_width, buffer.cone_spread, threads=threads,
                                     transmissions=transmissions, sun_direction=sun_direction),
        }
