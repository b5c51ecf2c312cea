"""Materials of mesh files: what a glTF, OBJ/MTL or bare (PLY) file's materials become in the
model (:class:`~serenity.scene.model.Material`, Phong + mirror + glass) as
:func:`serenity.scene.mesh_io.load_mesh_file` reads them (:class:`MaterialConverter`), and the way back
to a glTF material for :func:`serenity.scene.mesh_io.export_glb` (:func:`pbr_from_material`).

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

OBJ/MTL: albedo = Kd (taken as linear), albedo_texture = map_Kd (sRGB); specular = max(Ks);
shininess = Ns (≥ 1); transparency = 1 − d (or Tr); ior = Ni; illum 3, 5 or 7 (ray-traced
reflection) makes a mirror with reflectivity = max(Ks).

PLY and other files without materials: one grey material (albedo 0.8), or, with vertex/face
colours, one material per mesh whose albedo is their mean (sRGB-decoded) — the model has no
per-vertex colour.

Writing (:func:`pbr_from_material`) inverts the glTF mapping approximately (colours quantised to 8
bits by trimesh, shininess back to a roughness); the TOML beside an exported GLB carries the exact
values.
"""

from __future__ import annotations

import math
import warnings

import numpy as np
from PIL import Image

from serenity.colour import LUMA_REC709, srgb_to_linear
from serenity.errors import SceneError, first_line
from serenity.scene.model import IDENTITY_UV, Material, Texture
from serenity.scene.texture import texture_from_image, texture_to_srgb8

__all__ = ["MaterialConverter", "gltf_phong_split", "gltf_uv_transform", "pbr_from_material"]

_DEFAULT_ALBEDO = 0.8


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


class MaterialConverter:
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
                raise SceneError(f"{self.path}: texture of material {label!r} cannot be decoded ({first_line(e)})") \
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


def pbr_from_material(m: Material):
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
