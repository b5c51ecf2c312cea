"""The reference can be trusted not to create light: a material that reflects more than it receives
is warned of by name at export, and a render brighter than the scene's brightest emitter raises,
naming the scene, the count of pixels over the bound and the maximum. The breakfast room (glTF
metals, a closed room lit by a low sun) renders within the bound."""

import os
import warnings

import numpy as np
import pytest

from serenity.eval import reference as R
from serenity.scene import build_scene
from serenity.scene.model import Material, Mesh, Scene

pytest.importorskip("mitsuba")

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BREAKFAST = os.path.join(ROOT, "scenes", "breakfast_room", "breakfast_room.toml")


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


def test_material_gain_is_what_the_exported_blends_reflect():
    assert R.material_gain(Material("d", albedo=(0.5, 0.7, 0.2))) == pytest.approx(0.7)
    assert R.material_gain(Material("p", albedo=(0.6,) * 3, specular=0.3)) == pytest.approx(0.9)
    assert R.material_gain(Material("m", albedo=(0.05,) * 3, specular=0.9, reflectivity=0.9)) == pytest.approx(0.995)
    glass = Material("glass", albedo=(0.95,) * 3, specular=0.5, transparency=0.9, ior=1.5)
    assert R.material_gain(glass) == pytest.approx(0.9 + 0.1 * 1.45)
    # the breakfast room's Chrome as the former glTF mapping gave it
    assert R.material_gain(Material("Chrome", albedo=(0.8,) * 3, specular=0.828, reflectivity=0.113)) > 1.5


def test_a_material_that_reflects_more_than_it_receives_is_warned_of_by_name():
    s = build_scene("cornell")
    s.materials[s.material_index("red")] = Material("red", albedo=(0.9, 0.1, 0.1), specular=0.5, shininess=20.0)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        assert R.warn_energy_gain(s) == ["red"]
    msgs = [str(x.message) for x in w]
    assert len(msgs) == 1 and "'red'" in msgs[0] and "'cornell'" in msgs[0] and "1.4" in msgs[0]
    assert "\n" not in msgs[0]
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        assert R.warn_energy_gain(build_scene("cornell")) == []
    assert not w


def test_the_bound_is_the_brightest_emitter():
    s = R.with_effective_sun(build_scene("cornell"))
    assert np.allclose(R.emitter_radiance_bound(s, None), s.sun.radiance)
    sky = R.constant_sky_map((1e8, 2.0, 3.0), 16, 8)
    assert np.allclose(R.emitter_radiance_bound(s, sky), [1e8, s.sun.radiance[1], s.sun.radiance[2]])
    s.sun.direction = np.array([0.0, -1.0, 0.0])  # below the horizon: no sun in the export
    assert np.allclose(R.emitter_radiance_bound(s, sky), [1e8, 2.0, 3.0])
    img = np.zeros((2, 2, 3), np.float32)
    R.check_radiance_bound(img, s, sky)
    img[0, 1, 2] = 3.0 * 1.2
    with pytest.raises(R.ReferenceBoundError, match=r"'cornell'.*1 of 4 pixels.*maximum 3\.6"):
        R.check_radiance_bound(img, s, sky)
    img[0, 1, 2] = np.inf
    with pytest.raises(R.ReferenceBoundError, match="maximum inf"):
        R.check_radiance_bound(img, s, sky)


def closed_cornell_box():
    """The Cornell box closed behind the camera (a tube of four quads and a back wall at z = -0.9):
    its light comes in only through the ceiling's hole and leaves only through it."""
    s = build_scene("cornell")
    (x0, y0, z0), (x1, y1, _) = np.asarray(s.bounds)
    z = -0.9

    def quad(name, p):
        p = np.asarray(p, np.float64)
        n = np.cross(p[1] - p[0], p[2] - p[0])
        return Mesh(name, p, np.tile(n / np.linalg.norm(n), (4, 1)), np.zeros((4, 2), np.float32),
                    np.array([[0, 1, 2], [0, 2, 3]]), np.zeros(2, int))

    extra = [quad("front", [[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]]),
             quad("left", [[x0, y0, z], [x0, y0, z0], [x0, y1, z0], [x0, y1, z]]),
             quad("right", [[x1, y0, z], [x1, y0, z0], [x1, y1, z0], [x1, y1, z]]),
             quad("bottom", [[x0, y0, z], [x1, y0, z], [x1, y0, z0], [x0, y0, z0]]),
             quad("top", [[x0, y1, z], [x1, y1, z], [x1, y1, z0], [x0, y1, z0]])]
    return Scene("closed-cornell", s.meshes + extra, s.materials, s.camera, s.sun, s.sky, [])


def test_a_deliberately_non_conserving_material_is_caught():
    """Every wall of a closed box reflecting 1.85 of what it receives: the paths' weights grow with
    their length and the render breaks the bound (its maximum is 4e13 to 2e16 W/m^2/sr over eight
    seeds, against the sun's 1.5e7); it raises, naming the scene, and caches nothing. The same box
    with conserving walls (ρ 0.95) stays far below the bound."""
    s = closed_cornell_box()
    s.materials = [Material(m.name, albedo=(0.95,) * 3, specular=0.9, shininess=2.0) for m in s.materials]
    with pytest.warns(UserWarning, match="reflects up to 1.85"):
        with pytest.raises(R.ReferenceBoundError, match=r"reference of 'closed-cornell' \(16x16, 8 spp, depth -1\): "
                                                        r"\d+ of 256 pixels exceed"):
            R.render_reference(s, 16, 16, spp=8, progress=False)
    assert not os.path.isdir(R.cache_dir()) or not os.listdir(R.cache_dir())
    s.materials = [Material(m.name, albedo=(0.95,) * 3) for m in s.materials]
    img = R.render_reference(s, 16, 16, spp=8, progress=False)
    assert 0 < img.max() < 1e-3 * s.sun.radiance.max()


def test_the_breakfast_room_reference_stays_below_the_sun():
    import serenity

    scene = serenity.load(BREAKFAST)
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        img = R.render_reference(scene, 32, 18, spp=16, progress=False)
    assert not [x for x in w if "reflects up to" in str(x.message)]
    sun = R.with_effective_sun(scene).sun.radiance
    assert np.isfinite(img).all() and img.max() < sun.max()
    assert img.mean() > 0  # lit
