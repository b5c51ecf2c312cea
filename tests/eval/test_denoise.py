"""The OIDN wrapper: a clear error without pyoidn, guides from AOVs, and that it really removes noise
from a path-traced image of a tiny scene (relMSE and FLIP against a converged render both drop)."""

import sys

import numpy as np
import pytest

from serenity.errors import SerenityError
from serenity.eval import denoise as D


def test_missing_pyoidn_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pyoidn", None)  # import fails as if not installed
    with pytest.raises(SerenityError, match=r"pyoidn.*serenity\[eval\]"):
        D.denoise(np.ones((4, 4, 3), np.float32))
    assert not D.available()


def test_guides_from_aovs():
    h, w = 4, 6
    albedo = np.full((h, w, 3), 0.5, np.float32)
    albedo[0, 0] = 1.7  # out of range: clamped
    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 1] = 1.0
    depth = np.full((h, w, 1), 3.0, np.float32)
    depth[:, 0] = np.inf  # sky column
    rt = np.zeros((h, w, 1), np.float32)
    rt[3, 5] = 1.0  # a mirror pixel
    a, n = D.guides_from_aovs({"albedo": albedo, "normal": normal, "depth": depth, "rt_mask": rt})
    assert a.shape == n.shape == (h, w, 3) and a.dtype == np.float32
    assert np.all(a[:, 0] == 1.0) and np.all(n[:, 0] == 0.0)  # sky: white albedo, no normal
    assert np.all(a[3, 5] == 1.0) and np.all(n[3, 5] == [0.0, 1.0, 0.0])  # traced: white albedo
    assert np.all(a[1:3, 1:5] == 0.5) and np.all(n[1:3, 1:5] == [0.0, 1.0, 0.0])
    a2, n2 = D.guides_from_aovs({"albedo": albedo, "normal": normal, "depth": depth, "rt_mask": rt}, supersample=2)
    assert a2.shape == (2, 3, 3)
    assert a2[0, 0] == pytest.approx([0.75] * 3)  # half sky (1), half 0.5
    assert n2[0, 0] == pytest.approx([0.0, 0.5, 0.0])
    with pytest.raises(SerenityError, match="supersample"):
        D.guides_from_aovs({"albedo": albedo, "normal": normal, "depth": depth}, supersample=4)
    with pytest.raises(SerenityError, match="'depth' AOV"):
        D.guides_from_aovs({"albedo": albedo, "normal": normal})


needs_oidn = pytest.mark.skipif(not D.available(), reason="pyoidn is not installed")


@needs_oidn
def test_bad_input():
    c = np.ones((8, 8, 3), np.float32)
    with pytest.raises(SerenityError, match="color must be"):
        D.denoise(np.ones((8, 8), np.float32))
    with pytest.raises(SerenityError, match="shape mismatch"):
        D.denoise(c, np.ones((8, 4, 3), np.float32))
    with pytest.raises(SerenityError, match="negative"):
        D.denoise(-c)
    with pytest.raises(SerenityError, match="NaN"):
        D.denoise(c * np.nan)
    with pytest.raises(SerenityError, match="quality"):
        D.denoise(c, quality="best")
    with pytest.raises(SerenityError, match="albedo guide too"):
        D.denoise(c, normal=c)


@needs_oidn
def test_denoising_a_noisy_path_traced_image_reduces_its_error(tmp_path, monkeypatch):
    pytest.importorskip("mitsuba")
    from serenity.eval import reference as R
    from serenity.eval.metrics import flip, rel_mse
    from serenity.scene.model import Camera, Sky
    from tests.raster.scenes import plane_scene

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    s = plane_scene(albedo=0.5, zenith_deg=40.0, irradiance=1000.0, with_box=True)
    s.sky = Sky(radiance=(20.0, 25.0, 30.0), model="constant")
    # looking down so that the plane fills the frame: no black pixels, on which relMSE (absolute ε)
    # would count the denoiser's slight bleed across the plane's far edge as a huge error
    s.camera = Camera(position=(0.0, 12.0, 6.0), target=(0.0, 0.0, -1.0), fov_y_deg=50.0)
    w, h = 48, 27
    ref = R.render_reference(s, w, h, spp=128, progress=False)
    noisy = R.render_reference(s, w, h, spp=2, seed=7, progress=False)
    # noise-free guides from Mitsuba's own AOVs (our renderer's need GL; the bench uses those)
    mi = R.mitsuba()
    d = R.mitsuba_scene_dict(R.with_effective_sun(s), w, h, -1, R.sky_map(s))
    d["integrator"] = {"type": "aov", "aovs": "a:albedo,n:sh_normal"}
    aov = np.array(mi.render(mi.load_dict(d), spp=16), np.float32)
    albedo, normal = aov[..., :3], aov[..., 3:6]

    raw = rel_mse(noisy, ref), flip(noisy, ref)
    for out in (D.denoise(noisy), D.denoise(noisy, albedo, normal, quality="balanced")):
        assert out.shape == noisy.shape and out.dtype == np.float32 and np.all(np.isfinite(out))
        assert rel_mse(out, ref) < 0.5 * raw[0]
        assert flip(out, ref) < 0.8 * raw[1]
        assert out.mean() == pytest.approx(ref.mean(), rel=0.05)  # denoising keeps the energy
