"""Ray-traced G-buffers: texel-exact texture lookups and the ray-cone mip level against a numpy
reference, misses and untraced rays, and the whole G-buffer against the rasterised one for rays
equal to the camera's primary rays."""

import math

import numpy as np
import pytest
import trimesh

from serenity.colour import linear_to_srgb, srgb_to_linear
from serenity.errors import SerenityError
from serenity.gbuffer_layout import GBUFFER_TARGETS, RT_GBUFFER_KEYS
from serenity.kernels.raytrace import RayTracer
from serenity.scene.model import Camera, Material, Mesh, Scene, Sky, Sun, Texture
from serenity.scene.texture import texture_from_array


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


SIZE = 4.0  # the textured plane spans x in [0, SIZE], z in [-SIZE, 0], y = 0; uv = (x, -z) / SIZE


def stored_8bit(mip, srgb=True):
    """A linear level as the tracer stores it: each channel rounded to 8 bits, rgb sRGB-encoded (IEC
    61966-2-1) unless ``srgb`` is False, then decoded back to float32 (a numpy twin)."""
    a = np.clip(np.asarray(mip, np.float64), 0.0, 1.0)

    def to8(x):  # halves round up
        return np.floor(x * 255.0 + 0.5) / 255.0

    rgb = srgb_to_linear(to8(linear_to_srgb(a[..., :3]))) if srgb else to8(a[..., :3])
    return np.concatenate([rgb, to8(a[..., 3:])], axis=-1).astype(np.float32)


def textured_plane_scene(img, repeat=1.0):
    """The plane with ``img`` as its albedo texture, and that texture as the tracer stores it (``stored_8bit``)."""
    tex = texture_from_array(img)
    p = np.array([[0, 0, 0], [SIZE, 0, 0], [SIZE, 0, -SIZE], [0, 0, -SIZE]], np.float32)
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32) * repeat
    mesh = Mesh("plane", p, None, uv, np.array([[0, 1, 2], [0, 2, 3]]), np.zeros(2))
    mat = Material("tex", albedo=(1.0, 0.5, 1.0), albedo_texture=tex, specular=0.25, shininess=16.0)
    stored = Texture(name=tex.name, mips=[stored_8bit(m) for m in tex.mips])
    return Scene("plane", [mesh], [mat], Camera((2, 5, 2), (2, 0, -2)), Sun((0.3, 1, 0.2))), stored


def bilinear_ref(img, u, v):
    """GL_LINEAR + GL_REPEAT on an image stored top row first, v up."""
    h, w = img.shape[:2]
    x = (u - math.floor(u)) * w - 0.5
    y = (1 - (v - math.floor(v))) * h - 0.5
    x0, y0 = math.floor(x), math.floor(y)
    tx, ty = x - x0, y - y0
    c = [[img[(y0 + j) % h, (x0 + i) % w].astype(np.float64) for i in (0, 1)] for j in (0, 1)]
    return (c[0][0] * (1 - tx) + c[0][1] * tx) * (1 - ty) + (c[1][0] * (1 - tx) + c[1][1] * tx) * ty


def trilinear_ref(tex, u, v, lod):
    lam = min(max(lod, 0.0), len(tex.mips) - 1)
    l0 = int(math.floor(lam))
    f = lam - l0
    c = bilinear_ref(tex.mips[l0], u, v)
    if f > 0 and l0 + 1 < len(tex.mips):
        c = c * (1 - f) + bilinear_ref(tex.mips[l0 + 1], u, v) * f
    return c


def down_ray_at(u, v, height=1.0):
    """A ray straight down onto the plane at texture coordinate (u, v)."""
    return np.array([[SIZE * u, height, -SIZE * v]], np.float32), np.array([[0.0, -1.0, 0.0]], np.float32)


def test_texel_centres_give_the_texel(device):
    """An 8-bit image's texels come back exactly as the scene decodes them (the tracer stores 8-bit
    sRGB); a float image's within the 8-bit step of its sRGB encoding."""
    img8 = np.random.default_rng(0).integers(0, 256, (16, 16, 3), dtype=np.uint8)
    img = np.random.default_rng(0).uniform(0, 1, (16, 16, 3)).astype(np.float32)
    for image, exact in ((texture_from_array(img8, srgb=True).mips[0], True), (img, False)):
        scene, tex = textured_plane_scene(image)
        rt = RayTracer(scene, device=device)
        for r, c in [(0, 0), (3, 5), (15, 15), (8, 1)]:
            o, d = down_ray_at((c + 0.5) / 16, 1 - (r + 0.5) / 16)
            g = rt.trace(o, d, 0.0, 0.0)
            expected = (image if exact else tex.mips[0])[r, c]
            assert np.array_equal(tex.mips[0][r, c], image[r, c]) == exact or not exact
            assert np.allclose(g["albedo"][0, :3], expected * [1.0, 0.5, 1.0], rtol=0, atol=1e-6), (r, c)
            # half an 8-bit sRGB step: at most 0.0045 in linear
            assert np.allclose(g["albedo"][0, :3], image[r, c] * [1.0, 0.5, 1.0], atol=0.0045), (r, c)


def test_textures_stored_as_8bit_srgb_with_mips():
    """The packed texels: an 8-bit image's level 0 exactly (sRGB for albedo maps, linear for normal
    maps), every level within half an 8-bit step, a quarter of float32 RGBA's bytes."""
    from serenity.kernels.raytrace import lut8, pack_mip_chains

    rng = np.random.default_rng(5)
    albedo = texture_from_array(rng.integers(0, 256, (37, 20, 4), dtype=np.uint8), srgb=True)
    normal = texture_from_array(rng.integers(0, 256, (8, 8, 3), dtype=np.uint8), srgb=False)
    first, levels, offs, sizes, srgb, texels = pack_mip_chains([albedo, normal], [True, False])
    q = texels.numpy()
    assert q.dtype == np.uint32 and q.nbytes * 4 == sum(m[..., :1].size * 16 for t in (albedo, normal) for m in t.mips)
    table = lut8()
    for t, enc in ((albedo, True), (normal, False)):
        for k, mip in enumerate(t.mips):
            level = first[[albedo, normal].index(t)] + k
            w, h = sizes[level]
            assert srgb[level] == int(enc) and (h, w) == mip.shape[:2]
            p = q[offs[level]:offs[level] + w * h]
            base = 0 if enc else 256
            got = np.stack([table[base + (p >> s & 255)] for s in (0, 8, 16)] + [table[256 + (p >> 24)]], axis=1)
            want = mip.reshape(w * h, -1)
            want = np.concatenate([want, np.ones((w * h, 4 - want.shape[1]), np.float32)], axis=1)
            if k == 0:
                assert np.array_equal(got, want)
            # the twin's rounding, but for values at a half step (a box filter of 8-bit values makes
            # such ties; float32 and float64 round them apart): one step at most
            diff = np.abs(got - stored_8bit(want, enc))
            steps = np.asarray(want, np.float64) * 255.0
            if enc:
                steps[:, :3] = linear_to_srgb(want[:, :3]) * 255.0
            tie = np.abs(steps - np.floor(steps) - 0.5) < 1e-3
            assert diff[~tie].max(initial=0.0) <= 1e-6 and diff.max() <= 0.0045 + 1e-6


@pytest.mark.parametrize("level", [1, 2, 3])
def test_cone_width_selects_the_mip_level(device, level):
    # level-0 texels are SIZE/16 m wide: a cone of 2^level texels lands exactly on that level
    img = np.random.default_rng(1).uniform(0, 1, (16, 16, 3)).astype(np.float32)
    scene, tex = textured_plane_scene(img)
    rt = RayTracer(scene, device=device)
    n = 16 >> level
    texel = SIZE / 16
    for r, c in [(0, 0), (n - 1, n // 2)]:
        o, d = down_ray_at((c + 0.5) / n, 1 - (r + 0.5) / n, height=2.0)
        expected = tex.mips[level][r, c] * [1.0, 0.5, 1.0]
        by_width = rt.trace(o, d, cone_width=texel * 2**level, cone_spread=0.0)
        by_spread = rt.trace(o, d, cone_width=0.0, cone_spread=texel * 2**level / 2.0)  # hit at t = 2 m
        assert np.allclose(by_width["albedo"][0, :3], expected, atol=1e-5)
        assert np.allclose(by_spread["albedo"][0, :3], expected, atol=1e-5)


def test_trilinear_filtering_matches_reference(device):
    rng = np.random.default_rng(2)
    img = rng.uniform(0, 1, (32, 16, 3)).astype(np.float32)  # non-square, so level sizes differ per axis
    scene, tex = textured_plane_scene(img, repeat=3.0)  # uv in [0, 3]: repeat wrap
    rt = RayTracer(scene, device=device)
    n = 300
    uv = rng.uniform(0, 1, (n, 2))
    o = np.stack([SIZE * uv[:, 0], np.full(n, 1.5), -SIZE * uv[:, 1]], 1).astype(np.float32)
    d = np.tile(np.float32([0, -1, 0]), (n, 1))
    width = rng.uniform(0, 2.0, n).astype(np.float32)
    g = rt.trace(o, d, width, 0.0)
    # texel area / world area of level 0: (32*16 texels * 9 repeats) over SIZE^2 m^2
    density = math.sqrt(32 * 16 * 9 / SIZE**2)
    for i in range(n):
        lod = math.log2(width[i] * density) if width[i] > 0 else -1.0
        ref = trilinear_ref(tex, 3 * uv[i, 0], 3 * uv[i, 1], lod) * [1.0, 0.5, 1.0]
        assert np.allclose(g["albedo"][i, :3], ref, atol=2e-5), i


def test_grazing_hits_use_coarser_mips(device):
    img = np.random.default_rng(3).uniform(0, 1, (64, 64, 3)).astype(np.float32)
    scene, tex = textured_plane_scene(img)
    rt = RayTracer(scene, device=device)
    target = np.array([SIZE * 0.3, 0.0, -SIZE * 0.6])
    texel = SIZE / 64
    for cos_theta in (1.0, 0.5, 0.25):
        d = np.array([math.sqrt(1 - cos_theta**2), -cos_theta, 0.0])
        o = (target - 2.0 * d).astype(np.float32)[None]
        g = rt.trace(o, d.astype(np.float32)[None], cone_width=texel, cone_spread=0.0)
        lod = math.log2(1.0 / cos_theta)  # the footprint stretches by 1/cos along the plane
        ref = trilinear_ref(tex, 0.3, 0.6, lod) * [1.0, 0.5, 1.0]
        assert np.allclose(g["albedo"][0, :3], ref, atol=1e-4), cos_theta
        assert g["ray_dir"][0, 3] == pytest.approx(2.0, rel=1e-5)


def test_hit_attributes_misses_and_untraced_rays(device):
    img = np.full((4, 4, 3), 0.5, np.float32)
    scene, stored = textured_plane_scene(img)
    grey = float(stored.mips[0][0, 0, 0])  # 0.5 as 8-bit sRGB stores it
    rt = RayTracer(scene, device=device)
    o = np.array([[1.0, 1.0, -1.0], [1.0, -1.0, -1.0], [1.0, 1.0, -1.0], [1.0, 1.0, -1.0], [9.0, 1.0, 0.0]],
                 np.float32)
    d = np.array([[0, -2, 0], [0, 1, 0], [0, 0, 0], [np.nan, 0, 0], [1, -1, 0]], np.float32)
    g = rt.trace(o, d, 0.0, 0.0)
    assert set(g) == set(RT_GBUFFER_KEYS) and all(a.shape == (5, 4) and a.dtype == np.float32 for a in g.values())
    # 0: a hit from above
    assert np.allclose(g["position"][0], [1, 0, -1, 1], atol=1e-6)
    assert np.allclose(g["normal"][0], [0, 1, 0, 0.25], atol=1e-6)
    assert np.allclose(g["albedo"][0], [grey, grey / 2, grey, 0.0], atol=1e-6) and abs(grey - 0.5) < 0.004
    assert np.allclose(g["material"][0], [16.0, 0.0, 0.0, 1.5])
    assert np.allclose(g["ray_dir"][0], [0, -1, 0, 1.0], atol=1e-6)  # unit direction, distance in m
    # 4: a miss: the sky direction, nothing else
    assert np.allclose(g["ray_dir"][4, :3], [math.sqrt(0.5), -math.sqrt(0.5), 0], atol=1e-6)
    for k in GBUFFER_TARGETS:
        assert np.all(g[k][4] == 0)
    # 1: from below, the normal faces the ray (two-sided, like the raster G-buffer)
    assert np.allclose(g["normal"][1, :3], [0, -1, 0], atol=1e-6) and g["position"][1, 3] == 1
    # 2, 3: zero and NaN directions are "not traced": all zeros
    for k in RT_GBUFFER_KEYS:
        assert np.all(g[k][2:4] == 0)
    # backfaces=True: the same G-buffer, and which hits met the plane from behind (only ray 1)
    gb = rt.trace(o, d, 0.0, 0.0, backfaces=True)
    assert all(np.array_equal(gb[k], g[k]) for k in RT_GBUFFER_KEYS)
    assert gb["backface"].tolist() == [False, True, False, False, False]


def test_tmin_skips_the_starting_surface(device):
    scene, _ = textured_plane_scene(np.full((2, 2, 3), 0.5, np.float32))
    rt = RayTracer(scene, device=device)
    o = np.array([[1.0, 0.0, -1.0]], np.float32)  # on the plane
    assert rt.trace(o, [[0, -1, 0]])["position"][0, 3] == 0
    assert rt.trace(o, [[0, -1, 0]], tmin=0.0)["position"][0, 3] == 0  # t = 0 is never a hit
    assert rt.trace(o + [[0, 1e-5, 0]], [[0, -1, 0]], tmin=0.0)["position"][0, 3] == 1


def _mixed_scene():
    """A textured ground, a reflective box and a smooth glass sphere."""
    rng = np.random.default_rng(4)
    yy, xx = np.mgrid[0:64, 0:64] / 64.0
    img = np.stack([0.5 + 0.4 * np.sin(2 * np.pi * xx), 0.5 + 0.4 * np.cos(2 * np.pi * yy),
                    np.full_like(xx, 0.3)], -1).astype(np.float32)  # smooth: filtering barely matters
    ground_p = np.array([[-6, 0, 6], [6, 0, 6], [6, 0, -6], [-6, 0, -6]], np.float32)
    ground = Mesh("ground", ground_p, None, np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32),
                  np.array([[0, 1, 2], [0, 2, 3]]), np.zeros(2))
    b = trimesh.creation.box((1.5, 1.5, 1.5))
    b.apply_translation((-1.2, 0.75, -0.5))
    bv = b.vertices[b.faces].reshape(-1, 3)
    box = Mesh("box", bv, np.repeat(b.face_normals, 3, axis=0), None, np.arange(len(bv)).reshape(-1, 3),
               np.ones(len(b.faces)))
    s = trimesh.creation.icosphere(subdivisions=3, radius=0.8)
    s.apply_translation((1.3, 0.8 + 0.01 * rng.uniform(), 0.4))
    sphere = Mesh("sphere", s.vertices, s.vertex_normals, None, s.faces, np.full(len(s.faces), 2))
    mats = [Material("ground", albedo=(0.9, 0.9, 0.9), albedo_texture=texture_from_array(img)),
            Material("mirror", albedo=(0.25, 0.5, 0.75), reflectivity=0.5, specular=0.5, shininess=64.0),
            Material("glass", albedo=(0.75, 0.75, 0.75), transparency=0.75, ior=1.5, specular=0.25)]
    cam = Camera((0.5, 3.0, 6.0), (0.0, 0.5, 0.0), fov_y_deg=50.0)
    return Scene("mixed", [ground, box, sphere], mats, cam, Sun((0.3, 1.0, 0.4)), Sky(model="constant"))


def test_reordered_rays_give_the_same_gbuffer():
    """Ray reordering (``sort=True``) traces in another order and writes each ray's G-buffer entry at
    its own index: the same bits as without, for random rays with random cones, zero (untraced)
    directions among them and transmissions through the glass sphere, on one thread and on two."""
    tracer = RayTracer(_mixed_scene(), device="cpu")
    rng = np.random.default_rng(9)
    n = 5000
    o = rng.uniform((-4, 0.1, -4), (4, 3, 4), (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3)).astype(np.float32)
    d[::97] = 0.0
    cw = rng.uniform(0.0, 0.01, n).astype(np.float32)
    cs = rng.uniform(0.0, 0.01, n).astype(np.float32)
    ref = tracer.trace(o, d, cw, cs, transmissions=2, threads=1, sort=False)
    assert np.mean(ref["position"][:, 3] > 0) > 0.3
    for threads in (1, 2):
        got = tracer.trace(o, d, cw, cs, transmissions=2, threads=threads, sort=True)
        for k in RT_GBUFFER_KEYS:
            assert np.array_equal(got[k], ref[k]), (k, threads)


def test_empty_scene_raises():
    scene = _mixed_scene()

    class Empty:
        name = "empty"

        def merged(self):
            return (np.zeros((0, 3), np.float32),) * 2 + (np.zeros((0, 2), np.float32),
                                                           np.zeros((0, 3), np.int32), np.zeros(0, np.int32))

    with pytest.raises(SerenityError):
        RayTracer(Empty(), device="cpu")
    assert RayTracer(scene, device="cpu").tree.stats.valid_triangles == scene.triangle_count


def test_casting_buffer_rays_follow_their_flags():
    scene = _mixed_scene()
    rt = RayTracer(scene, device="cpu")

    class Buffer:
        origins = np.array([[0.0, 0.5, 3.0]] * 3, np.float32)
        reflect_dirs = np.array([[0.0, 0.0, -1.0]] * 3, np.float32)
        refract_dirs = np.array([[0.0, -1.0, 0.0]] * 3, np.float32)
        cone_width = np.zeros(3, np.float32)
        cone_spread = np.full(3, 1e-3, np.float32)
        flags = np.array([1, 3, 1 | 4], np.int32)

    out = rt.trace_casting_buffer(Buffer())
    assert np.all(out["reflection"]["ray_dir"][:, 2] == -1)
    assert out["refraction"]["position"][1, 3] == 1 and abs(out["refraction"]["position"][1, 1]) < 1e-6
    assert np.all(out["refraction"]["ray_dir"][[0, 2]] == 0)  # not traced


@pytest.mark.gl
def test_gbuffer_matches_raster_gbuffer_for_primary_rays(device):
    try:
        from serenity.raster.context import check_gl_error, get_context
        from serenity.raster.gbuffer import GBufferPass
        from serenity.raster.interop import read_texture
        from serenity.raster.scene_gl import SceneGL

        ctx = get_context()
    except (SerenityError, ImportError) as e:
        pytest.skip(f"no headless GL: {e}")
    scene = _mixed_scene()
    w, h = 160, 96
    cam = scene.camera
    scene_gl = SceneGL(ctx, scene)
    gpass = GBufferPass(ctx, scene_gl)
    gpass.resize(w, h)
    gb = gpass.render(cam.projection_matrix(w / h) @ cam.view_matrix(), cam.position)
    ref = {k: read_texture(getattr(gb, k), 4).reshape(-1, 4) for k in GBUFFER_TARGETS}
    check_gl_error(ctx, "gbuffer")

    o, d = cam.primary_rays(w, h)
    spread = math.atan(2 * math.tan(math.radians(cam.fov_y_deg) / 2) / h)
    got = RayTracer(scene, device=device).trace(o, d, 0.0, spread)

    cov_gl = ref["position"][:, 3] > 0
    cov_rt = got["position"][:, 3] > 0
    assert cov_gl.mean() > 0.5
    assert np.mean(cov_gl == cov_rt) > 0.995
    # compare away from silhouettes and material boundaries (a pixel and its 8 neighbours agree)
    mat = np.where(cov_gl, ref["albedo"][:, 3], -1).reshape(h, w)
    pad = np.pad(mat, 1, mode="edge")
    interior = np.ones((h, w), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            interior &= pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] == mat
    sel = (interior.reshape(-1) & cov_gl & cov_rt)
    assert sel.mean() > 0.4
    dist = np.linalg.norm(got["position"][sel, :3] - o[sel], axis=1)
    assert np.all(np.abs(got["position"][sel, :3] - ref["position"][sel, :3]).max(axis=1) < 1e-3 * dist + 1e-4)
    assert np.allclose(got["normal"][sel], ref["normal"][sel], atol=2e-3)
    assert np.array_equal(got["material"][sel], ref["material"][sel])
    assert np.array_equal(got["albedo"][sel, 3], ref["albedo"][sel, 3])
    untextured = sel & (ref["albedo"][:, 3] > 0)
    textured = sel & (ref["albedo"][:, 3] == 0)
    assert untextured.any() and textured.any()
    assert np.allclose(got["albedo"][untextured, :3], ref["albedo"][untextured, :3], atol=1e-3)
    # GL picks the mip from screen derivatives (with anisotropic filtering); the tracer from the cone
    err = np.abs(got["albedo"][textured, :3] - ref["albedo"][textured, :3])
    assert err.mean() < 0.01 and err.max() < 0.05


def test_cpu_and_cuda_gbuffers_are_identical(cuda_devices):
    if not cuda_devices:
        pytest.skip("no CUDA device")
    scene = _mixed_scene()
    o, d = scene.camera.primary_rays(64, 40)
    ref = RayTracer(scene, device="cpu").trace(o, d, 0.0, 1e-3)
    for dev in cuda_devices:
        got = RayTracer(scene, device=dev).trace(o, d, 0.0, 1e-3)
        for k in RT_GBUFFER_KEYS:
            assert np.allclose(got[k], ref[k], atol=1e-6), k


def _glass_slab_and_wall():
    """A glass slab 6×2×0.2 m (x in [−3, 3], z in [−0.1, 0.1], ior 1.5, outward normals, one normal
    per face) and a diffuse wall at z = 2 facing it."""
    box = trimesh.creation.box(extents=(6.0, 2.0, 0.2))
    box.unmerge_vertices()
    nrm = np.repeat(box.face_normals, 3, axis=0).astype(np.float32)
    slab = Mesh("slab", box.vertices.astype(np.float32), nrm, np.zeros((len(box.vertices), 2), np.float32),
                box.faces.astype(np.int32), np.zeros(len(box.faces), np.int32))
    wp_ = np.array([[-5, -5, 2], [5, -5, 2], [5, 5, 2], [-5, 5, 2]], np.float32)
    wall = Mesh("wall", wp_, np.tile([0, 0, -1.0], (4, 1)).astype(np.float32), np.zeros((4, 2), np.float32),
                np.array([[0, 2, 1], [0, 3, 2]], np.int32), np.ones(2, np.int32))
    mats = [Material("glass", albedo=(0.9, 0.9, 0.9), transparency=0.9, ior=1.5), Material("wall", albedo=(0.5,) * 3)]
    return Scene("slab", [slab, wall], mats, Camera((0, 0, -3), (0, 0, 0)), Sun((0.3, 1, 0.2)))


def test_refraction_rays_pass_through_a_glass_solid(device):
    """A ray refracted into the slab at 30° incidence: with transmissions it leaves through the back
    face parallel to where it came from (Snell twice) and hits the wall, shifted sideways by the slab;
    without (the paper's single refraction) it stops on the slab's own back face."""
    tracer = RayTracer(_glass_slab_and_wall(), device=device)
    s_in = math.sin(math.radians(30.0))
    d0 = np.array([s_in, 0.0, math.cos(math.radians(30.0))])
    st = s_in / 1.5
    d1 = np.array([[st, 0.0, math.sqrt(1 - st * st)]], np.float32)  # inside the glass
    o = np.array([[0.0, 0.0, -0.1]], np.float32)
    first = tracer.trace(o, d1)
    assert first["position"][0, 2] == pytest.approx(0.1, abs=1e-5) and first["material"][0, 2] == pytest.approx(0.9)
    through = tracer.trace(o, d1, transmissions=2)
    x_exit = 0.2 * st / math.sqrt(1 - st * st)
    x_wall = x_exit + 1.9 * math.tan(math.radians(30.0))
    np.testing.assert_allclose(through["position"][0, :3], [x_wall, 0.0, 2.0], atol=1e-4)
    np.testing.assert_allclose(through["ray_dir"][0, :3], d0, atol=1e-5)
    np.testing.assert_allclose(through["eye"][0, :3], [x_exit, 0.0, 0.1], atol=1e-4)
    assert through["material"][0, 2] == 0.0  # the wall
    assert through["ray_dir"][0, 3] == pytest.approx(0.2 / math.sqrt(1 - st * st) + 1.9 / d0[2], rel=1e-4)


def test_total_internal_reflection_inside_the_glass(device):
    """Beyond the critical angle (41.8° for ior 1.5) the ray is mirrored at the back face and, with
    one transmission, reports the front face it then reaches from inside."""
    tracer = RayTracer(_glass_slab_and_wall(), device=device)
    d = np.array([[0.9, 0.0, 0.2]], np.float32)  # 77° from the face normal
    g = tracer.trace(np.array([[0.0, 0.0, -0.1]], np.float32), d, transmissions=1)
    assert g["ray_dir"][0, 2] < 0.0
    assert g["position"][0, 2] == pytest.approx(-0.1, abs=1e-5)
    assert g["position"][0, 0] == pytest.approx(2 * 0.9, abs=1e-4)


def test_sun_shadow_rays_see_the_glass(device):
    """With a sun direction, ``eye.w`` is the sun's visibility at each hit: the wall behind the glass
    slab is in its shadow (glass blocks the sun, as in the shadow maps and the reference), the wall
    beside it is lit; without one, and on a miss, it is 0. A bad direction is a SerenityError."""
    tracer = RayTracer(_glass_slab_and_wall(), device=device)
    o = np.array([[0.0, 0.0, 1.5], [4.0, 0.0, 1.5], [0.0, 0.0, 1.5]], np.float32)
    d = np.array([[0, 0, 1], [0, 0, 1], [0, 1, 0]], np.float32)  # wall behind, wall beside, miss
    sun = np.array([0.0, 0.1, -1.0])
    g = tracer.trace(o, d, sun_direction=sun)
    assert g["position"][:2, 3].tolist() == [1.0, 1.0] and g["position"][2, 3] == 0.0
    assert g["eye"][:, 3].tolist() == [0.0, 1.0, 0.0]
    np.testing.assert_array_equal(g["eye"][:, :3], o)
    assert tracer.trace(o, d)["eye"][:, 3].tolist() == [0.0, 0.0, 0.0]
    # the sun passing beside the slab's top edge lights the wall behind it
    assert tracer.trace(o[:1], d[:1], sun_direction=(0.0, 1.0, -1.0))["eye"][0, 3] == 1.0
    with pytest.raises(SerenityError, match="sun_direction"):
        tracer.trace(o, d, sun_direction=(0.0, 0.0, 0.0))
