"""TOML scene files: a mesh file plus everything a mesh file cannot say.

A scene file references one mesh file (glTF/GLB, OBJ, PLY; a path relative to the TOML file) and
sets the camera, the sun (by date, time and place, or by explicit angles), the sky, occlusion
quads and per-material overrides. Every table is optional except ``[scene].mesh``; what is not
given comes from :func:`serenity.scene.mesh_io.scene_from_meshes` (a camera framing the bounds,
the default sun and sky, no quads)::

    [scene]
    name = "courtyard"
    mesh = "courtyard.glb"

    [camera]                       # metres, world space (y up, +x east, -z north)
    position = [0.0, 1.7, 12.0]
    target = [0.0, 2.0, 0.0]
    fov_y_deg = 60.0               # full vertical field of view
    near = 0.1
    far = 300.0

    [sun]                          # either a time and place ...
    time = "2024-06-21 16:00 +01:00"
    latitude = 38.72               # degrees, north positive
    longitude = -9.14              # degrees, east positive
    # ... or elevation_deg = 45.0 / azimuth_deg = 135.0 (clockwise from north), or direction = [x, y, z]
    irradiance = [1000.0, 960.0, 900.0]   # W/m² per channel, facing the sun
    angular_diameter_deg = 0.53

    [sky]
    model = "atmosphere"           # or "constant"
    radiance = [20.0, 30.0, 45.0]  # W·m⁻²·sr⁻¹, the constant sky / ambient baseline

    [[occlusion_quads]]            # paper §7, Fig. 6
    center = [0.0, 5.0, -10.0]
    up = [0.0, 1.0, 0.0]
    right = [1.0, 0.0, 0.0]
    half_up = 5.0
    half_right = 10.0

    [materials.glass]              # override any field of a material named in the mesh file
    transparency = 0.9
    ior = 1.5
    albedo_texture = "glass.png"   # sRGB image, relative to the TOML file

    [[animation]]                  # rigid motion of a mesh (serenity.scene.animation)
    mesh = "car"                   # a mesh of the file (a glTF node's name)
    times = [0.0, 4.0]             # seconds of the keyframes
    translation = [[0.0, 0.0, 0.0], [12.0, 0.0, 0.0]]   # metres moved at each keyframe
    rotation_deg = [0.0, 90.0]     # optional: degrees about axis (default [0, 1, 0]) through pivot,
                                   # or rotation = quaternions [x, y, z, w]; scale = [[sx, sy, sz], ...]
    pivot = [0.0, 0.0, 0.0]        # optional: default the mesh's bounds centre as loaded
    interpolation = "linear"       # or "step"
    repeat = "loop"                # "once" (hold the last keyframe), "loop" or "pingpong"

Unknown tables or keys are errors (a typo must not be silently ignored). :func:`save_toml` writes
the exact values (sun as a direction, all material fields), so ``export_glb`` + ``save_toml``
load back identically.
"""

from __future__ import annotations

import math
import os
from dataclasses import fields

import numpy as np

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib

from serenity.errors import SceneError
from serenity.scene.animation import Animation, Track, axis_angle_quaternion
from serenity.scene.mesh_io import load_mesh_file, scene_from_meshes
from serenity.scene.model import Camera, Material, OcclusionQuad, Scene, Sky, Sun, direction_from_angles
from serenity.scene.sun import parse_time, sun_from_time
from serenity.scene.texture import load_texture

__all__ = ["load_toml", "save_toml"]

_TABLES = {"scene", "camera", "sun", "sky", "occlusion_quads", "materials", "animation"}
_ANIMATION_KEYS = {"mesh", "times", "translation", "rotation", "rotation_deg", "axis", "scale", "pivot",
                   "interpolation", "repeat"}
_CAMERA_KEYS = {"position", "target", "up", "fov_y_deg", "near", "far"}
_SUN_KEYS = {"time", "latitude", "longitude", "utc_offset", "elevation_deg", "azimuth_deg", "direction",
             "irradiance", "angular_diameter_deg"}
_SKY_KEYS = {"model", "radiance"}
_QUAD_KEYS = {"center", "up", "right", "half_up", "half_right"}
_MATERIAL_KEYS = {"albedo", "albedo_texture", "specular", "shininess", "reflectivity", "transparency", "ior", "alpha",
                  "alpha_cutoff", "double_sided", "normal_scale"}


def _check_keys(where: str, table, allowed: set[str]) -> None:
    if not isinstance(table, dict):
        raise SceneError(f"{where} must be a table")
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise SceneError(f"{where}: unknown key(s) {', '.join(unknown)} (allowed: {', '.join(sorted(allowed))})")


def load_toml(path) -> Scene:
    """Load a TOML scene file (see the module docstring for the format)."""
    path = os.fspath(path)
    try:
        with open(path, "rb") as f:
            doc = tomllib.load(f)
    except FileNotFoundError:
        raise SceneError(f"{path}: file not found") from None
    except tomllib.TOMLDecodeError as e:
        raise SceneError(f"{path}: not valid TOML ({e})") from None
    except UnicodeDecodeError:
        raise SceneError(f"{path}: not valid TOML (not UTF-8 text)") from None
    base = os.path.dirname(os.path.abspath(path))
    try:
        _check_keys("the file", doc, _TABLES)
        head = doc.get("scene", {})
        _check_keys("[scene]", head, {"name", "mesh"})
        if "mesh" not in head:
            raise SceneError("[scene] needs mesh = \"<file>\" (a .glb/.gltf/.obj/.ply path relative to this file)")
        mesh_path = os.path.join(base, str(head["mesh"]))
        if not os.path.exists(mesh_path):
            raise SceneError(f"[scene] mesh {head['mesh']!r}: file not found ({mesh_path})")
        meshes, materials = load_mesh_file(mesh_path)
        name = str(head.get("name", os.path.splitext(os.path.basename(path))[0]))

        by_name = {m.name: i for i, m in enumerate(materials)}
        overrides = doc.get("materials", {})
        _check_keys("[materials]", overrides, set(by_name) | set(overrides))
        for mname, over in overrides.items():
            if mname not in by_name:
                raise SceneError(f"[materials.{mname}]: no material of that name in {head['mesh']} "
                                 f"(it has: {', '.join(by_name) or 'none'})")
            _check_keys(f"[materials.{mname}]", over, _MATERIAL_KEYS)
            old = materials[by_name[mname]]
            kw = {f.name: getattr(old, f.name) for f in fields(Material)}
            for k, v in over.items():
                if k == "albedo_texture":
                    kw[k] = load_texture(os.path.join(base, str(v))) if v else None
                else:
                    kw[k] = v
            materials[by_name[mname]] = Material(**kw)

        scene = scene_from_meshes(name, meshes, materials, source=path)
        if "camera" in doc:
            cam = doc["camera"]
            _check_keys("[camera]", cam, _CAMERA_KEYS)
            if "position" not in cam or "target" not in cam:
                raise SceneError("[camera] needs position and target")
            scene.camera = Camera(**cam)
        if "sun" in doc:
            sd = dict(doc["sun"])
            _check_keys("[sun]", sd, _SUN_KEYS)
            ways = [k for k in ("time", "direction", "elevation_deg") if k in sd]
            if len(ways) > 1:
                raise SceneError(f"[sun]: give one of time, direction or elevation_deg/azimuth_deg, not {ways}")
            irr = sd.get("irradiance", scene.sun.irradiance)
            diam = float(sd.get("angular_diameter_deg", scene.sun.angular_diameter_deg))
            if "time" in sd:
                lat = sd.get("latitude", (scene.location or (None, None))[0])
                lon = sd.get("longitude", (scene.location or (None, None))[1])
                if lat is None or lon is None:
                    raise SceneError("[sun] time needs latitude and longitude")
                offset = sd.get("utc_offset")
                sun = sun_from_time(parse_time(str(sd["time"])), float(lat), float(lon), irr,
                                    utc_offset_hours=None if offset is None else float(offset))
                scene.location = (float(lat), float(lon))
                direction = sun.direction
            elif "direction" in sd:
                direction = sd["direction"]
            elif "elevation_deg" in sd:
                if "azimuth_deg" not in sd:
                    raise SceneError("[sun] elevation_deg needs azimuth_deg")
                el, az = float(sd["elevation_deg"]), float(sd["azimuth_deg"])
                if not (-90.0 <= el <= 90.0 and math.isfinite(az)):
                    raise SceneError(f"[sun] elevation_deg must be in [-90, 90], got {el}")
                direction = direction_from_angles(el, az)
            else:
                direction = scene.sun.direction
            scene.sun = Sun(direction, irradiance=irr, angular_diameter_deg=diam)
        if "sky" in doc:
            _check_keys("[sky]", doc["sky"], _SKY_KEYS)
            scene.sky = Sky(**doc["sky"])
        quads = doc.get("occlusion_quads", [])
        if not isinstance(quads, list):
            raise SceneError("occlusion_quads must be an array of tables ([[occlusion_quads]])")
        scene.occlusion_quads = []
        for i, q in enumerate(quads):
            _check_keys(f"[[occlusion_quads]] #{i + 1}", q, _QUAD_KEYS)
            missing = _QUAD_KEYS - set(q)
            if missing:
                raise SceneError(f"[[occlusion_quads]] #{i + 1}: missing {', '.join(sorted(missing))}")
            scene.occlusion_quads.append(OcclusionQuad(**q))
        scene.animation = _animation(doc.get("animation"))
        scene.validate()
        return scene
    except SceneError as e:
        msg = str(e)
        raise SceneError(msg if msg.startswith(path) else f"{path}: {msg}") from None
    except (TypeError, ValueError) as e:
        raise SceneError(f"{path}: {e}") from None


def _animation(tables) -> Animation | None:
    """The ``[[animation]]`` tracks (module docstring), or None."""
    if tables is None:
        return None
    if not isinstance(tables, list):
        raise SceneError("animation must be an array of tables ([[animation]])")
    tracks = []
    for i, a in enumerate(tables):
        where = f"[[animation]] #{i + 1}"
        _check_keys(where, a, _ANIMATION_KEYS)
        if "mesh" not in a or "times" not in a:
            raise SceneError(f"{where}: needs mesh and times")
        if "rotation" in a and "rotation_deg" in a:
            raise SceneError(f"{where}: give rotation (quaternions) or rotation_deg (angles about axis), not both")
        rotation = a.get("rotation")
        if "rotation_deg" in a:
            axis = np.asarray(a.get("axis", [0.0, 1.0, 0.0]), np.float64)
            if axis.shape != (3,) or not np.all(np.isfinite(axis)) or np.linalg.norm(axis) == 0:
                raise SceneError(f"{where}: axis must be a non-zero 3-vector, got {a.get('axis')!r}")
            rotation = [axis_angle_quaternion(axis, float(deg)) for deg in a["rotation_deg"]]
        try:
            tracks.append(Track(str(a["mesh"]), a["times"], a.get("translation"), rotation, a.get("scale"),
                                a.get("interpolation", "linear"), a.get("repeat", "once"), a.get("pivot")))
        except SceneError as e:
            raise SceneError(f"{where}: {e}") from None
    return Animation(tracks)


def _fmt(v) -> str:
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(_fmt(x) for x in np.asarray(v, dtype=np.float64).tolist()) + "]"
    return repr(float(v))  # repr round-trips float64 exactly


def save_toml(scene: Scene, path, mesh_file: str) -> None:
    """Write ``scene``'s camera, sun, sky, quads, animation and exact material values beside ``mesh_file``
    (a path relative to the TOML file, written separately by ``export_glb``). Albedo textures
    stay in the mesh file; the TOML does not override them."""
    lines = ["# Serenity scene file (see serenity/scene/toml_scene.py for the format)", "[scene]",
             f"name = {_fmt(scene.name)}", f"mesh = {_fmt(mesh_file)}", "", "[camera]"]
    cam = scene.camera
    for k in ("position", "target", "up", "fov_y_deg", "near", "far"):
        lines.append(f"{k} = {_fmt(getattr(cam, k))}")
    sun = scene.sun
    lines += ["", "[sun]", f"direction = {_fmt(sun.direction)}", f"irradiance = {_fmt(sun.irradiance)}",
              f"angular_diameter_deg = {_fmt(sun.angular_diameter_deg)}", "",
              "[sky]", f"model = {_fmt(scene.sky.model)}", f"radiance = {_fmt(scene.sky.radiance)}"]
    for q in scene.occlusion_quads:
        lines += ["", "[[occlusion_quads]]"] + [f"{k} = {_fmt(getattr(q, k))}" for k in
                                                ("center", "up", "right", "half_up", "half_right")]
    for t in (scene.animation.tracks if scene.animation is not None else []):
        lines += ["", "[[animation]]", f"mesh = {_fmt(t.mesh)}", f"times = {_fmt(t.times)}"]
        for k in ("translation", "rotation", "scale", "pivot"):
            value = getattr(t, k)
            if value is not None:
                rows = np.atleast_2d(value) if k != "pivot" else value
                lines.append(f"{k} = " + ("[" + ", ".join(_fmt(r) for r in rows) + "]" if k != "pivot" else _fmt(rows)))
        lines += [f"interpolation = {_fmt(t.interpolation.lower())}", f"repeat = {_fmt(t.repeat)}"]
    for m in scene.materials:
        lines += ["", f"[materials.{_fmt(m.name)}]"]
        lines += [f"{k} = {_fmt(getattr(m, k))}" for k in
                  ("albedo", "specular", "shininess", "reflectivity", "transparency", "ior")]
        if m.alpha_cutoff is not None:
            lines += [f"alpha = {_fmt(m.alpha)}", f"alpha_cutoff = {_fmt(m.alpha_cutoff)}"]
    with open(os.fspath(path), "w", encoding="utf-8") as f:
        f.write("\n".join(lines) + "\n")
