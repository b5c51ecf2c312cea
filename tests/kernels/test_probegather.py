"""Ray-traced irradiance probes (SkyConfig.method = "gather"): exact answers over a lit plane — the
bounce it sends up, no light of its own back onto itself, a white furnace — probe relocation out of
geometry, and the pass schedule after a change of the sun."""

import math

import numpy as np
import pytest

from serenity.config import LPVConfig, RenderConfig, SkyConfig
from serenity.errors import ConfigError
from serenity.kernels.atmosphere_ref import scene_sun_irradiance
from serenity.kernels.sampling import fibonacci_sphere
from serenity.kernels.skyvolume import SkyVolume
from serenity.scene.model import Sky
from serenity.scene.procedural import plane_scene

SKY = 1.0  # constant sky radiance, W·m⁻²·sr⁻¹


def _volume(device, scene, origin, cell=2.0, **kw):
    """One probe at ``origin`` (a 1³ grid), lit by gathering."""
    kw.setdefault("gather_rays", 512)
    cfg = SkyConfig(method="gather", resolution=(1, 1, 1), normal_offset=0.0, ground_albedo=0.0, **kw)
    vol = SkyVolume(scene, cfg, device=device)
    vol.grid_origin = np.asarray(origin, np.float64)
    vol.cell_size = np.full(3, cell)
    vol.rebuild()
    return vol


def _plane(albedo=0.5, irradiance=1000.0, elevation=60.0):
    s = plane_scene(elevation_deg=elevation, albedo=albedo, irradiance=irradiance)
    s.sky = Sky(radiance=(SKY,) * 3, model="constant")
    return s


def _exitance(scene, albedo):
    """The plane's Lambertian radiance: ρ/π·(E_sun·cos θ + π·L_sky) — it sees only the sky."""
    e_sun = scene_sun_irradiance(scene)[0] * scene.sun.direction[1]
    return albedo / math.pi * (e_sun + math.pi * SKY)


def test_plane_bounce_up_and_no_self_illumination(device):
    # a probe 1 m over the middle of a 40 m plane: below it the lit plane (radiance B), above the sky
    scene, albedo = _plane(), 0.5
    vol = _volume(device, scene, (0.0, 1.0, 0.0))
    b = _exitance(scene, albedo)
    p = vol.probe_positions()[:1]
    down = vol.irradiance(p, np.array([[0.0, -1.0, 0.0]]))[0, 0]
    up = vol.irradiance(p, np.array([[0.0, 1.0, 0.0]]))[0, 0]
    # the plane fills all but ~3° of the lower hemisphere (a form factor of 0.997)
    assert down == pytest.approx(math.pi * b, rel=0.03)
    # the plane must not light itself: what faces up sees the sky and nothing of the plane
    assert abs(up - math.pi * SKY) <= 0.1 * math.pi * b


def test_white_furnace(device):
    # albedo 1, no sun, a sky of L and a ground of L: every normal sees radiance L, E = π·L
    scene = _plane(albedo=1.0, irradiance=0.0)
    cfg_ground = 1.0
    vol = SkyVolume(scene, SkyConfig(method="gather", resolution=(1, 1, 1), normal_offset=0.0,
                                     ground_albedo=cfg_ground, gather_rays=512), device=device)
    vol.grid_origin = np.array([0.0, 1.0, 0.0])
    vol.cell_size = np.full(3, 2.0)
    vol.rebuild()
    n = fibonacci_sphere(64)
    e = vol.irradiance(np.repeat(vol.probe_positions()[:1], len(n), axis=0), n)
    assert np.allclose(e, math.pi * SKY, rtol=0.03)


def test_probe_under_the_plane_is_moved_out(device):
    # 1 cm under the plane half its rays hit the plane's back: it is moved up by 0.45 cell (0.9 m)
    # and sees what a probe over the plane sees
    scene = _plane()
    under = _volume(device, scene, (0.0, -0.01, 0.0))
    over = _volume(device, scene, (0.0, 0.89, 0.0))
    assert under.method.probes.relocated == 1 and under.method.probes.inside == 0
    n = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
    a = under.irradiance(np.repeat(under.probe_positions()[:1], 3, axis=0), n)
    b = over.irradiance(np.repeat(over.probe_positions()[:1], 3, axis=0), n)
    assert np.allclose(a, b, rtol=1e-4)


def test_passes_follow_a_sun_change_layer_by_layer(device):
    scene = _plane()
    cfg = SkyConfig(method="gather", resolution=(2, 3, 2), gather_rays=32, gather_bounces=2, transfer_layers=1)
    vol = SkyVolume(scene, cfg, device=device)
    vol.grid_origin, vol.cell_size = np.array([-5.0, 0.5, -5.0]), np.full(3, 2.0)  # over the plane
    assert vol.update() is True  # never lit: every bounce at once
    assert vol.updated_layers == [(0, 3)] and vol.method.passes_left == 0
    assert vol.update() is False  # nothing changed: no work
    before = vol.coefficients().copy()
    scene.sun.direction = np.array([0.3, 0.9, 0.1]) / np.linalg.norm([0.3, 0.9, 0.1])
    seen = []
    for _ in range(2 * 3):  # 2 passes of 3 layers, one layer per update
        assert vol.update() is True
        seen += vol.updated_layers
    assert seen == [(0, 1), (1, 1), (2, 1)] * 2
    assert vol.update() is False
    assert not np.allclose(vol.coefficients(), before)  # the bounce follows the sun (under a constant sky)


def test_gather_with_the_lpv_diffuse_is_refused():
    gather = SkyConfig(method="gather")
    with pytest.raises(ConfigError, match="counts twice"):
        RenderConfig(sky=gather)
    RenderConfig(sky=gather, lpv=LPVConfig(diffuse=False))
    RenderConfig(sky=gather, lpv=LPVConfig(enabled=False))


def _with_pane(scene, transparency: float, height: float = 2.0, half: float = 3.0, thickness: float = 0.02):
    """``scene`` plus a horizontal pane, a 2·half m square slab ``thickness`` thick at ``height``, of a
    glass-like material (transparency > 0) or an opaque grey one."""
    from serenity.scene.model import Material, Mesh

    scene.materials.append(Material(name="pane", albedo=np.full(3, 0.5), transparency=transparency, ior=1.5))
    lo = np.array([-half, height, -half])
    hi = np.array([half, height + thickness, half])
    pos, nrm, faces = [], [], []
    for axis in range(3):
        for side, normal_sign in ((lo, -1.0), (hi, 1.0)):
            u, v = [a for a in range(3) if a != axis]
            corners = []
            for cu, cv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                c = np.empty(3)
                c[axis] = side[axis]
                c[u] = (lo, hi)[cu][u]
                c[v] = (lo, hi)[cv][v]
                corners.append(c)
            n = np.zeros(3)
            n[axis] = normal_sign
            base = len(pos)
            pos += corners
            nrm += [n] * 4
            tri = [[0, 1, 2], [0, 2, 3]]
            e = np.cross(corners[1] - corners[0], corners[2] - corners[0])
            if np.dot(e, n) < 0:
                tri = [[0, 2, 1], [0, 3, 2]]
            faces += [[base + i for i in t] for t in tri]
    mat = len(scene.materials) - 1
    scene.meshes.append(Mesh("pane", np.array(pos), np.array(nrm), None, np.array(faces), np.full(len(faces), mat)))
    return scene


def test_rays_pass_through_glass_and_stop_on_an_opaque_pane(device):
    # no sun, a plane under the constant sky, a probe 1 m over it and a 6 m pane 1 m above the probe:
    # through glass (its rays bent in and out of the 2 cm slab) the probe sees the sky as without
    # the pane, E_up = π·L; an opaque grey pane hides most of it (its underside sees only the plane)
    up = np.array([[0.0, 1.0, 0.0]])

    def e_up(transparency=None):
        scene = _plane(irradiance=0.0)
        if transparency is not None:
            scene = _with_pane(scene, transparency)
        vol = _volume(device, scene, (0.0, 1.0, 0.0))
        return vol.irradiance(vol.probe_positions()[:1], up)[0, 0]

    none, clear, opaque = e_up(), e_up(0.9), e_up(0.0)
    assert none == pytest.approx(math.pi * SKY, rel=0.03)
    assert clear == pytest.approx(none, rel=0.03)
    assert opaque < 0.5 * math.pi * SKY


def test_surfels_carry_the_phong_lobes_energy(device):
    # k_s = 0.2 on a plane of albedo 0.5: what it sends up is (ρ + k_s)/π·E with SkyConfig.glossy
    # (the reference's Phong lobe reflects its k_s too), ρ/π·E without, and a mirror's k_s not at all
    down = np.array([[0.0, -1.0, 0.0]])
    results = {}
    for label, glossy, reflectivity in (("glossy", True, 0.0), ("diffuse", False, 0.0), ("mirror", True, 0.5)):
        scene = _plane()
        scene.materials[0].specular = 0.2
        scene.materials[0].reflectivity = reflectivity
        vol = _volume(device, scene, (0.0, 1.0, 0.0), glossy=glossy)
        results[label] = vol.irradiance(vol.probe_positions()[:1], down)[0, 0]
    b = _exitance(_plane(), 0.5)
    assert results["glossy"] == pytest.approx(math.pi * b * 0.7 / 0.5, rel=0.03)
    assert results["diffuse"] == pytest.approx(math.pi * b, rel=0.03)
    assert results["mirror"] == pytest.approx(results["diffuse"], rel=1e-6)


def test_sun_moving_every_update_then_stopping_converges_to_the_rebuild(device):
    # one y-layer per update: each move of the sun re-traces one slice of the surfels' shadow rays
    # (every surfel once per pass of y updates); once the sun stops the passes run out and the
    # volume is what a rebuild at the last sun gives (the first pass's stale slices decay away)
    scene = _plane()
    cfg = SkyConfig(method="gather", resolution=(3, 4, 3), gather_rays=64, transfer_layers=1, gather_bounces=12,
                    gather_tolerance=0.0)  # a fixed count of passes
    vol = SkyVolume(scene, cfg, device=device)
    vol.grid_origin, vol.cell_size = np.array([-4.0, 0.5, -4.0]), np.full(3, 2.0)
    vol.update()
    g = vol.method.probes
    for k in range(7):  # the sun swings 7 times, one update each
        a = math.radians(60.0 - 4.0 * k)
        vol.update(sun_direction=np.array([0.0, math.sin(a), -math.cos(a)]))
        assert g._vis_parts == 4 and g._vis_left == 3  # one slice traced now, three to go
    steps = 0
    while vol.update(sun_direction=np.array([0.0, math.sin(a), -math.cos(a)])):
        steps += 1
    assert (cfg.gather_bounces - 1) * 4 <= steps <= cfg.gather_bounces * 4 and g._vis_left == 0
    fresh = SkyVolume(scene, cfg, device=device)
    fresh.grid_origin, fresh.cell_size = vol.grid_origin, vol.cell_size
    fresh.rebuild(sun_direction=np.array([0.0, math.sin(a), -math.cos(a)]))
    c, f = vol.coefficients(), fresh.coefficients()
    assert np.abs(c - f).max() <= 0.01 * np.abs(f).max()


def test_trace_cached_on_disk_reads_back_the_same_volume(device, tmp_path, monkeypatch):
    import serenity.kernels.probegather as PG

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path))
    monkeypatch.setattr(PG, "CACHE_MIN_RAYS", 1)
    cfg = SkyConfig(method="gather", resolution=(3, 2, 3), gather_rays=64)

    def build():
        vol = SkyVolume(_plane(), cfg, device=device)
        vol.rebuild()
        return vol

    first = build()
    files = list(tmp_path.glob("probegather-*.npz"))
    assert not first.method.probes.from_cache and len(files) == 1
    second = build()
    assert second.method.probes.from_cache
    assert np.array_equal(first.coefficients(), second.coefficients())
    files[0].write_bytes(b"not an npz")  # a corrupt cache file: traced again, and rewritten
    third = build()
    assert not third.method.probes.from_cache
    assert np.array_equal(first.coefficients(), third.coefficients())
    scene = _plane()
    scene.materials[0].albedo = np.full(3, 0.25)  # another scene: another key
    other = SkyVolume(scene, cfg, device=device)
    other.rebuild()
    assert not other.method.probes.from_cache and len(list(tmp_path.glob("probegather-*.npz"))) == 2


def test_first_lighting_cached_on_disk_skips_the_passes(device, tmp_path, monkeypatch):
    """A volume lit for the first time caches its coefficients after every pass; the next renderer of
    the same scene, sky and sun reads them instead of gathering, and gets the same volume; another
    sun is another entry, lit by the passes."""
    import serenity.kernels.probegather as PG

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path))
    monkeypatch.setattr(PG, "CACHE_MIN_RAYS", 1)
    cfg = SkyConfig(method="gather", resolution=(3, 2, 3), gather_rays=64, gather_bounces=3, gather_tolerance=0.0)
    gathers = []
    monkeypatch.setattr(PG.ProbeGather, "gather", lambda self, *a, _g=PG.ProbeGather.gather: (gathers.append(1),
                                                                                                _g(self, *a)))

    def build(sun=None):
        vol = SkyVolume(_plane(), cfg, device=device)
        vol.rebuild(sun_direction=sun)
        return vol

    first = build()
    passes = len(gathers)
    assert passes >= 2 and len(list(tmp_path.glob("probegather-lit-*.npy"))) == 1
    second = build()
    assert len(gathers) == passes  # read back: no pass ran
    assert np.array_equal(first.coefficients(), second.coefficients()) and np.abs(first.coefficients()).max() > 0
    third = build(sun=np.array([0.3, 0.8, 0.2]))
    assert len(gathers) > passes and len(list(tmp_path.glob("probegather-lit-*.npy"))) == 2
    assert not np.array_equal(first.coefficients(), third.coefficients())
    for f in tmp_path.glob("probegather-lit-*.npy"):
        f.write_bytes(b"garbage")  # unreadable: lit by the passes again
    before = len(gathers)
    again = build()
    assert len(gathers) == before + passes and np.array_equal(first.coefficients(), again.coefficients())


def test_visibility_lookup_warp_equals_host(device):
    """The Warp lookup with the probes' visibility (the surfels' and the sky-light VPLs') equals the
    numpy twin of sky.glsl's; the octahedral map's encoding inverts its decoding."""
    from serenity.kernels.probesurfels import oct_decode_np
    from serenity.kernels.skylookup import oct_encode_np
    from serenity.scene.procedural import build_scene

    uv = np.random.default_rng(6).uniform(-1, 1, size=(500, 2))
    assert np.allclose(oct_encode_np(oct_decode_np(uv)), uv, atol=1e-9)
    scene = build_scene("courtyard")
    vol = SkyVolume(scene, SkyConfig(method="gather", target_probes=800, gather_rays=32, fit="content"),
                    device=device)
    vol.rebuild()
    g = vol.method.probes
    pick = np.arange(0, g.surfel_count, max(1, g.surfel_count // 400))
    p, n = g.surfel_positions[pick], g.surfel_normals[pick]
    assert np.allclose(vol.irradiance_wp(p, n), vol.irradiance(p, n), rtol=1e-4, atol=1e-3)


def test_passes_stop_once_converged(device, tmp_path, monkeypatch):
    """The Cornell box passes light on for many bounces: with gather_tolerance the passes stop well
    before the cap of 64, and the volume they leave is within a few tolerances (relative L1) of the
    one 64 passes give; with tolerance 0 all 64 run."""
    import serenity.kernels.probegather as PG
    from serenity.scene import load

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path))
    gathers = []
    monkeypatch.setattr(PG.ProbeGather, "gather", lambda self, *a, _g=PG.ProbeGather.gather: (gathers.append(1),
                                                                                                _g(self, *a)))
    scene = load("cornell")

    def lit(tolerance):
        gathers.clear()
        cfg = SkyConfig(method="gather", resolution=(3, 3, 3), gather_rays=64, gather_bounces=64,
                        gather_tolerance=tolerance)
        vol = SkyVolume(scene, cfg, device=device)
        vol.rebuild()
        return vol.coefficients(), len(gathers)

    full, n_full = lit(0.0)
    conv, n_conv = lit(0.005)
    assert n_full == 64 and 3 <= n_conv < 32
    rel = np.abs(conv - full).sum() / np.abs(full).sum()
    print(f"{n_conv} passes, relative L1 from 64 passes {rel:.4f}")
    assert rel <= 3 * 0.005


def test_reachable_probes_hold_every_lookup_and_skip_the_empty_air():
    """Every probe a lookup at a point of the triangles (moved by up to the offset along any normal)
    reads is reachable; probes far from every triangle are not; a big slanted triangle marks only the
    probes near its plane, not its whole box."""
    from serenity.kernels.skylookup import lookup_probes, reachable_probes

    rng = np.random.default_rng(3)
    # a floor (two big triangles below the grid: the lookups clamp onto the bottom layer), a small box
    # in the air, a big slanted quad inside the grid
    v = np.array([[-9, -0.5, -9], [9, -0.5, -9], [9, -0.5, 9], [-9, -0.5, 9],
                  [1.0, 4.0, 1.0], [1.3, 4.0, 1.0], [1.3, 4.2, 1.3],
                  [-3.0, 1.0, -3.0], [3.0, 1.0, -3.0], [3.0, 7.0, 3.0], [-3.0, 7.0, 3.0]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [7, 8, 9], [7, 9, 10]])
    origin, cell, res, reach = np.array([-4.0, 0.0, -4.0]), np.full(3, 0.5), (17, 17, 17), 0.2
    mask = reachable_probes(v, f, origin, cell, res, reach)
    tri = v[f].astype(np.float64)
    t = rng.integers(0, len(f), 200_000)
    a, b = rng.random((2, len(t)))
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    p = tri[t, 0] + a[:, None] * (tri[t, 1] - tri[t, 0]) + b[:, None] * (tri[t, 2] - tri[t, 0])
    n = rng.normal(size=p.shape)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    read = np.zeros(mask.size, bool)
    read[lookup_probes(p + reach * rng.random((len(t), 1)) * n, origin, cell, res).reshape(-1)] = True
    assert not np.any(read & ~mask)
    assert read.sum() >= 0.9 * mask.sum()  # and not much more than that
    grid = np.stack(np.meshgrid(*(np.arange(k) for k in res[::-1]), indexing="ij")[::-1], axis=-1).reshape(-1, 3)
    q = origin + grid * cell
    plane_n = np.array([0.0, 1.0, -1.0]) / math.sqrt(2.0)
    box = np.linalg.norm(q - [1.15, 4.1, 1.15], axis=1)
    far = (np.abs((q - tri[3, 0]) @ plane_n) > 2.0) & (q[:, 1] > 1.5) & (box > 2.0)
    assert far.sum() > 500 and not np.any(mask[far])


def test_probes_no_lookup_reads_are_not_traced(device, monkeypatch):
    """Over a plane, a grid of 6 layers: the lookups on the plane read the lowest two, so only they are
    traced and gathered (the others hold zeros), and the plane's light is what tracing every probe gives."""
    import serenity.kernels.skygather as SG

    def volume():
        cfg = SkyConfig(method="gather", resolution=(3, 6, 3), gather_rays=128, ground_albedo=0.0)
        vol = SkyVolume(_plane(), cfg, device=device)
        vol.grid_origin, vol.cell_size = np.array([-1.0, 0.5, -1.0]), np.full(3, 1.0)
        vol.rebuild()
        return vol

    vol = volume()
    g = vol.method.probes
    assert g.active.reshape(3, 6, 3)[:, :2].all() and not g.active.reshape(3, 6, 3)[:, 2:].any()
    c = vol.coefficients()
    assert np.all(c[:, 2:] == 0) and np.all(np.abs(c[:, :2]).max(axis=(2, 3)) > 0)
    assert np.all(g._surfel.numpy()[~g.active] == -2)
    monkeypatch.setattr(SG, "reachable_probes", lambda *a: np.ones(3 * 6 * 3, bool))
    every = volume()
    assert every.method.probes.active.all()
    pts = np.array([[x, 0.0, z] for x in (-0.7, 0.2, 1.1) for z in (-0.4, 0.6)])
    up = np.tile([0.0, 1.0, 0.0], (len(pts), 1))
    assert np.allclose(vol.irradiance(pts, up), every.irradiance(pts, up), rtol=2e-3)
