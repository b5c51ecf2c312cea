"""Blender Cycles (with its built-in Open Image Denoise) as a second path-tracing peer beside Mitsuba 3.

    from serenity.eval import cycles
    if cycles.available():
        peer = cycles.CyclesPeer(scene, 320, 180)
        curves = peer.curves([1, 2, 4, 8])      # {"cycles": [(spp, image, seconds), ...],
                                                #  "cycles+oidn-fast": [...], "cycles+oidn-accurate": [...]}

Blender's ``bpy`` pins a numpy that the project's environment cannot share (``bpy`` 5.0 needs numpy
1.x, the project numpy 2), so it cannot be an extra of ``pyproject.toml``: Cycles runs in a Python
of its own — ``.venv-cycles/bin/python`` at the top of the repository (``make cycles`` makes it), or
the interpreter named by ``$SERENITY_CYCLES_PYTHON`` — driven as a subprocess that runs
``cycles_worker.py`` beside this file. The scene goes over as files in a temporary folder (a JSON
description and an ``.npz`` of arrays), the images come back the same way. :func:`available` tells
whether such an interpreter exists; without one, :class:`CyclesPeer` raises a one-line
:class:`SerenityError` naming ``make cycles`` and the variable.

**The export** (:func:`export_scene`) is the Mitsuba export's (:mod:`serenity.eval.reference`),
item by item, in Blender's world (z up: ``(x, y, z)`` here is ``(x, -z, y)`` there, a rotation, so
north, -z, is Blender's +y and east stays +x):

- **Geometry**: one mesh per material (the reference's grouping), vertex normals as custom normals
  on smooth faces (Cycles shades with them, and shades both sides of a triangle as ``twosided``
  does), the uvs; a material's albedo and normal uv transforms are applied to uv layers of their
  own (exact: an affine map commutes with barycentric interpolation), the tangents come from the
  untransformed uvs as in the reference.
- **Phong**: ``Mix(k_s, Diffuse(ρ/(1 − k_s)), Glossy(Beckmann, white))`` — the reference's
  ``blendbsdf`` of a diffuse and a ``roughconductor`` with F = 1. Cycles squares its Glossy
  roughness input into the Beckmann α, so the input is √α with α = :func:`~serenity.eval.reference.phong_alpha`.
  The diffuse colour is exported unclamped, as the reference's raw bitmap is (the built-in glass).
- **Mirrors** ``Mix(R, surface, Glossy(roughness 0))``; **glass** ``Mix(T, surface, Glass(ior,
  roughness 0))`` whose surface is black on the back of a face (Cycles' Backfacing, the faces of
  glass wound as their vertex normals point), as the reference's one-sided opaque part of glass:
  light inside a pane is not reflected back out by it.
  **Normal maps**: a tangent-space Normal Map node reading the reference's baked bitmap (scale and
  uv frame in it) feeding every BSDF of the surface. **Cut-outs**: ``Mix(opacity, Transparent,
  surface)`` with the reference's opacity bitmap (1 where coverage reaches the cutoff).
  Textures are raw float images (no colour conversion), bilinear, repeating, row 0 = v 0.
- **Sky**: the reference's environment map (:func:`~serenity.eval.reference.sky_map`) in a World
  Environment Texture. Mitsuba reads column u at azimuth 2πu from north towards east; Blender's
  equirect lookup has u = ½ − atan2(y, x)/2π, which puts north at u = ¼ past Mitsuba's, so the
  map's columns are turned by a quarter of its width (:func:`blender_sky`) and its rows flipped
  (Blender's row 0 is the bottom, the nadir).
- **Sun**: a Blender sun lamp of strength = the sun's irradiance (Cycles' sun strength is the
  irradiance on a surface facing it, W·m⁻²; the colour carries the ratio of the channels), the
  angle of the disc (0.53°), shadows sampled over the disc, seen by camera and BSDF rays — the
  reference's calibrated sphere, without its 10⁻⁴ rad parallax. The irradiance is the renderer's
  (:func:`~serenity.eval.reference.with_effective_sun`), as the Mitsuba peer's. A sun below the
  horizon is left out.
- **Camera**: Blender's camera (looking down its -z, y up) at the same position and basis as
  ``Camera.primary_rays``, vertical sensor fit, the full vertical fov, the near and far planes; a
  1-pixel box filter (the reference's ``box``).
- **Film**: exposure 1, view transform "Standard" (no Filmic or AgX), output a float32 OpenEXR of
  the linear render, so the images are radiance in W·m⁻²·sr⁻¹ like the reference's.
- **Integrator**: CPU, all cores, no adaptive sampling, no clamping, no glossy filter, caustics on,
  no path guiding, :data:`MAX_BOUNCES` bounces of every kind (Cycles' Russian roulette ends paths
  long before; the reference has no limit).

**The runs** (``cycles_worker.py``): the scene is built once with persistent data on; per curve, one
warm-up render at 1 spp is reported apart (``warmup_seconds``), then each count is
a fresh render timed by the wall clock around ``bpy.ops.render.render`` (scene sync excluded by the
warm-up; the median of 3 renders below ``repeat_below_s``; the scene is tagged as changed before
each, as persistent data hands back the last result otherwise), denoised inside Cycles with its own
albedo and normal passes for the ``+oidn`` curves. Unlike the Mitsuba peer's progressive chunks,
each count is a render of its own: 1…64 spp costs the sum of all counts' renders to measure, but
each point's time is what one frame at that count costs.
"""

from __future__ import annotations

import functools
import json
import math
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from serenity.config import check_image_size
from serenity.errors import SerenityError
from serenity.eval.reference import meshes_by_material, phong_alpha, sky_map, with_effective_sun
from serenity.scene.model import IDENTITY_UV, apply_uv_transform, normal_map_frame

ENV_VAR = "SERENITY_CYCLES_PYTHON"
"""Names the interpreter with ``bpy`` (default: ``.venv-cycles/bin/python`` at the repository's top)."""
CURVES = {"cycles": "none", "cycles+oidn-fast": "fast", "cycles+oidn-accurate": "accurate"}
"""Curve name → the worker's denoiser mode: none, Open Image Denoise with the FAST or the ACCURATE prefilter."""
MAX_BOUNCES = 128
WORKER = Path(__file__).with_name("cycles_worker.py")
Y_UP_TO_Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
"""Serenity's world (y up, north -z) → Blender's (z up, north +y): a rotation about x by +90°."""
INSTALL_HINT = f"run `make cycles` or set {ENV_VAR} to a Python that has bpy"
SEED_BASE = 2**20
"""Cycles seed of the render at n spp: SEED_BASE + n (the warm-up: SEED_BASE - 1)."""

_AUTO = object()


class CyclesUnavailableError(SerenityError):
    """No interpreter with Blender's ``bpy`` was found (the message says how to get one)."""


# ------------------------------------------------------------------------------------ interpreter


def interpreter() -> Path:
    """The Python that runs Cycles: ``$SERENITY_CYCLES_PYTHON``, else ``.venv-cycles/bin/python`` at
    the repository's top (beside the ``serenity`` package), else the same under the working folder."""
    named = os.environ.get(ENV_VAR)
    if named:
        return Path(named)
    top = Path(__file__).resolve().parents[2] / ".venv-cycles" / "bin" / "python"
    here = Path.cwd() / ".venv-cycles" / "bin" / "python"
    return top if top.exists() or not here.exists() else here


@functools.lru_cache(maxsize=8)
def _check(python: str) -> str | None:
    """None when ``python`` imports bpy, else why not (one line)."""
    if not os.path.isfile(python):
        return f"no Cycles interpreter at {python}"
    try:
        p = subprocess.run([python, "-c", "import bpy, numpy"], capture_output=True, text=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"{python} does not run ({exc})"
    if p.returncode != 0:
        last = (p.stderr.strip().splitlines() or [f"exit status {p.returncode}"])[-1]
        return f"{python} cannot import bpy ({last})"
    return None


def available() -> bool:
    """True when the Cycles interpreter (:func:`interpreter`) exists and imports ``bpy``."""
    return _check(str(interpreter())) is None


def unavailable_reason() -> str:
    """Why :func:`available` is False, as one line naming what to do ("" when it is True)."""
    why = _check(str(interpreter()))
    return "" if why is None else f"Blender Cycles peer: {why}: {INSTALL_HINT}"


def require() -> Path:
    """The Cycles interpreter, or :class:`CyclesUnavailableError` (one line: ``make cycles``, the variable)."""
    python = interpreter()
    why = _check(str(python))
    if why is not None:
        raise CyclesUnavailableError(f"Blender Cycles peer: {why}: {INSTALL_HINT}")
    return python


# ------------------------------------------------------------------------------------------ export


def to_blender(v) -> np.ndarray:
    """Points or directions (..., 3) of Serenity's world in Blender's."""
    return np.asarray(v, np.float64) @ Y_UP_TO_Z_UP.T


def camera_matrix(camera) -> np.ndarray:
    """(4, 4) camera-to-world of Blender's camera (looks down its -z, y up) for ``camera``: the basis
    of ``Camera.primary_rays`` (right, up, forward), in Blender's world."""
    f = np.asarray(camera.forward, np.float64)
    r = np.cross(f, camera.up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = to_blender(r), to_blender(u), to_blender(-f), to_blender(camera.position)
    return m


def sun_matrix(direction) -> np.ndarray:
    """(4, 4) world matrix of a Blender sun lamp shining along -``direction`` (its local -z), where
    ``direction`` points towards the sun in Serenity's world."""
    z = to_blender(direction)
    z /= np.linalg.norm(z)
    helper = np.array([1.0, 0.0, 0.0]) if abs(z[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2] = x, np.cross(z, x), z
    return m


def blender_sky(sky: np.ndarray) -> np.ndarray:
    """The reference's equirect map ((H, W, 3), row 0 = zenith, column u at azimuth 2πu from north
    towards east) as Blender's Environment Texture reads it: (H, W, 4) float32, row 0 = the nadir,
    columns turned so that Blender's u (½ − atan2(y, x)/2π, Blender's world) sees the same
    direction: Blender's u = Mitsuba's u + ¼ (a quarter of the width, linearly interpolated where
    the width is not a multiple of 4)."""
    sky = np.asarray(sky, np.float64)[..., :3]
    w = sky.shape[1]
    shift = w / 4.0  # out[:, j] = sky[:, j - shift]
    whole, frac = int(math.floor(shift)), shift - math.floor(shift)
    out = np.roll(sky, whole, axis=1)
    if frac:
        out = (1.0 - frac) * out + frac * np.roll(out, 1, axis=1)
    rgba = np.ones(sky.shape[:2] + (4,), np.float32)
    rgba[..., :3] = out[::-1]
    return rgba


def blender_equirect_uv(d) -> np.ndarray:
    """(..., 2) uv of Blender's equirect lookup of directions ``d`` (Blender's world), v = 0 at the nadir."""
    d = np.asarray(d, np.float64)
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    u = (0.5 - np.arctan2(d[..., 1], d[..., 0]) / (2 * math.pi)) % 1.0
    v = 1.0 - np.arccos(np.clip(d[..., 2], -1.0, 1.0)) / math.pi
    return np.stack([u, v], axis=-1)


def _rgba(img) -> np.ndarray:
    """(H, W, C) → (H, W, 4) float32 with its rows flipped (the reference's bitmaps: row 0 = v 0)."""
    img = np.asarray(img, np.float32)
    out = np.ones(img.shape[:2] + (4,), np.float32)
    c = min(img.shape[2], 3)
    out[..., :3] = img[..., :c] if c == 3 else np.repeat(img[..., :1], 3, axis=2)
    return np.ascontiguousarray(out[::-1])


def _material(k: int, m, arrays: dict) -> dict:
    """A material's description for the worker (module doc); its images go into ``arrays``."""
    ks = float(m.specular)
    spec: dict = {"name": f"m{k}_{m.name}", "ks": ks, "roughness": math.sqrt(phong_alpha(m.shininess)),
                  "mirror": float(m.reflectivity), "glass": float(m.transparency), "ior": float(m.ior),
                  "albedo_uv": "uv" if np.array_equal(m.albedo_uv_transform, IDENTITY_UV) else "albedo_uv",
                  "normal_uv": "uv" if np.array_equal(m.normal_uv_transform, IDENTITY_UV) else "normal_uv",
                  "opacity": None, "normal_map": None}
    scale = 1.0 if ks <= 0.0 else (0.0 if ks >= 1.0 else 1.0 / (1.0 - ks))
    if m.albedo_texture is None:
        spec["diffuse"] = {"rgb": (np.asarray(m.albedo, np.float64) * scale).tolist()}
    else:
        img = np.asarray(m.albedo_texture.mips[0], np.float32)[..., :3] * m.albedo.astype(np.float32)
        arrays[f"albedo{k}"] = _rgba(np.maximum(img * np.float32(scale), 0.0))
        spec["diffuse"] = {"texture": f"albedo{k}"}
    if m.normal_texture is not None and m.transparency <= 0.0:
        n = np.asarray(m.normal_texture.mips[0], np.float64)[..., :3] * 2.0 - 1.0
        n[..., :2] = (n[..., :2] * m.normal_scale) @ normal_map_frame(m.normal_uv_transform).T
        n /= np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
        arrays[f"normal{k}"] = _rgba(n * 0.5 + 0.5)
        spec["normal_map"] = f"normal{k}"
    if m.alpha_tested:
        t = m.albedo_texture
        if t is None or t.channels < 4:
            spec["opacity"] = float(m.alpha >= m.alpha_cutoff)
        else:
            keep = (m.alpha * np.asarray(t.mips[0], np.float32)[..., 3] >= m.alpha_cutoff).astype(np.float32)
            arrays[f"opacity{k}"] = _rgba(keep[..., None])
            spec["opacity"] = f"opacity{k}"
    return spec


def _wound_as_normals(pos, nrm, faces) -> np.ndarray:
    """``faces`` with the corners of each triangle whose winding opposes its vertex normals swapped."""
    p = np.asarray(pos, np.float64)[faces]
    flip = np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), nrm[faces].sum(axis=1)) < 0
    out = np.array(faces, copy=True)
    out[flip] = out[flip][:, [0, 2, 1]]
    return out


def export_scene(scene, width: int, height: int, sky=_AUTO) -> tuple[dict, dict]:
    """(description, arrays) of ``scene`` for the worker (module doc): the description is JSON-able,
    the arrays go into an ``.npz``. ``sky``: an equirect map in the reference's layout, or None for
    a black sky (default: :func:`~serenity.eval.reference.sky_map` of the scene with the renderer's
    sun, as the Mitsuba peer uses). The sun is the renderer's
    (:func:`~serenity.eval.reference.with_effective_sun`)."""
    check_image_size(width, height)
    scene = with_effective_sun(scene)
    if sky is _AUTO:
        sky = sky_map(scene)
    arrays: dict = {}
    materials, meshes = [], []
    index: dict[int, int] = {}
    for k, pos, nrm, uv, faces in meshes_by_material(scene):
        m = scene.materials[k]
        if k not in index:
            index[k] = len(materials)
            materials.append(_material(k, m, arrays))
        spec = materials[index[k]]
        prefix = f"mesh{len(meshes)}_"
        arrays[prefix + "positions"] = to_blender(pos).astype(np.float32)
        arrays[prefix + "normals"] = to_blender(nrm).astype(np.float32)
        if m.transparency > 0.0:  # Cycles tells the back of a face by its winding, the reference by its normals
            faces = _wound_as_normals(pos, nrm, faces)
        arrays[prefix + "faces"] = np.asarray(faces, np.int32)
        arrays[prefix + "uv"] = np.asarray(uv, np.float32)
        layers = ["uv"]
        for layer, transform in (("albedo_uv", m.albedo_uv_transform), ("normal_uv", m.normal_uv_transform)):
            if spec[layer] == layer:
                arrays[prefix + layer] = apply_uv_transform(transform, uv).astype(np.float32)
                layers.append(layer)
        meshes.append({"name": f"m{k}", "prefix": prefix, "material": index[k], "uv_layers": layers})
    c = scene.camera
    desc: dict = {
        "scene": scene.name, "width": int(width), "height": int(height),
        "camera": {"matrix": camera_matrix(c).tolist(), "fov_y_deg": float(c.fov_y_deg), "near": float(c.near),
                   "far": float(c.far)},
        "sun": None, "sky": sky is not None, "materials": materials, "meshes": meshes,
        "images": sorted(k for k in arrays if not k.startswith("mesh")),
    }
    sun = scene.sun
    irr = np.asarray(sun.irradiance, np.float64)
    if sun.is_up and np.any(irr > 0):
        strength = float(irr.max())
        desc["sun"] = {"matrix": sun_matrix(sun.direction).tolist(), "strength": strength,
                       "color": (irr / strength).tolist(), "angle_deg": float(sun.angular_diameter_deg)}
    if sky is not None:
        arrays["sky"] = blender_sky(sky)
    return desc, arrays


# -------------------------------------------------------------------------------------------- peer


class CyclesPeer:
    """Blender Cycles on a Scene, timed: :meth:`curves` renders every sample count for each curve of
    :data:`CURVES` in one worker run (the scene is built and synced once).

    The scene is exported on construction (not timed, like the Mitsuba peer's load; ``sky`` as
    :func:`export_scene`'s); ``max_bounces``: of every kind (0: direct light only); ``python``: the
    interpreter with bpy (default :func:`interpreter`, checked: a missing one raises
    :class:`CyclesUnavailableError`). ``last_run`` holds the worker's report of the latest run
    (Blender version, threads, build and warm-up seconds, the denoiser's quality)."""

    def __init__(self, scene, width: int, height: int, *, python: str | None = None, sky=_AUTO,
                 max_bounces: int = MAX_BOUNCES, timeout_s: float = 3600.0):
        if python is None:
            python = require()
        else:
            why = _check(str(python))
            if why is not None:
                raise CyclesUnavailableError(f"Blender Cycles peer: {why}: {INSTALL_HINT}")
        self.python = str(python)
        self.width, self.height = int(width), int(height)
        self.name = scene.name
        self.description, self.arrays = export_scene(scene, self.width, self.height, sky)
        self.max_bounces, self.timeout_s = int(max_bounces), float(timeout_s)
        self.last_run: dict = {}

    def curves(self, spp_list, curves=tuple(CURVES), repeat_below_s: float = 1.0,
               seed: int = SEED_BASE) -> dict[str, list[tuple[int, np.ndarray, float]]]:
        """{curve: [(spp, (H, W, 3) float32 linear radiance, wall seconds), ...]} for the rising
        ``spp_list`` and each of ``curves`` (names of :data:`CURVES`); see the module doc for the timing."""
        spp_list = [int(n) for n in spp_list]
        if not spp_list or spp_list[0] < 1 or any(b <= a for a, b in zip(spp_list, spp_list[1:], strict=False)):
            raise SerenityError(f"spp counts must rise from >= 1, got {spp_list}")
        bad = [c for c in curves if c not in CURVES]
        if bad or not curves:
            raise SerenityError(f"Cycles curves must be among {', '.join(CURVES)}, got {list(curves)}")
        modes = [CURVES[c] for c in curves]
        job = {**self.description, "spp": spp_list, "modes": modes, "seed": int(seed),
               "repeat_below_s": float(repeat_below_s), "max_bounces": self.max_bounces}
        result, images = self._run(job)
        out = {}
        for c, mode in zip(curves, modes, strict=True):
            out[c] = [(n, np.nan_to_num(images[f"{mode}_{n}"], nan=0.0, posinf=0.0, neginf=0.0).astype(np.float32),
                       float(s)) for n, s in zip(spp_list, result["seconds"][mode], strict=True)]
        self.last_run = {**{k: v for k, v in result.items() if k != "seconds"},
                         "warmup_seconds": {c: result["warmup_seconds"][CURVES[c]] for c in curves}}
        return out

    def render(self, spp: int, curve: str = "cycles", seed: int = SEED_BASE) -> tuple[np.ndarray, float]:
        """One image at ``spp`` samples per pixel of one curve, and its wall seconds (a worker run of its own)."""
        if int(spp) < 1:
            raise SerenityError(f"spp must be >= 1, got {spp}")
        ((_, img, s),) = self.curves([int(spp)], (curve,), repeat_below_s=0.0, seed=seed)[curve]
        return img, s

    def _run(self, job: dict) -> tuple[dict, dict]:
        tmp = tempfile.mkdtemp(prefix="serenity-cycles-")
        try:
            with open(os.path.join(tmp, "job.json"), "w") as f:
                json.dump(job, f)
            np.savez(os.path.join(tmp, "arrays.npz"), **self.arrays)
            try:
                p = subprocess.run([self.python, str(WORKER), tmp], capture_output=True, text=True,
                                   timeout=self.timeout_s, cwd=tmp)
            except subprocess.TimeoutExpired:
                raise SerenityError(f"Blender Cycles peer: {self.name!r} did not finish within {self.timeout_s:g} s") \
                    from None
            if p.returncode != 0:
                lines = [ln for ln in (p.stderr + p.stdout).strip().splitlines() if ln.strip()]
                raise SerenityError(f"Blender Cycles peer: rendering {self.name!r} failed (exit {p.returncode}): "
                                    f"{lines[-1] if lines else 'no output'}")
            with open(os.path.join(tmp, "result.json")) as f:
                result = json.load(f)
            with np.load(os.path.join(tmp, "images.npz")) as z:
                images = {k: np.asarray(z[k], np.float32) for k in z.files}
            return result, images
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
