"""Mesh files through trimesh: glTF/GLB, OBJ (+ MTL) and PLY in, GLB out.

``load_mesh_file(path)`` gives the meshes and materials of a file; ``scene_from_meshes`` puts bare
geometry in a scene (a camera framing its bounds (:func:`frame_bounds`), the sun at
:data:`~serenity.scene.sun.DEFAULT_TIME` in :data:`~serenity.scene.sun.DEFAULT_LOCATION`, the
default sky and no occlusion quads); ``export_glb(scene, path)`` writes a scene back out.
:func:`serenity.scene.loaders.load` is the dispatcher that picks this, a TOML scene file or a
built-in scene.

Conversion of a trimesh scene: every node instance of a triangle geometry becomes one
:class:`Mesh` named after the node, in file order, with the node's world transform applied
(normals by the inverse transpose, winding flipped for mirroring transforms). Vertices, normals
(the file's, or trimesh's when the file has none) and uvs are kept as they are (trimesh already
flips glTF's v so that v points up). Point clouds and lines are ignored.

Degenerate triangles — repeated indices or zero area (twice the area ≤ (1e-7 × bounds diagonal)²)
— are dropped with a ``UserWarning`` giving their count; the scene still loads.

An image that a .gltf names by a relative ``uri`` must exist: a missing one is a one-line error.

Materials become the model's (Phong + mirror + glass) as :mod:`serenity.scene.mesh_materials`
documents (glTF metallic-roughness and its extensions, OBJ/MTL, files without materials).

``export_glb(scene, path)`` writes the geometry, materials (the inverse of the glTF mapping,
colours quantised to 8 bits by trimesh) and albedo textures (8-bit sRGB PNG). The companion TOML
written by :func:`serenity.scene.toml_scene.save_toml` carries the exact material values, camera,
sun, sky and occlusion quads, so GLB + TOML load back identically.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import pickle
import struct
import warnings
from pathlib import Path
from urllib.parse import unquote

import numpy as np

from serenity.errors import SceneError, first_line
from serenity.io.atomic import atomic_write
from serenity.scene import mesh_materials as _materials_module
from serenity.scene import model as _model_module
from serenity.scene import texture as _texture_module
from serenity.scene.cache import cache_dir
from serenity.scene.mesh_materials import MaterialConverter, gltf_phong_split, gltf_uv_transform, pbr_from_material
from serenity.scene.model import Camera, Material, Mesh, Scene, Sky, vertex_normals
from serenity.scene.sun import DEFAULT_LOCATION, DEFAULT_TIME, sun_from_time

__all__ = ["MESH_EXTENSIONS", "load_mesh_file", "scene_from_meshes", "frame_bounds", "export_glb", "gltf_phong_split",
           "gltf_uv_transform"]

MESH_EXTENSIONS = (".glb", ".gltf", ".obj", ".ply")
_DEGENERATE_REL = 1e-7


def scene_from_meshes(name: str, meshes: list[Mesh], materials: list[Material], source: str | None = None) -> Scene:
    """A scene around bare geometry: framing camera, default sun/time/place and sky, no occlusion quads."""
    bounds = _bounds_of(meshes, source or name)
    try:
        return Scene(name, meshes, materials, frame_bounds(bounds), sun_from_time(DEFAULT_TIME, *DEFAULT_LOCATION),
                     Sky(), [], source=source, location=DEFAULT_LOCATION)
    except SceneError as e:
        raise SceneError(f"{source}: {e}" if source else str(e)) from None


def frame_bounds(bounds, fov_y_deg: float = 50.0, direction=(0.55, 0.45, 0.70)) -> Camera:
    """A camera that sees the whole (2,3) box ``bounds``: it looks at the centre from ``direction``
    (default: from the south-east, above), at the distance where the bounding sphere fits the
    vertical field of view; near/far enclose the sphere."""
    b = np.asarray(bounds, dtype=np.float64).reshape(2, 3)
    c = 0.5 * (b[0] + b[1])
    r = max(0.5 * float(np.linalg.norm(b[1] - b[0])), 1e-3)
    d = np.asarray(direction, dtype=np.float64)
    d = d / np.linalg.norm(d)
    dist = r / math.sin(math.radians(fov_y_deg) / 2) * 1.05
    near = max((dist - r) * 0.5, dist * 1e-4)
    return Camera(position=c + d * dist, target=c, fov_y_deg=fov_y_deg, near=near, far=(dist + r) * 2.0)


def _bounds_of(meshes: list[Mesh], where: str) -> np.ndarray:
    pts = [m.positions[np.unique(m.faces)] for m in meshes if m.triangle_count]
    if not pts:
        raise SceneError(f"{where}: contains no triangles")
    p = np.concatenate(pts)
    return np.stack([p.min(axis=0), p.max(axis=0)]).astype(np.float64)


# --------------------------------------------------------------------------------------------- reading


def _gltf_json(path: str) -> dict:
    """The JSON of a .gltf/.glb (for exact material factors and extensions); {} if unreadable."""
    try:
        with open(path, "rb") as f:
            data = f.read()
        if path.lower().endswith(".glb"):
            if len(data) < 20 or data[:4] != b"glTF":
                return {}
            n, kind = struct.unpack("<II", data[12:20])
            if kind != 0x4E4F534A:  # "JSON"
                return {}
            return json.loads(data[20:20 + n].decode("utf-8"))
        return json.loads(data.decode("utf-8"))
    except (OSError, ValueError, UnicodeDecodeError, struct.error):
        return {}


def _gltf_materials_by_name(js: dict) -> dict[str, dict]:
    mats = js.get("materials") or []
    names = [m.get("name") for m in mats if isinstance(m, dict)]
    out = {}
    for m in mats:
        if isinstance(m, dict) and m.get("name") and names.count(m.get("name")) == 1:
            out[m["name"]] = m
    return out


def _check_readable_gltf(path: str) -> None:
    """Refuse garbage .glb files up front with a clear message (trimesh's errors are cryptic)."""
    if not path.lower().endswith(".glb"):
        return
    with open(path, "rb") as f:
        head = f.read(20)
    if len(head) < 20 or head[:4] != b"glTF":
        raise SceneError(f"{path}: not a valid GLB file (missing 'glTF' header)")
    version, length = struct.unpack("<II", head[4:12])
    if version != 2:
        raise SceneError(f"{path}: unsupported GLB version {version} (only glTF 2.0)")
    if length != os.path.getsize(path):
        raise SceneError(f"{path}: corrupt GLB file (header says {length} bytes, file has {os.path.getsize(path)})")


def _check_gltf_images(path: str, js: dict) -> None:
    """A texture's image given by a relative file ``uri`` must exist (trimesh drops it silently)."""
    images = js.get("images") or []
    base = os.path.dirname(os.path.abspath(path))
    for tex in js.get("textures") or []:
        src = tex.get("source") if isinstance(tex, dict) else None
        if not isinstance(src, int) or not (0 <= src < len(images)) or not isinstance(images[src], dict):
            continue
        uri = images[src].get("uri")
        if isinstance(uri, str) and uri and not uri.startswith("data:"):
            f = os.path.join(base, unquote(uri))
            if not os.path.isfile(f):
                raise SceneError(f"{path}: texture image {uri!r} not found ({f})")


#: a glTF whose files (the .gltf or .glb, its buffers and images) hold at least this many bytes is
#: cached on disk once read (``_mesh_cache_path``)
MESH_CACHE_MIN_BYTES = 1 << 20
#: bump when what the cache holds changes in a way its key does not see
MESH_CACHE_VERSION = 1


def load_mesh_file(path) -> tuple[list[Mesh], list[Material]]:
    """Meshes and materials of a .glb/.gltf/.obj/.ply file (see the module docstring).

    A big glTF (``MESH_CACHE_MIN_BYTES``) is read back from the disk cache (``cache_dir()``, a pickle of
    what this returns and the warnings it gave, keyed by the bytes of the file, its buffers and
    images and of the loader's code) when it was read before: neither trimesh (and scipy) is
    imported nor a texture decoded again (most of the breakfast room's second of loading)."""
    path = os.fspath(path)
    ext = os.path.splitext(path)[1].lower()
    if ext not in MESH_EXTENSIONS:
        raise SceneError(f"{path}: unsupported mesh file type {ext!r} (supported: {', '.join(MESH_EXTENSIONS)})")
    if not os.path.isfile(path):
        raise SceneError(f"{path}: file not found")
    _check_readable_gltf(path)
    js = _gltf_json(path) if ext in (".glb", ".gltf") else {}
    _check_gltf_images(path, js)
    cached = _mesh_cache_path(path, js) if ext in (".glb", ".gltf") else None
    hit = _read_mesh_cache(cached)
    if hit is None:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            meshes, materials = _read_mesh_file(path, ext, js)
        notes = [str(w.message) for w in caught if issubclass(w.category, UserWarning)]
        for w in caught:
            if not issubclass(w.category, UserWarning):
                warnings.warn(w.message, w.category, stacklevel=2)
        _write_mesh_cache(cached, (meshes, materials, notes))
    else:
        meshes, materials, notes = hit
    for text in notes:
        warnings.warn(text, UserWarning, stacklevel=2)
    return meshes, materials


def _mesh_cache_path(path: str, js: dict) -> Path | None:
    """Where the read meshes of the glTF at ``path`` (its JSON ``js``) are cached: a digest of its bytes,
    of every file its buffers and images name, and of the loader's own source; None below
    ``MESH_CACHE_MIN_BYTES`` or where a file cannot be read (then nothing is cached)."""
    h = hashlib.blake2b(digest_size=20)
    h.update(f"mesh-v{MESH_CACHE_VERSION}".encode())
    base = os.path.dirname(path)
    files = [path] + [os.path.join(base, unquote(item["uri"])) for key in ("buffers", "images")
                      for item in js.get(key, ()) if isinstance(item, dict) and isinstance(item.get("uri"), str)
                      and item["uri"] and not item["uri"].startswith("data:")]
    code = [m.__file__ for m in (_model_module, _texture_module, _materials_module)] + [__file__]
    total = 0
    try:
        for f in code + files:
            if f in files[1:] and not os.path.isfile(f):  # named but absent (an unused image: a .dds
                h.update(f"absent {f}".encode())  # beside the .jpg the texture reads): so it stays
                continue
            with open(f, "rb") as fh:
                data = fh.read()
            total += len(data) if f not in code else 0
            h.update(len(data).to_bytes(8, "little"))
            h.update(data)
    except (OSError, TypeError):
        return None
    if total < MESH_CACHE_MIN_BYTES:
        return None
    return cache_dir() / f"mesh-{h.hexdigest()}.pickle"


def _read_mesh_cache(path: Path | None):
    """(meshes, materials, warnings) cached at ``path``; None when absent or unreadable."""
    if path is None or not path.is_file():
        return None
    try:
        with open(path, "rb") as f:
            hit = pickle.load(f)
    except Exception:  # a truncated or foreign file: read the mesh file again
        return None
    if not (isinstance(hit, tuple) and len(hit) == 3 and all(isinstance(x, list) for x in hit)
            and all(isinstance(m, Mesh) for m in hit[0]) and all(isinstance(m, Material) for m in hit[1])):
        return None
    return hit


def _write_mesh_cache(path: Path | None, value) -> None:
    """Cache ``value`` at ``path`` (written aside, then moved into place); an unwritable cache is ignored."""
    if path is None:
        return

    def write(tmp):
        with open(tmp, "wb") as f:
            pickle.dump(value, f, protocol=pickle.HIGHEST_PROTOCOL)

    try:
        atomic_write(path, write)
    except (OSError, pickle.PicklingError):
        pass


def _read_mesh_file(path: str, ext: str, js: dict) -> tuple[list[Mesh], list[Material]]:
    """:func:`load_mesh_file` through trimesh (checked: the file exists and is of a known type)."""
    import trimesh  # here: trimesh (and scipy) take most of a second to import, a tracer process needs neither

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            tm = trimesh.load(path, force="scene", process=False)
    except SceneError:
        raise
    except Exception as e:  # trimesh raises anything from KeyError to struct.error on bad files
        raise SceneError(f"{path}: cannot read the {ext[1:].upper()} file ({first_line(e)})") from None
    gltf = _gltf_materials_by_name(js)

    order = {g: i for i, g in enumerate(tm.geometry.keys())}
    nodes = []
    for node in tm.graph.nodes_geometry:
        transform, gname = tm.graph[node]
        g = tm.geometry.get(gname)
        if isinstance(g, trimesh.Trimesh) and len(g.faces):
            nodes.append((order.get(gname, 0), str(node), np.asarray(transform, dtype=np.float64), g))
    nodes.sort(key=lambda t: (t[0], t[1]))

    converter = MaterialConverter(path, gltf)
    raw = []
    all_pts = []
    for _, node, transform, g in nodes:
        v = np.asarray(g.vertices, dtype=np.float64)
        bad = ~np.isfinite(v).all(axis=1)
        if bad.any():
            raise SceneError(f"{path}: mesh {node!r} has {int(bad.sum())} vertices with NaN or infinite coordinates")
        raw.append((node, transform, g, v))
        all_pts.append(v @ transform[:3, :3].T + transform[:3, 3])
    if not raw:
        raise SceneError(f"{path}: contains no triangles")
    pts = np.concatenate(all_pts)
    if not np.all(np.isfinite(pts)):
        raise SceneError(f"{path}: node transforms produce NaN or infinite coordinates")
    diag = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    eps2 = (max(diag, 1e-30) * _DEGENERATE_REL) ** 2

    meshes: list[Mesh] = []
    dropped = 0
    for node, transform, g, v in raw:
        f = np.asarray(g.faces, dtype=np.int64)
        if f.min() < 0 or f.max() >= len(v):
            raise SceneError(f"{path}: mesh {node!r} has face indices out of range")
        m3, t3 = transform[:3, :3], transform[:3, 3]
        pos = v @ m3.T + t3
        nrm = _normals_of(g, v, f)
        if not np.allclose(m3, np.eye(3)):
            try:
                nrm = nrm @ np.linalg.inv(m3)
            except np.linalg.LinAlgError:
                raise SceneError(f"{path}: node {node!r} has a singular transform") from None
            ln = np.linalg.norm(nrm, axis=1, keepdims=True)
            nrm = np.where(ln > 1e-20, nrm / np.maximum(ln, 1e-30), [0.0, 1.0, 0.0])
            if np.linalg.det(m3) < 0:
                f = f[:, ::-1]
        area2 = np.linalg.norm(np.cross(pos[f[:, 1]] - pos[f[:, 0]], pos[f[:, 2]] - pos[f[:, 0]]), axis=1)
        keep = (area2 > eps2) & (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
        dropped += int(len(f) - keep.sum())
        f = f[keep]
        if not len(f):
            continue
        uv = _uvs_of(g, len(v))
        mat_index = converter.index_for(g, node)
        try:
            meshes.append(Mesh(node, pos, nrm, uv, f, np.full(len(f), mat_index)))
        except SceneError as e:
            raise SceneError(f"{path}: {e}") from None
    if dropped:
        warnings.warn(f"{path}: dropped {dropped} degenerate (zero-area) triangles", UserWarning, stacklevel=2)
    if not meshes:
        raise SceneError(f"{path}: contains no triangles (all {dropped} are degenerate)")
    return meshes, converter.materials


def _normals_of(g, v: np.ndarray, f: np.ndarray) -> np.ndarray:
    try:
        n = np.asarray(g.vertex_normals, dtype=np.float64)
    except Exception:  # trimesh cannot compute them (e.g. all faces degenerate)
        n = None
    if n is None or n.shape != v.shape:
        return vertex_normals(v, f).astype(np.float64)
    ln = np.linalg.norm(n, axis=1)
    bad = ~np.isfinite(ln) | (ln < 1e-12)
    if bad.any():
        n = n.copy()
        n[bad] = vertex_normals(v, f)[bad]
        ln = np.linalg.norm(n, axis=1)
    return n / ln[:, None]


def _uvs_of(g, nverts: int) -> np.ndarray:
    uv = getattr(g.visual, "uv", None)
    if uv is None:
        return np.zeros((nverts, 2), np.float32)
    uv = np.asarray(uv, dtype=np.float64)
    if uv.shape != (nverts, 2):
        return np.zeros((nverts, 2), np.float32)
    return np.where(np.isfinite(uv), uv, 0.0).astype(np.float32)


# --------------------------------------------------------------------------------------------- writing


def export_glb(scene: Scene, path) -> None:
    """Write ``scene``'s meshes, materials and textures as a binary glTF (GLB) file.

    One glTF mesh per (Mesh, material) pair, faces in their original order (a single-material
    mesh keeps its vertex order too), named after the Mesh (``MESH.MATERIAL`` when a Mesh has
    several materials). Identity node transforms.
    """
    import trimesh
    from trimesh.visual import TextureVisuals

    path = os.fspath(path)
    out = trimesh.Scene()
    pbr = [pbr_from_material(m) for m in scene.materials]
    used_names: set[str] = set()
    for mesh in scene.meshes:
        mats = list(dict.fromkeys(mesh.face_material.tolist()))
        for mi in mats:
            sel = mesh.face_material == mi
            faces = mesh.faces[sel]
            used, inverse = np.unique(faces, return_inverse=True)
            faces = inverse.reshape(-1, 3)
            name = mesh.name if len(mats) == 1 else f"{mesh.name}.{scene.materials[mi].name}"
            base, k = name, 1
            while name in used_names:
                k += 1
                name = f"{base}_{k}"
            used_names.add(name)
            geom = trimesh.Trimesh(
                vertices=mesh.positions[used].astype(np.float64), faces=faces,
                vertex_normals=mesh.normals[used].astype(np.float64),
                visual=TextureVisuals(uv=mesh.uvs[used].astype(np.float64), material=pbr[mi]),
                process=False, validate=False,
            )
            out.add_geometry(geom, geom_name=name, node_name=name)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    data = out.export(file_type="glb")
    with open(path, "wb") as f:
        f.write(data)
