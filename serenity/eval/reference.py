"""Reference renders: a ``Scene`` exported to Mitsuba 3 and path traced (docs/architecture.md, "Accuracy").

    img = render_reference(scene, 320, 180, spp=64, component="full")   # (H, W, 3) float32

The output is linear radiance in W·m⁻²·sr⁻¹ per RGB channel, row 0 = top — the units and layout of
``serenity.frame.Frame.hdr``. Mitsuba runs in its ``scalar_rgb`` variant only (the ``llvm_*``
variants crash on these machines' LLVM); it renders with its own thread pool.

What is exported, and how faithfully (geometry, textures, Phong, mirrors, glass, the sun, the sky,
the camera), is :mod:`serenity.eval.mitsuba_export`'s; its names import from here too. This module
renders the export, checks it and caches it:

- **Components** via the ``path`` integrator's ``max_depth``: "direct" = 2 (emitters seen directly +
  one scattering event lit by sun/sky), "one-bounce" = 3, "full" = unlimited (Russian roulette
  from depth 5), and "indirect" = full − direct (each rendered and cached on its own).

**Bounds.** No surface can send out more than the brightest radiance that reaches it when its BSDF
reflects at most what it receives, so no reference pixel may exceed the brightest emitter's
radiance, per channel: max(the sun's disc, the sky map's brightest texel)
(:func:`emitter_radiance_bound`). A render that does raises :class:`ReferenceBoundError` naming
the scene, the count of such pixels and the maximum, and is not cached; the tolerance
(:data:`RADIANCE_BOUND_TOLERANCE`) covers the sun's calibration (±0.3 %), Monte Carlo weights
slightly above one and the built-in glass's Phong surface (the export's Phong). Before that, the export
warns (one line, naming the material) of every material whose exported BSDF can reflect more than
it receives (:func:`material_gain` > 1): T + (1 − T)·(R + (1 − R)·(max ρ + k_s)). The built-in glass
(ρ 0.95, k_s 0.5, T 0.9: 1.045) is one, on purpose (the export's Phong); in a closed room such a material makes
the path tracer's estimate grow without bound with the path length.

**Noise floor.** :func:`reference_with_floor` renders a reference as two independent halves
(different seeds, half the samples each) and reports the FLIP and relMSE between them
(:class:`Reference`'s ``floor``, stored beside the cached halves as ``.floor.json``): an error
measured against the reference means something only well above it. The floor is conservative:
two halves differ by twice the variance of one, four times that of their mean, the reference, so
the reference's own relMSE against the converged image is about a quarter of the floor's.
:func:`reference_for_error` doubles the samples (each half a sum of cached blocks of 1, 1, 2, 4…
times the first block's samples, so a larger request renders only the new blocks) until the floor
is at most a quarter of a given error, or says it could not within ``max_spp``.

Results are cached as ``.npy`` in ``$SERENITY_CACHE`` (default ``~/.cache/serenity/reference``),
keyed by a SHA-256 of every scene array and field, the sky map, the settings and the Mitsuba version.
"""

from __future__ import annotations

import copy
import hashlib
import json
import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from serenity.config import DEFAULT_EXPOSURE, check_image_size
from serenity.errors import SerenityError
from serenity.eval import metrics
from serenity.eval.mitsuba_export import (
    AUTO_SKY,
    EXPORTER_VERSION,
    MATERIAL_GAIN_TOLERANCE,
    SKY_MAP_SIZE,
    SUN_DISTANCE_FACTOR,
    calibrate_sun,
    cast_primary,
    constant_sky_map,
    default_sky_envmap,
    diffuse_exceeds_one,
    load_mitsuba_scene,
    material_bsdf,
    material_gain,
    meshes_by_material,
    mitsuba,
    mitsuba_scene_dict,
    phong_alpha,
    sensor_dict,
    sky_map,
    sun_sphere,
    warn_energy_gain,
)
from serenity.kernels.atmosphere import scene_sun_irradiance
from serenity.scene.model import IDENTITY_UV

__all__ = [
    "COMPONENTS", "COMPONENT_DEPTH", "DEFAULT_CHUNK_SPP", "EXPORTER_VERSION", "MATERIAL_GAIN_TOLERANCE",
    "RADIANCE_BOUND_TOLERANCE", "SKY_MAP_SIZE", "SUN_DISTANCE_FACTOR", "Reference", "ReferenceBoundError",
    "cache_dir", "calibrate_sun", "cast_primary", "check_radiance_bound", "constant_sky_map", "default_sky_envmap",
    "diffuse_exceeds_one", "emitter_radiance_bound", "load_mitsuba_scene", "material_bsdf", "material_gain",
    "meshes_by_material", "mitsuba", "mitsuba_scene_dict", "phong_alpha", "reference_for_error",
    "reference_with_floor", "render_reference", "scene_hash", "sensor_dict", "sky_map", "sun_sphere",
    "warn_energy_gain", "with_effective_sun",
]

COMPONENT_DEPTH = {"direct": 2, "one-bounce": 3, "full": -1}
COMPONENTS = (*COMPONENT_DEPTH, "indirect")
DEFAULT_CHUNK_SPP = 4
RADIANCE_BOUND_TOLERANCE = 1.1
"""A reference pixel may exceed the brightest emitter's radiance by this factor (module doc, Bounds)."""


def cache_dir() -> str:
    """``$SERENITY_CACHE`` or ``~/.cache/serenity/reference``."""
    return os.environ.get("SERENITY_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "serenity",
                                                             "reference")


# ------------------------------------------------------------------------------------------- caching


def scene_hash(scene, settings: dict, sky: np.ndarray | None = None) -> str:
    """SHA-256 (hex) of everything in ``scene`` that changes the image, the sky map and ``settings``."""
    h = hashlib.sha256()

    def put(*items):
        for x in items:
            if isinstance(x, np.ndarray):
                a = np.ascontiguousarray(x)
                h.update(f"{a.dtype}{a.shape}".encode())
                h.update(a.tobytes())
            else:
                h.update(repr(x).encode())
            h.update(b"|")

    mi = mitsuba()
    put("serenity-reference", EXPORTER_VERSION, mi.__version__, sorted(settings.items()))
    for m in scene.meshes:
        put(m.positions, m.normals, m.uvs, m.faces, m.face_material)
    for m in scene.materials:
        put(m.albedo, m.specular, m.shininess, m.reflectivity, m.transparency, m.ior)
        put(None if m.albedo_texture is None else m.albedo_texture.mips[0])
        if m.alpha_tested or m.normal_texture is not None or not np.array_equal(m.albedo_uv_transform, IDENTITY_UV):
            # only scenes that use these change their keys
            put("cut-outs, normal maps, uv transforms", m.alpha_tested, m.alpha, m.alpha_cutoff, m.albedo_uv_transform,
                m.normal_uv_transform, m.normal_scale, None if m.normal_texture is None else m.normal_texture.mips[0])
        if diffuse_exceeds_one(m):  # exported unclamped since then: only these scenes' keys change
            put("diffuse > 1 unclamped")
    c = scene.camera
    put(c.position, c.target, c.up, c.fov_y_deg, c.near, c.far)
    put(scene.sun.direction, scene.sun.irradiance, scene.sun.angular_diameter_deg)
    put(sky if sky is not None else "black-sky")
    return h.hexdigest()


# ------------------------------------------------------------------------------------------- bounds


class ReferenceBoundError(SerenityError):
    """A reference render brighter than its scene's emitters can make it (module doc, Bounds)."""


def emitter_radiance_bound(scene, sky: np.ndarray | None) -> np.ndarray:
    """(3,) the brightest radiance any emitter of the exported ``scene`` sends, per channel: the sun's
    disc (when it is up and lit; ``scene`` carries the sun the reference uses, see
    :func:`with_effective_sun`) and the sky map's brightest texel."""
    bound = np.zeros(3)
    if scene.sun.is_up and np.any(scene.sun.irradiance > 0):
        bound = np.maximum(bound, np.asarray(scene.sun.radiance, np.float64))
    if sky is not None:
        bound = np.maximum(bound, np.asarray(sky, np.float64)[..., :3].reshape(-1, 3).max(axis=0))
    return bound


def check_radiance_bound(img: np.ndarray, scene, sky: np.ndarray | None, what: str = "",
                         tolerance: float = RADIANCE_BOUND_TOLERANCE) -> None:
    """Raise :class:`ReferenceBoundError` when a pixel of ``img`` (or a non-finite value) exceeds
    ``tolerance`` × :func:`emitter_radiance_bound` in some channel."""
    bound = emitter_radiance_bound(scene, sky) * float(tolerance)
    a = np.asarray(img, np.float64)[..., :3]
    over = ~np.isfinite(a) | (a > bound)
    bad = over.any(axis=-1)
    if not bad.any():
        return
    finite = a[np.isfinite(a)]
    peak = float(finite.max()) if finite.size else float("inf")
    if not np.isfinite(a).all():
        peak = float("inf")
    raise ReferenceBoundError(
        f"reference of {scene.name!r}{' ' + what if what else ''}: {int(bad.sum())} of {bad.size} pixels exceed "
        f"the brightest emitter's radiance ({float(bound.max() / tolerance):.3g} W/m^2/sr, x{tolerance:g} "
        f"tolerance), maximum {peak:.3g}: a material reflects more than it receives or the export divides "
        "by nearly zero")


def _cached(path: str) -> np.ndarray | None:
    try:
        return np.load(path)
    except (OSError, ValueError):
        return None


def _store(path: str, img: np.ndarray) -> None:
    os.makedirs(os.path.dirname(path), exist_ok=True)
    tmp = f"{path}.{os.getpid()}.tmp.npy"
    np.save(tmp, img)
    os.replace(tmp, path)


# ------------------------------------------------------------------------------------------- render


def with_effective_sun(scene):
    """A shallow copy of ``scene`` whose sun carries the irradiance our renderer uses
    (:func:`serenity.kernels.atmosphere.scene_sun_irradiance`: the atmosphere's sun colour for
    "atmosphere" skies), so both renderers are lit by the same sun."""
    out = copy.copy(scene)
    out.sun = copy.copy(scene.sun)
    out.sun.irradiance = scene_sun_irradiance(scene)
    return out


def render_reference(scene, width: int, height: int, spp: int = 64, component: str = "full", seed: int = 0, *,
                     max_depth: int | None = None, sky_envmap=AUTO_SKY, cache: bool = True, progress: bool = True,
                     chunk_spp: int = DEFAULT_CHUNK_SPP, info: dict | None = None) -> np.ndarray:
    """Path-traced reference of ``scene``: (H, W, 3) float32 linear radiance, W·m⁻²·sr⁻¹, row 0 = top.

    component: "direct" | "one-bounce" | "full" | "indirect" (= full − direct); ``max_depth``
        overrides it with the ``path`` integrator's depth (-1 = unlimited).
    spp: samples per pixel, rendered in chunks of ``chunk_spp`` with seeds derived from ``seed``
        and averaged (a tqdm bar counts the chunks).
    sky_envmap: ``f(sun_direction) -> (H, W, 3)`` equirect sky for ``model == "atmosphere"`` skies;
        default: the atmosphere module's ``equirect_sky`` when it exists; None = constant sky.
    cache: read/write ``cache_dir()/<hash>.npy``.
    info: if given, filled with ``cache_paths`` (list) and ``cached`` (True when nothing was rendered).
    """
    scene = with_effective_sun(scene)
    if info is not None:
        info.setdefault("cache_paths", [])
        info.setdefault("cached", True)
    if max_depth is None:
        if component == "indirect":
            kw = dict(spp=spp, seed=seed, sky_envmap=sky_envmap, cache=cache, progress=progress,
                      chunk_spp=chunk_spp, info=info)
            full = render_reference(scene, width, height, component="full", **kw)
            direct = render_reference(scene, width, height, component="direct", **kw)
            return (full - direct).astype(np.float32)
        if component not in COMPONENT_DEPTH:
            raise SerenityError(f"component must be one of {', '.join(COMPONENTS)}, got {component!r}")
        max_depth = COMPONENT_DEPTH[component]
    if not (max_depth == -1 or max_depth >= 1):
        raise SerenityError(f"max depth must be -1 (unlimited) or >= 1, got {max_depth}")
    check_image_size(width, height)
    if not int(spp) >= 1:
        raise SerenityError(f"spp must be >= 1, got {spp}")
    width, height, spp, chunk_spp = int(width), int(height), int(spp), max(1, int(chunk_spp))

    sky = sky_map(scene, sky_envmap)
    settings = {"width": width, "height": height, "spp": spp, "max_depth": int(max_depth), "seed": int(seed),
                "chunk_spp": chunk_spp}
    path = os.path.join(cache_dir(), scene_hash(scene, settings, sky) + ".npy")
    if info is not None:
        info["cache_paths"].append(path)
    what = f"({width}x{height}, {spp} spp, depth {max_depth})"
    if cache:
        img = _cached(path)
        if img is not None and img.shape == (height, width, 3):
            check_radiance_bound(img, scene, sky, what)
            return img
    if info is not None:
        info["cached"] = False

    mi = mitsuba()
    mscene = load_mitsuba_scene(scene, width, height, max_depth, sky=sky)
    chunks = [chunk_spp] * (spp // chunk_spp) + ([spp % chunk_spp] if spp % chunk_spp else [])
    acc = np.zeros((height, width, 3), np.float64)

    bar = tqdm(total=spp, unit="spp", desc=f"reference {scene.name} {width}x{height} depth {max_depth}",
               disable=not progress, leave=False)
    with bar:
        for k, n in enumerate(chunks):
            img = np.array(mi.render(mscene, spp=n, seed=int(seed) * 1_000_003 + k), dtype=np.float64)[..., :3]
            acc += np.nan_to_num(img, nan=0.0, posinf=np.inf, neginf=0.0) * n  # +inf: caught by the bound
            bar.update(n)
    with np.errstate(invalid="ignore", over="ignore"):
        img = (acc / spp).astype(np.float32)
    check_radiance_bound(img, scene, sky, what)
    if cache:
        _store(path, img)
    return img


# ------------------------------------------------------------------------------------------- noise floor


@dataclass
class Reference:
    """A reference rendered as two independent halves (module doc, Noise floor).

    image: (H, W, 3) float32, the mean of the halves; spp: its samples per pixel (both halves);
    floor: {"flip", "rel_mse"} between the halves (metrics of :mod:`serenity.eval.metrics`, the
    first half against the second); converged / message: :func:`reference_for_error`'s verdict
    (None / "" from :func:`reference_with_floor`); cached: nothing was rendered."""

    image: np.ndarray
    spp: int
    floor: dict
    halves: tuple = field(repr=False, default=())
    converged: bool | None = None
    message: str = ""
    cached: bool = False


def _half_seed(seed: int, half: int, block: int) -> int:
    """Seed of ``block`` of ``half`` (0 or 1): distinct from each other and from a plain reference's."""
    return (int(seed) * 64 + int(block)) * 2 + int(half) + 1


def _blocks(first: int, level: int) -> list[int]:
    """Samples of each block of a half at ``level``: first, first, 2·first, 4·first, … (sum first·2^level)."""
    return [first] + [first * 2 ** (j - 1) for j in range(1, level + 1)]


def _floor_of(a: np.ndarray, b: np.ndarray, exposure: float) -> dict:
    return {"flip": float(metrics.flip(a, b, exposure=exposure)), "rel_mse": float(metrics.rel_mse(a, b))}


def _reference_level(scene, width, height, first: int, level: int, seed: int, exposure: float, cache: bool,
                     **kw) -> Reference:
    halves, paths, cached = [], [], True
    blocks = _blocks(first, level)
    for h in (0, 1):
        acc = None
        for j, n in enumerate(blocks):
            info: dict = {}
            img = render_reference(scene, width, height, spp=n, seed=_half_seed(seed, h, j), cache=cache, info=info,
                                   **kw).astype(np.float64) * n
            paths += [os.path.basename(p) for p in info["cache_paths"]]
            cached = cached and info["cached"]
            acc = img if acc is None else acc + img
        halves.append((acc / sum(blocks)).astype(np.float32))
    key = hashlib.sha256(repr((sorted(paths), float(exposure))).encode()).hexdigest()
    floor_path = os.path.join(cache_dir(), f"{key}.floor.json")
    floor = None
    if cache:
        try:
            with open(floor_path) as f:
                floor = {k: float(v) for k, v in json.load(f)["floor"].items()}
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            floor = None
    if floor is None:
        floor = _floor_of(halves[0], halves[1], exposure)
        if cache:
            os.makedirs(cache_dir(), exist_ok=True)
            tmp = f"{floor_path}.{os.getpid()}.tmp"
            with open(tmp, "w") as f:
                json.dump({"scene": scene.name, "size": [width, height], "spp": 2 * sum(blocks),
                           "exposure": float(exposure), "floor": floor}, f)
            os.replace(tmp, floor_path)
    image = ((halves[0].astype(np.float64) + halves[1]) / 2).astype(np.float32)
    return Reference(image, 2 * sum(blocks), floor, tuple(halves), cached=cached)


def _exposure(exposure):
    return float(DEFAULT_EXPOSURE if exposure is None else exposure)


def reference_with_floor(scene, width: int, height: int, spp: int = 64, component: str = "full", seed: int = 0, *,
                         exposure: float | None = None, cache: bool = True, progress: bool = True,
                         **kw) -> Reference:
    """A reference of ``spp`` samples per pixel (even, ≥ 2) as two halves of ``spp/2`` with their
    noise floor (module doc); ``exposure`` is FLIP's (default: the renderer's). Other keywords
    (``max_depth``, ``sky_envmap``, ``chunk_spp``) as :func:`render_reference`'s."""
    if not int(spp) >= 2 or int(spp) % 2:
        raise SerenityError(f"a reference with its noise floor needs an even spp >= 2 (two halves), got {spp}")
    return _reference_level(scene, width, height, int(spp) // 2, 0, seed, _exposure(exposure), cache,
                            component=component, progress=progress, **kw)


def reference_for_error(scene, width: int, height: int, *, flip: float | None = None, rel_mse: float | None = None,
                        spp: int = 16, max_spp: int = 4096, component: str = "full", seed: int = 0,
                        exposure: float | None = None, cache: bool = True, progress: bool = True,
                        **kw) -> Reference:
    """A reference whose noise floor is at most a quarter of the error being measured: ``flip`` and/or
    ``rel_mse`` (the errors of an image against this reference). Starts at ``spp`` and doubles
    (every render cached; a larger request renders only the new blocks) until each given metric's
    floor ≤ error/4. When ``max_spp`` is reached first, the result has ``converged=False`` and a
    ``message`` naming the scene, the floor and the error, also given as a ``UserWarning``."""
    targets = {k: float(v) for k, v in (("flip", flip), ("rel_mse", rel_mse)) if v is not None}
    if not targets:
        raise SerenityError("reference_for_error needs the error being measured: flip= and/or rel_mse=")
    if any(not (v > 0 and math.isfinite(v)) for v in targets.values()):
        raise SerenityError(f"the errors being measured must be positive, got {targets}")
    if not int(spp) >= 2 or int(spp) % 2 or int(max_spp) < int(spp):
        raise SerenityError(f"spp must be even and >= 2 and max_spp >= spp, got spp {spp}, max_spp {max_spp}")
    first, level, exposure = int(spp) // 2, 0, _exposure(exposure)
    while True:
        ref = _reference_level(scene, width, height, first, level, seed, exposure, cache, component=component,
                               progress=progress, **kw)
        if all(ref.floor[k] <= v / 4 for k, v in targets.items()):
            ref.converged = True
            return ref
        if ref.spp * 2 > int(max_spp):
            worst = ", ".join(f"{k} floor {ref.floor[k]:.3g} > {v:.3g}/4" for k, v in targets.items()
                              if ref.floor[k] > v / 4)
            ref.converged = False
            ref.message = (f"reference of {scene.name!r} ({width}x{height}): noise floor not below a quarter of the "
                           f"error at {ref.spp} spp (max_spp {int(max_spp)}): {worst}")
            warnings.warn(ref.message, UserWarning, stacklevel=2)
            return ref
        level += 1

