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

Material mapping (documented approximations; the renderer is Phong + mirror + glass):

glTF metallic-roughness (m = metallicFactor, r = roughnessFactor, glTF defaults 1 and 1):
- base = baseColorFactor.rgb (linear, exact from the file's JSON when the material name is unique,
  else trimesh's 8-bit copy); albedo_texture = baseColorTexture decoded sRGB → linear with mips.
- shininess n = 2/α² − 2 with α = r² (the Blinn-Phong ↔ Beckmann correspondence), in [1, 10000].
- energy-conserving split into the Phong model's diffuse ρ (per channel) and scalar k_s, with
  F0 = 0.04 (a dielectric's reflectance at normal incidence) and g = 1 − r the fraction of the
  specular energy kept as a glossy lobe (a lobe as wide as a rough material's is nearly Lambertian,
  and our indirect light only follows the diffuse term, so the rest is spread as diffuse):

      k_s = g·((1 − m)·F0 + m·lum(base))
      ρ   = albedo = base·((1 − m)·(1 − g·F0) + m·(1 − g))

  A metal reflects its base colour and transmits nothing into a diffuse layer; the model's k_s is
  grey, so the metal's glossy share carries the base's luminance and the share spread by roughness
  keeps its colour (a rough metal is its base colour, diffusely; a grey metal reflects exactly its
  base). Per channel ρ + k_s is a convex mix of (1 − m)·(base(1 − gF0) + gF0) and
  m·(base(1 − g) + g·lum(base)), so ρ + k_s ≤ 1 whenever base ≤ 1: no material reflects more than
  it receives (keeping a metal's base colour as ρ beside a k_s near 1 reflected up to 1.6 of the
  light and made closed rooms diverge in the path-traced reference). A dielectric keeps its base
  as ρ where it is rough (g = 0) and loses the g·F0 its specular lobe takes where it is not.
- mirror: when m ≥ 0.5 and r ≤ 0.2, reflectivity = m·(1 − r/0.2)·max(baseColor.rgb).
- glass: transparency = KHR_materials_transmission's transmissionFactor, or 1 − alpha for
  alphaMode BLEND with alpha < 1; ior = KHR_materials_ior's ior (default 1.5), clamped to [1, 4].
- cut-outs: alphaMode MASK gives alpha = baseColorFactor.a and alpha_cutoff = alphaCutoff (default
  0.5); the alpha test reads the base colour texture's alpha channel (:attr:`Material.alpha_cutoff`).
- doubleSided is kept as :attr:`Material.double_sided` (every pass shades and casts both sides).
- normalTexture (decoded linear, no sRGB) with its ``scale`` → normal_texture, normal_scale.
- KHR_texture_transform on baseColorTexture / normalTexture → albedo_uv_transform /
  normal_uv_transform (offset, rotation, scale; converted to the v-up uvs). Only TEXCOORD_0 is
  read: a texCoord of 1 warns and uses set 0.
- KHR_materials_specular: the dielectric reflectance at normal incidence F0 = ((ior − 1)/(ior + 1))²
  (0.04 at ior 1.5) becomes min(F0 · max(specularColorFactor), 1) · specularFactor in the k_s and ρ
  formulas above (its textures are not read).
- an image a .gltf names by a relative ``uri`` must exist: a missing one is a one-line error.

OBJ/MTL: albedo = Kd (taken as linear), albedo_texture = map_Kd (sRGB); specular = max(Ks);
shininess = Ns (≥ 1); transparency = 1 − d (or Tr); ior = Ni; illum 3, 5 or 7 (ray-traced
reflection) makes a mirror with reflectivity = max(Ks).

PLY and other files without materials: one grey material (albedo 0.8), or, with vertex/face
colours, one material per mesh whose albedo is their mean (sRGB-decoded) — the model has no
per-vertex colour.

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
from PIL import Image

from serenity.colour import LUMA_REC709, srgb_to_linear
from serenity.errors import SceneError
from serenity.io.atomic import atomic_write
from serenity.scene import model as _model_module
from serenity.scene import texture as _texture_module
from serenity.scene.cache import cache_dir
from serenity.scene.model import IDENTITY_UV, Camera, Material, Mesh, Scene, Sky, Texture, vertex_normals
from serenity.scene.sun import DEFAULT_LOCATION, DEFAULT_TIME, sun_from_time
from serenity.scene.texture import texture_from_image, texture_to_srgb8

__all__ = ["MESH_EXTENSIONS", "load_mesh_file", "scene_from_meshes", "frame_bounds", "export_glb", "gltf_phong_split"]

MESH_EXTENSIONS = (".glb", ".gltf", ".obj", ".ply")
_DEFAULT_ALBEDO = 0.8
_DEGENERATE_REL = 1e-7


def _one_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    msg = text[0] if text else ""
    return f"{type(e).__name__}: {msg}"[:200] if msg else type(e).__name__


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
    code = [m.__file__ for m in (_model_module, _texture_module)] + [__file__]
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
        raise SceneError(f"{path}: cannot read the {ext[1:].upper()} file ({_one_line(e)})") from None
    gltf = _gltf_materials_by_name(js)

    order = {g: i for i, g in enumerate(tm.geometry.keys())}
    nodes = []
    for node in tm.graph.nodes_geometry:
        transform, gname = tm.graph[node]
        g = tm.geometry.get(gname)
        if isinstance(g, trimesh.Trimesh) and len(g.faces):
            nodes.append((order.get(gname, 0), str(node), np.asarray(transform, dtype=np.float64), g))
    nodes.sort(key=lambda t: (t[0], t[1]))

    converter = _MaterialConverter(path, gltf)
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


def _rgba01(c) -> np.ndarray | None:
    if c is None:
        return None
    a = np.asarray(c, dtype=np.float64).reshape(-1)
    if a.size < 3:
        return None
    if np.issubdtype(np.asarray(c).dtype, np.integer) or a.max() > 1.0:
        a = a / 255.0
    if a.size == 3:
        a = np.append(a, 1.0)
    return np.clip(a[:4], 0.0, 1.0)


def _float_list(v) -> list[float] | None:
    if v is None:
        return None
    if isinstance(v, (int, float)):
        return [float(v)]
    try:
        return [float(x) for x in v]
    except (TypeError, ValueError):
        return None


class _MaterialConverter:
    """trimesh materials → unique :class:`Material` s (deduplicated by identity, then by content)."""

    def __init__(self, path: str, gltf: dict[str, dict]):
        self.path = path
        self.gltf = gltf
        self.materials: list[Material] = []
        self._by_id: dict[int, int] = {}
        self._textures: dict[int, Texture] = {}

    def index_for(self, g, node: str) -> int:
        visual = g.visual
        mat = getattr(visual, "material", None)
        if mat is not None and id(mat) in self._by_id:
            return self._by_id[id(mat)]
        from trimesh.visual.color import ColorVisuals
        from trimesh.visual.material import PBRMaterial, SimpleMaterial

        if isinstance(mat, PBRMaterial):
            m = self._from_pbr(mat)
        elif isinstance(mat, SimpleMaterial):
            m = self._from_mtl(mat)
        elif isinstance(visual, ColorVisuals) and visual.kind is not None:
            cols = np.asarray(visual.vertex_colors if visual.kind == "vertex" else visual.face_colors, np.float64)
            albedo = srgb_to_linear(cols[:, :3].mean(axis=0) / 255.0)
            m = Material(f"{node}_colour", albedo=albedo)
        else:
            m = Material("default", albedo=(_DEFAULT_ALBEDO,) * 3)
        idx = self._add(m)
        if mat is not None:
            self._by_id[id(mat)] = idx
        return idx

    def _add(self, m: Material) -> int:
        base, k = m.name, 1
        while True:
            same_name = [i for i, other in enumerate(self.materials) if other.name == m.name]
            if not same_name:
                self.materials.append(m)
                return len(self.materials) - 1
            if _same_material(self.materials[same_name[0]], m):
                return same_name[0]
            k += 1
            m.name = f"{base}_{k}"

    def _texture(self, image, label: str, srgb: bool = True) -> Texture | None:
        if image is None:
            return None
        key = (id(image), srgb)
        if key not in self._textures:
            try:
                self._textures[key] = texture_from_image(image, name=f"{self.path}:{label}", srgb=srgb)
            except Exception as e:
                raise SceneError(f"{self.path}: texture of material {label!r} cannot be decoded ({_one_line(e)})") \
                    from None
        return self._textures[key]

    def _uv_transform(self, info, material: str) -> np.ndarray:
        """KHR_texture_transform of a textureInfo as a (2, 3) map of v-up uvs (module docstring)."""
        tt = ((info or {}).get("extensions") or {}).get("KHR_texture_transform") if isinstance(info, dict) else None
        tex_coord = int(info.get("texCoord", 0)) if isinstance(info, dict) else 0
        if isinstance(tt, dict) and "texCoord" in tt:
            tex_coord = int(tt["texCoord"])
        if tex_coord != 0:
            warnings.warn(f"{self.path}: material {material!r} reads TEXCOORD_{tex_coord}; only TEXCOORD_0 is "
                          "loaded and used instead", UserWarning, stacklevel=4)
        if not isinstance(tt, dict):
            return IDENTITY_UV.copy()
        try:
            return gltf_uv_transform(tt.get("offset", (0.0, 0.0)), tt.get("rotation", 0.0), tt.get("scale", (1.0, 1.0)))
        except (TypeError, ValueError) as e:
            raise SceneError(f"{self.path}: material {material!r} has a bad KHR_texture_transform ({e})") from None

    def _from_pbr(self, mat) -> Material:
        name = mat.name or f"material_{len(self.materials)}"
        js = self.gltf.get(mat.name or "", {})
        pbr = js.get("pbrMetallicRoughness", {}) if js else {}
        rgba = _rgba01(pbr.get("baseColorFactor")) if "baseColorFactor" in pbr else _rgba01(mat.baseColorFactor)
        if rgba is None:
            rgba = np.ones(4)
        metal = pbr.get("metallicFactor", mat.metallicFactor if not js else 1.0)
        rough = pbr.get("roughnessFactor", mat.roughnessFactor if not js else 1.0)
        metal = float(np.clip(1.0 if metal is None else metal, 0.0, 1.0))
        rough = float(np.clip(1.0 if rough is None else rough, 0.0, 1.0))
        ext = js.get("extensions", {}) if js else {}
        transparency = 0.0
        if "KHR_materials_transmission" in ext:
            transparency = float(ext["KHR_materials_transmission"].get("transmissionFactor", 0.0))
        elif str(getattr(mat, "alphaMode", None) or js.get("alphaMode", "OPAQUE")).upper() == "BLEND" and rgba[3] < 1:
            transparency = 1.0 - float(rgba[3])
        ior = float(ext.get("KHR_materials_ior", {}).get("ior", 1.5))
        f0 = 0.04
        spec_ext = ext.get("KHR_materials_specular")
        if isinstance(spec_ext, dict):
            colour = _float_list(spec_ext.get("specularColorFactor", [1.0, 1.0, 1.0])) or [1.0]
            f0_ior = ((ior - 1.0) / (ior + 1.0)) ** 2
            f0 = min(f0_ior * max(colour[:3]), 1.0) * float(spec_ext.get("specularFactor", 1.0))
            f0 = float(np.clip(f0, 0.0, 1.0))
        reflectivity = 0.0
        if metal >= 0.5 and rough <= 0.2:
            reflectivity = metal * (1.0 - rough / 0.2) * float(rgba[:3].max())
        alpha = max(rough * rough, 1e-4)
        mode = str((js.get("alphaMode") if js else None) or getattr(mat, "alphaMode", None) or "OPAQUE").upper()
        cutoff = None
        if mode == "MASK":
            c = js.get("alphaCutoff") if js else getattr(mat, "alphaCutoff", None)
            cutoff = float(np.clip(0.5 if c is None else float(c), 0.0, 1.0))
        double = bool(js.get("doubleSided", False)) if js else bool(getattr(mat, "doubleSided", False))
        normal_info = js.get("normalTexture") if js else None
        normal_tex = self._texture(getattr(mat, "normalTexture", None), f"{name}.normal", srgb=False)
        scale = float(normal_info.get("scale", 1.0)) if isinstance(normal_info, dict) else 1.0
        diffuse, specular = gltf_phong_split(rgba[:3], metal, rough, f0)
        return Material(
            name,
            albedo=diffuse,
            albedo_texture=self._texture(getattr(mat, "baseColorTexture", None), name),
            specular=specular,
            shininess=float(np.clip(2.0 / alpha**2 - 2.0, 1.0, 10000.0)),
            reflectivity=float(np.clip(reflectivity, 0.0, 1.0)),
            transparency=float(np.clip(transparency, 0.0, 1.0)),
            ior=float(np.clip(ior, 1.0, 4.0)),
            alpha=float(rgba[3]),
            alpha_cutoff=cutoff,
            double_sided=double,
            normal_texture=normal_tex,
            normal_scale=scale,
            albedo_uv_transform=self._uv_transform(pbr.get("baseColorTexture"), name),
            normal_uv_transform=self._uv_transform(normal_info, name),
        )

    def _from_mtl(self, mat) -> Material:
        name = mat.name or f"material_{len(self.materials)}"
        kw = {str(k).lower(): v for k, v in (getattr(mat, "kwargs", None) or {}).items()}
        kd = _float_list(kw.get("kd"))
        albedo = np.array((kd * 3)[:3] if kd and len(kd) == 1 else kd[:3]) if kd else _rgba01(mat.diffuse)[:3]
        ks = _float_list(kw.get("ks"))
        if ks:
            spec = max(ks[:3])
        else:
            s = _rgba01(mat.specular)
            spec = float(s[:3].max()) if s is not None else 0.0
        ns = mat.glossiness if mat.glossiness is not None else _first(kw.get("ns"), 1.0)
        d = _first(kw.get("d"), None)
        tr = _first(kw.get("tr"), None)
        transparency = 1.0 - d if d is not None else (tr if tr is not None else 0.0)
        ior = _first(kw.get("ni"), 1.5)
        illum = int(_first(kw.get("illum"), 2))
        reflectivity = spec if illum in (3, 5, 7) else 0.0
        return Material(
            name,
            albedo=np.clip(albedo, 0.0, 1.0),
            albedo_texture=self._texture(getattr(mat, "image", None), name),
            specular=float(np.clip(spec, 0.0, 1.0)),
            shininess=float(np.clip(float(np.asarray(ns).reshape(-1)[0]), 1.0, 10000.0)),
            reflectivity=float(np.clip(reflectivity, 0.0, 1.0)),
            transparency=float(np.clip(transparency, 0.0, 1.0)),
            ior=float(np.clip(ior, 1.0, 4.0)),
        )


def gltf_phong_split(base, metallic: float, roughness: float, f0: float = 0.04) -> tuple[np.ndarray, float]:
    """(diffuse albedo ρ (3,), specular k_s) of a glTF metallic-roughness material (module docstring):
    ρ + k_s ≤ 1 per channel for base colours in [0, 1]. For a textured base, ``base`` is the factor
    and ρ scales the texture as the factor does."""
    base = np.clip(np.asarray(base, np.float64).reshape(3), 0.0, 1.0)
    m = float(np.clip(metallic, 0.0, 1.0))
    g = 1.0 - float(np.clip(roughness, 0.0, 1.0))
    f0 = float(np.clip(f0, 0.0, 1.0))
    lum = float(base @ LUMA_REC709.astype(np.float64))
    specular = g * ((1.0 - m) * f0 + m * lum)
    diffuse = base * ((1.0 - m) * (1.0 - g * f0) + m * (1.0 - g))
    return diffuse, float(np.clip(specular, 0.0, 1.0))


def _first(v, default):
    lst = _float_list(v)
    return lst[0] if lst else default


def gltf_uv_transform(offset, rotation, scale) -> np.ndarray:
    """KHR_texture_transform's uv' = T(offset)·R(rotation)·S(scale)·uv (glTF uvs, v down; R turns
    (1, 0) towards (cos, −sin)) as a (2, 3) affine map of the v-up uvs used here (v ↦ 1 − v on both
    sides)."""
    ox, oy = (float(x) for x in offset)
    sx, sy = (float(x) for x in scale)
    c, s = math.cos(float(rotation)), math.sin(float(rotation))
    m = np.array([[1.0, 0.0, ox], [0.0, 1.0, oy], [0.0, 0.0, 1.0]]) @ np.array(
        [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]]) @ np.diag([sx, sy, 1.0])
    flip = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 1.0], [0.0, 0.0, 1.0]])
    out = (flip @ m @ flip)[:2]
    if not np.all(np.isfinite(out)):
        raise ValueError("offset, rotation and scale must be finite")
    return out


def _same_texture(ta, tb) -> bool:
    if ta is None or tb is None:
        return ta is tb
    return ta is tb or (ta.mips[0].shape == tb.mips[0].shape and np.array_equal(ta.mips[0], tb.mips[0]))


def _same_material(a: Material, b: Material) -> bool:
    keys = ("specular", "shininess", "reflectivity", "transparency", "ior", "alpha", "alpha_cutoff", "double_sided",
            "normal_scale")
    if not (np.array_equal(a.albedo, b.albedo) and all(getattr(a, k) == getattr(b, k) for k in keys)
            and np.array_equal(a.albedo_uv_transform, b.albedo_uv_transform)
            and np.array_equal(a.normal_uv_transform, b.normal_uv_transform)):
        return False
    return _same_texture(a.albedo_texture, b.albedo_texture) and _same_texture(a.normal_texture, b.normal_texture)


# --------------------------------------------------------------------------------------------- writing


def _pbr_from_material(m: Material):
    """The inverse of the glTF mapping (approximate; the TOML holds the exact values)."""
    # shininess n = 2/α² − 2, α = r²  →  r = (2 / (n + 2)) ** 0.25
    rough = float((2.0 / (m.shininess + 2.0)) ** 0.25)
    metal = 1.0 if m.reflectivity > 0 else 0.0
    if metal:
        rough = min(rough, 0.1)
    image = None
    if m.albedo_texture is not None:
        px = texture_to_srgb8(m.albedo_texture)
        image = Image.fromarray(px if px.shape[2] in (3, 4) else px[:, :, :3])
    alpha = m.alpha if m.alpha_cutoff is not None else 1.0 - m.transparency
    from trimesh.visual.material import PBRMaterial

    return PBRMaterial(
        name=m.name,
        baseColorFactor=[*np.clip(m.albedo, 0, 1).tolist(), alpha],
        metallicFactor=metal,
        roughnessFactor=rough,
        baseColorTexture=image,
        alphaMode="MASK" if m.alpha_cutoff is not None else "BLEND" if alpha < 1.0 else "OPAQUE",
        alphaCutoff=m.alpha_cutoff,
        doubleSided=True,
    )


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
    pbr = [_pbr_from_material(m) for m in scene.materials]
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
