"""The Mitsuba 3 reference: units, cameras, sky, components and caching.

The agreement checks (docs/architecture.md, Accuracy; issue #3): our direct-only render and Mitsuba's direct-only
render (depth 2, black sky) of a diffuse plane under the sun and of the courtyard match within 2% in
the mean over lit pixels, and their silhouettes (depth discontinuities) align with IoU >= 0.99.
"""

import math

import numpy as np
import pytest
from scipy import ndimage

from serenity.errors import SerenityError
from serenity.eval import reference as R
from serenity.eval.metrics import depth_edges, edge_iou
from serenity.scene.model import Material, Scene, Sky, Sun, direction_from_angles
from serenity.scene.texture import texture_from_array

pytest.importorskip("mitsuba")

W, H, SPP = 96, 54, 32
LUMA = np.array([0.2126, 0.7152, 0.0722])


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


def plane(albedo=0.5, elevation=60.0, irradiance=1000.0, sky=(0.0, 0.0, 0.0), with_box=False, texture=None):
    from tests.raster.scenes import plane_scene

    s = plane_scene(albedo=albedo, zenith_deg=90.0 - elevation, irradiance=irradiance, with_box=with_box)
    s.sky = Sky(radiance=sky, model="constant")
    if texture is not None:
        s.materials[0] = Material("plane", albedo=(1.0, 1.0, 1.0), albedo_texture=texture)
    return s


def asymmetric_texture():
    """A texture that tells u from v and top from bottom: a gradient in u, dark top rows, a bright corner."""
    h, w = 64, 64
    img = np.zeros((h, w, 3), np.uint8)
    img[..., 0] = np.linspace(40, 230, w, dtype=np.uint8)[None, :]
    img[..., 1] = 150
    img[..., 2] = 90
    img[: h // 4] //= 3
    img[-16:, -16:] = 255
    return texture_from_array(img, name="asym", srgb=True)


# --------------------------------------------------------------------------------------- Mitsuba alone


def test_sun_irradiance_units_match_the_analytic_plane():
    """A diffuse plane of albedo ρ under the sun at elevation e reflects ρ/π · E · sin e."""
    for elevation, albedo in ((60.0, 0.5), (20.0, 0.8)):
        img = R.render_reference(plane(albedo, elevation), 48, 27, spp=8, component="direct", progress=False)
        expect = albedo / math.pi * 1000.0 * math.sin(math.radians(elevation))
        covered = ndimage.binary_erosion(img[..., 1] > 0)  # not the plane's far edge
        assert covered.sum() > 0.6 * img[..., 1].size
        assert img[covered].mean() == pytest.approx(expect, rel=3e-3)


def test_sun_disc_has_the_scene_radiance_and_size():
    s = plane()
    mscene = R.load_mitsuba_scene(s, 8, 8, 2)
    sun = [sh for sh in mscene.shapes() if sh.id() == "sun"][0]
    centre, radius = R.sun_sphere(s)
    dist = np.linalg.norm(centre - s.bounds.mean(0))
    half = math.asin(radius / dist)
    assert math.degrees(2 * half) == pytest.approx(0.53, rel=1e-6)
    assert sun.emitter() is not None
    # the calibration factor is within float32 rounding of 1
    assert abs(R.calibrate_sun(mscene, s) - 1.0) < 6e-3


def test_constant_sky_gives_irradiance_pi_L():
    """Sun below the horizon, constant sky L: a diffuse plane reflects ρ·L (irradiance π·L)."""
    s = plane(albedo=0.6, sky=(10.0, 20.0, 40.0))
    s.sun = Sun(direction_from_angles(-10.0, 0.0))
    img = R.render_reference(s, 48, 27, spp=16, component="direct", progress=False)
    # rows below the plane's far edge (the plane is 40 m; the camera looks down at 40°)
    ground = img[14:].reshape(-1, 3)
    assert np.allclose(ground.mean(0), 0.6 * np.array([10.0, 20.0, 40.0]), rtol=0.02)


def test_sky_map_orientation_follows_the_compass():
    """Row 0 is the zenith and column u is the azimuth 2πu from north towards east, as in the scene model."""
    mi = R.mitsuba()
    hw, hh = 64, 32
    az = (np.arange(hw) + 0.5) / hw * 360.0
    sky = np.zeros((hh, hw, 3), np.float32)
    sky[..., 0] = az[None, :]  # red = azimuth in degrees
    sky[..., 1] = ((np.arange(hh) + 0.5) / hh * 180.0)[:, None]  # green = zenith angle in degrees
    s = plane()
    s.sky = Sky(radiance=(1.0, 1.0, 1.0), model="atmosphere")
    got_sun = []
    mscene = R.load_mitsuba_scene(s, 8, 8, 2, sky_envmap=lambda d: got_sun.append(d) or sky)
    assert np.allclose(got_sun[0], s.sun.direction)
    env = mscene.environment()
    for elevation, azimuth in ((30.0, 45.0), (10.0, 100.0), (60.0, 200.0), (-20.0, 300.0)):
        d = direction_from_angles(elevation, azimuth)
        si = mi.SurfaceInteraction3f()
        si.wi = mi.Vector3f(*(-d))
        v = np.array(env.eval(si))
        assert v[0] == pytest.approx(azimuth, abs=6.0)
        assert v[1] == pytest.approx(90.0 - elevation, abs=6.0)


def test_constant_placeholder_sky_is_black_below_the_horizon():
    sky = R.constant_sky_map((1.0, 2.0, 3.0), 16, 8)
    assert np.all(sky[:4] == np.array([1.0, 2.0, 3.0], np.float32)) and np.all(sky[4:] == 0)
    s = plane(sky=(0.0, 0.0, 0.0))
    assert R.sky_map(s) is None  # black: no env map at all


def test_camera_rays_go_through_our_pixel_centres():
    s = plane(with_box=True)
    dirs, depth, mat = R.cast_primary(s, W, H)
    _, ours = s.camera.primary_rays(W, H)
    cos = (dirs.reshape(-1, 3) * ours).sum(1)
    assert cos.min() > 1 - 1e-6
    assert set(np.unique(mat)) == {-1, 0, 1}


def test_components_and_cache(tmp_path):
    from serenity.scene import load

    s = load("cornell")
    info = {}
    direct = R.render_reference(s, 24, 24, spp=4, component="direct", progress=False, info=info)
    assert not info["cached"] and len(info["cache_paths"]) == 1
    one = R.render_reference(s, 24, 24, spp=4, component="one-bounce", progress=False)
    full = R.render_reference(s, 24, 24, spp=4, component="full", progress=False)
    indirect = R.render_reference(s, 24, 24, spp=4, component="indirect", progress=False)
    assert direct.shape == (24, 24, 3) and direct.dtype == np.float32
    assert direct.mean() < one.mean() < full.mean()
    assert np.allclose(indirect, full - direct)
    info = {}
    again = R.render_reference(s, 24, 24, spp=4, component="direct", progress=False, info=info)
    assert info["cached"] and np.array_equal(again, direct)
    other = R.render_reference(s, 24, 24, spp=4, component="direct", seed=1, progress=False)
    assert not np.array_equal(other, direct)
    with pytest.raises(SerenityError, match="component"):
        R.render_reference(s, 8, 8, component="nope")


def test_material_mapping():
    mi = R.mitsuba()
    d = R.material_bsdf(mi, Material("m", albedo=(0.5, 0.5, 0.5)))
    assert d == {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb",
                                                                                "value": [0.5, 0.5, 0.5]}}}
    d = R.material_bsdf(mi, Material("p", albedo=(0.6, 0.6, 0.6), specular=0.25, shininess=49.0))["bsdf"]
    assert d["type"] == "blendbsdf" and d["weight"] == 0.25
    assert d["bsdf_0"]["reflectance"]["value"] == pytest.approx([0.8] * 3)
    assert d["bsdf_1"]["alpha"] == pytest.approx(math.sqrt(2 / 198))
    d = R.material_bsdf(mi, Material("mirror", reflectivity=0.9))["bsdf"]
    assert d["weight"] == 0.9 and d["bsdf_1"]["type"] == "conductor"
    d = R.material_bsdf(mi, Material("glass", transparency=0.8, ior=1.33))
    assert d["type"] == "blendbsdf" and d["weight"] == 0.8 and d["bsdf_1"]["int_ior"] == 1.33


def test_phong_brighter_than_one_is_exported_as_rendered():
    """The built-in glass's Phong surface (ρ 0.95, k_s 0.5: ρ + k_s > 1) exports unclamped: Mitsuba's
    diffuse part evaluates to exactly our ρ/π·cos (it was clamped to 0.5/π), and only such
    materials change the reference cache key."""
    mi = R.mitsuba()
    glass = Material("glass", albedo=(0.95, 0.95, 0.95), specular=0.5, shininess=500.0, transparency=0.9, ior=1.5)
    assert R.diffuse_exceeds_one(glass) and not R.diffuse_exceeds_one(Material("p", albedo=(0.6,) * 3, specular=0.25))
    blend = mi.load_dict(R.material_bsdf(mi, glass)["bsdf_0"])  # the Phong part of the glass blend
    si = mi.SurfaceInteraction3f()
    si.wi, si.n, si.sh_frame, si.uv = [0.6, 0.0, 0.8], [0, 0, 1], mi.Frame3f([0, 0, 1]), [0.3, 0.7]
    wo = np.array([-0.3, 0.5, 0.8124]) / np.linalg.norm([-0.3, 0.5, 0.8124])  # far from the glossy lobe
    value = np.asarray(blend.eval(mi.BSDFContext(), si, mi.Vector3f(*wo)))
    assert value == pytest.approx([0.95 / math.pi * wo[2]] * 3, rel=1e-4)


# ------------------------------------------------------------------------ agreement with our renderer


def our_direct(scene):
    """Our direct-only frame (no ambient term, no ray tracing: Mitsuba's depth 2 has no mirror bounce
    lit by the sun either, and those pixels are left out)."""
    from serenity.config import LPVConfig, RayTracingConfig, RenderConfig, SkyConfig
    from serenity.frame import Renderer

    cfg = RenderConfig(ambient="none", rt=RayTracingConfig(enabled=False), lpv=LPVConfig(enabled=False),
                       sky=SkyConfig(enabled=False))
    frame = Renderer(scene, W, H, config=cfg).render()
    return frame.hdr, frame.aovs["depth"][..., 0]


def direct_agreement(scene):
    ref = R.render_reference(scene, W, H, spp=SPP, component="direct", progress=False)
    _, ref_depth, mat = R.cast_primary(scene, W, H)
    ours, our_depth = our_direct(scene)
    rt = np.array([m.needs_ray_tracing for m in scene.materials] + [True])  # index -1: misses
    edges = ndimage.binary_dilation(depth_edges(our_depth) | depth_edges(ref_depth))
    usable = (mat >= 0) & ~rt[mat] & ~edges
    lo, lr = ours @ LUMA, ref @ LUMA
    # lit in both, one pixel away from any shadow boundary (penumbra technique differences are not units)
    lit = (ndimage.binary_erosion(lo > 0.05 * np.percentile(lo[usable], 99))
           & ndimage.binary_erosion(lr > 0.05 * np.percentile(lr[usable], 99)) & usable)
    return {
        "iou": edge_iou(our_depth, ref_depth),
        "lit": int(lit.sum()),
        "mean_rel": float(ours[lit].mean() / ref[lit].mean() - 1.0),
        "median_ratio": float(np.median(lo[lit] / lr[lit])),
        "rgb_rel": (ours[lit].mean(0) / ref[lit].mean(0) - 1.0).tolist(),
    }


@pytest.mark.gl
@pytest.mark.parametrize("case", ["plane", "plane-box-textured", "courtyard"])
def test_direct_light_and_silhouettes_agree_with_our_renderer(case):
    pytest.importorskip("moderngl")
    if case == "plane":
        scene = plane(albedo=0.5, elevation=60.0)
    elif case == "plane-box-textured":
        scene = plane(elevation=35.0, with_box=True, texture=asymmetric_texture())
    else:
        from serenity.scene import load

        scene = load("courtyard")
        scene.sky = Sky(radiance=(0.0, 0.0, 0.0), model="constant")
    r = direct_agreement(scene)
    print(case, r)
    assert r["lit"] > 0.15 * W * H
    assert r["iou"] >= 0.99
    assert abs(r["mean_rel"]) < 0.02
    assert max(abs(x) for x in r["rgb_rel"]) < 0.02
    assert abs(r["median_ratio"] - 1.0) < 0.02


def test_scene_type():
    assert isinstance(plane(), Scene)
