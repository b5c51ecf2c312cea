"""The scene model: plain data, validated on construction.

Conventions (everyone builds on these):
- World space is right-handed, **y up, metres** (as glTF). Compass: **+x east, -z north**
  (so +z is south). Azimuth is measured from north towards east.
- Colours are **linear** RGB. Albedo textures are converted sRGB→linear on load
  (:mod:`serenity.scene.texture`), with a full mip chain kept for GL and for the CPU ray tracer.
- Radiometry: radiance in W·m⁻²·sr⁻¹ per RGB channel ("radiometric RGB"); the sun is given by
  its irradiance on a surface facing it at the ground, in W·m⁻² per channel, and its angular
  diameter. A diffuse surface of albedo ρ lit by the sun at zenith angle θ reflects
  L = ρ/π · E · cos θ. The frame's HDR output is this radiance; exposure is applied only before
  the tone map.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from serenity.errors import SceneError

SUN_ANGULAR_DIAMETER_DEG = 0.53


def _vec3(v, what: str) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(-1)
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise SceneError(f"{what} must be 3 finite numbers, got {v!r}")
    return a


def _unit(v, what: str) -> np.ndarray:
    a = _vec3(v, what)
    n = float(np.linalg.norm(a))
    if n < 1e-12:
        raise SceneError(f"{what} must be a non-zero vector")
    return a / n


@dataclass
class Texture:
    """A linear-RGB(A) texture with its full mip chain.

    ``mips[0]`` is (H, W, C) float32 linear (C = 3 or 4); ``mips[k]`` is the 2×2 box filter of
    ``mips[k-1]`` (odd sizes clamp), down to 1×1. ``name`` is the source (file path or label).
    """

    name: str
    mips: list[np.ndarray]

    @property
    def width(self) -> int:
        return int(self.mips[0].shape[1])

    @property
    def height(self) -> int:
        return int(self.mips[0].shape[0])

    @property
    def channels(self) -> int:
        return int(self.mips[0].shape[2])


@dataclass
class Material:
    """A Phong material with optional mirror reflection and glass transmission.

    Attributes:
        name: identifier (unique in a scene).
        albedo: linear diffuse reflectance (3,), in [0, 1]; multiplied by ``albedo_texture``.
        albedo_texture: optional linear texture (sRGB-decoded at load).
        specular: Phong specular strength k_s in [0, 1] (energy-normalised lobe, see raster docs).
        shininess: Phong exponent n ≥ 1.
        reflectivity: mirror reflectance at normal incidence in [0, 1] (mirrors, polished metal);
            pixels with reflectivity > 0 are ray traced.
        transparency: fraction of light transmitted in [0, 1] (glass); pixels with
            transparency > 0 are ray traced for refraction.
        ior: index of refraction (glass ≈ 1.5), used for refraction and the Fresnel term.
        alpha: coverage factor in [0, 1] (glTF baseColorFactor.a), times the albedo texture's alpha
            channel where it has one; read only by the alpha test.
        alpha_cutoff: None (opaque) or the cut-out threshold in [0, 1] (glTF ``alphaMode: MASK``):
            a surface point whose coverage alpha × texture alpha is below it is not there — for
            the camera, the shadow maps, the RSM and every traced ray alike.
        double_sided: the source's flag (glTF ``doubleSided``). Every pass shades both sides of a
            triangle with the normal turned towards the viewer or ray and casts from both sides,
            single-sided or not (glTF lets a renderer skip back-face culling; thin walls and
            blinds modelled as single quads would otherwise let light through).
        normal_texture: optional tangent-space normal map (linear, RGB in [0, 1] ↦ [-1, 1]; +x along
            the tangent dP/du, +y along dP/dv with v up, +z the vertex normal).
        normal_scale: the x and y of the normal map's normals are multiplied by this (glTF scale).
        albedo_uv_transform, normal_uv_transform: (2, 3) affine maps uv ↦ M·(u, v, 1) applied to
            the mesh's uvs before the albedo (and alpha) / normal texture is read (glTF
            KHR_texture_transform, converted to the v-up uvs used here); identity by default.
    """

    name: str
    albedo: np.ndarray = field(default_factory=lambda: np.array([0.8, 0.8, 0.8]))
    albedo_texture: Texture | None = None
    specular: float = 0.0
    shininess: float = 32.0
    reflectivity: float = 0.0
    transparency: float = 0.0
    ior: float = 1.5
    alpha: float = 1.0
    alpha_cutoff: float | None = None
    double_sided: bool = True
    normal_texture: Texture | None = None
    normal_scale: float = 1.0
    albedo_uv_transform: np.ndarray = field(default_factory=lambda: IDENTITY_UV.copy())
    normal_uv_transform: np.ndarray = field(default_factory=lambda: IDENTITY_UV.copy())

    def __post_init__(self):
        self.albedo = _vec3(self.albedo, f"material {self.name!r} albedo")
        if np.any(self.albedo < 0) or np.any(self.albedo > 1):
            raise SceneError(f"material {self.name!r}: albedo must be in [0, 1], got {self.albedo.tolist()}")
        for attr, lo, hi in (("specular", 0, 1), ("reflectivity", 0, 1), ("transparency", 0, 1)):
            v = float(getattr(self, attr))
            if not (lo <= v <= hi):
                raise SceneError(f"material {self.name!r}: {attr} must be in [{lo}, {hi}], got {v}")
            setattr(self, attr, v)
        self.shininess = float(self.shininess)
        if not (self.shininess >= 1.0 and math.isfinite(self.shininess)):
            raise SceneError(f"material {self.name!r}: shininess must be >= 1, got {self.shininess}")
        self.ior = float(self.ior)
        if not (1.0 <= self.ior <= 4.0):
            raise SceneError(f"material {self.name!r}: ior must be in [1, 4], got {self.ior}")
        self.alpha = float(self.alpha)
        if not (0.0 <= self.alpha <= 1.0):
            raise SceneError(f"material {self.name!r}: alpha must be in [0, 1], got {self.alpha}")
        if self.alpha_cutoff is not None:
            self.alpha_cutoff = float(self.alpha_cutoff)
            if not (0.0 <= self.alpha_cutoff <= 1.0):
                raise SceneError(f"material {self.name!r}: alpha_cutoff must be in [0, 1], got {self.alpha_cutoff}")
        self.double_sided = bool(self.double_sided)
        self.normal_scale = float(self.normal_scale)
        if not math.isfinite(self.normal_scale):
            raise SceneError(f"material {self.name!r}: normal_scale must be finite, got {self.normal_scale}")
        for attr in ("albedo_uv_transform", "normal_uv_transform"):
            m = np.asarray(getattr(self, attr), np.float64)
            if m.shape != (2, 3) or not np.all(np.isfinite(m)):
                raise SceneError(f"material {self.name!r}: {attr} must be a finite (2, 3) matrix")
            setattr(self, attr, m)

    @property
    def needs_ray_tracing(self) -> bool:
        return self.reflectivity > 0.0 or self.transparency > 0.0

    @property
    def alpha_tested(self) -> bool:
        """Whether the material is a cut-out (``alpha_cutoff`` set) that can cut anything away:
        a constant coverage at or above the cutoff without an alpha texture is simply opaque."""
        if self.alpha_cutoff is None:
            return False
        t = self.albedo_texture
        return self.alpha < self.alpha_cutoff or (t is not None and t.channels == 4)

    def coverage(self, uv: np.ndarray) -> np.ndarray:
        """(N,) bool: whether the surface is there at (N, 2) mesh uvs (the alpha test, point-sampled
        bilinearly at mip 0 after ``albedo_uv_transform``); all True for an opaque material."""
        uv = np.asarray(uv, np.float64).reshape(-1, 2)
        if not self.alpha_tested:
            return np.ones(len(uv), bool)
        a = np.full(len(uv), self.alpha)
        t = self.albedo_texture
        if t is not None and t.channels == 4:
            a = a * bilinear_repeat(t.mips[0][..., 3], apply_uv_transform(self.albedo_uv_transform, uv))
        return a >= self.alpha_cutoff


IDENTITY_UV = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


def apply_uv_transform(m: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, 2) uvs mapped by the (2, 3) affine ``m``."""
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    return uv @ np.asarray(m, np.float64)[:, :2].T + np.asarray(m, np.float64)[:, 2]


def normal_map_frame(m: np.ndarray) -> np.ndarray:
    """(2, 2): turns a normal map's (x, y), given in the frame of the transformed uvs (the (2, 3)
    ``m``: KHR_texture_transform), into the frame of the mesh's own uvs, in which the tangents are
    built — the orthogonal factor of the inverse of m's linear part (a rotation, or a reflection for
    a mirrored axis; a uniform scale leaves a normal's tilt as it is)."""
    a = np.asarray(m, np.float64)[:, :2]
    try:
        u, _, vt = np.linalg.svd(np.linalg.inv(a))
    except np.linalg.LinAlgError:
        return np.eye(2)
    return u @ vt


def bilinear_repeat(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookup of an (H, W) image (row 0 = top) at (N, 2) uvs with v up and repeat wrap —
    the ray tracer's and GL's GL_LINEAR on level 0."""
    img = np.asarray(img, np.float64)
    h, w = img.shape[:2]
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    x = (uv[:, 0] - np.floor(uv[:, 0])) * w - 0.5
    y = (1.0 - (uv[:, 1] - np.floor(uv[:, 1]))) * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    tx, ty = x - x0, y - y0
    c0, c1 = np.mod(x0, w).astype(np.int64), np.mod(x0 + 1, w).astype(np.int64)
    r0, r1 = np.mod(y0, h).astype(np.int64), np.mod(y0 + 1, h).astype(np.int64)
    top = img[r0, c0] * (1 - tx) + img[r0, c1] * tx
    bottom = img[r1, c0] * (1 - tx) + img[r1, c1] * tx
    return top * (1 - ty) + bottom * ty


@dataclass
class Mesh:
    """An indexed triangle mesh with per-vertex attributes and per-face materials.

    Attributes:
        name: identifier (for error messages).
        positions: (V, 3) float32, metres, world space.
        normals: (V, 3) float32, unit length.
        uvs: (V, 2) float32 texture coordinates (zeros when the source has none).
        faces: (F, 3) int32 vertex indices, counter-clockwise seen from the front.
        face_material: (F,) int32 indices into ``Scene.materials``.
    """

    name: str
    positions: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    faces: np.ndarray
    face_material: np.ndarray

    def __post_init__(self):
        self.positions = np.ascontiguousarray(self.positions, dtype=np.float32).reshape(-1, 3)
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int32).reshape(-1, 3)
        v = len(self.positions)
        if self.uvs is None:
            self.uvs = np.zeros((v, 2), np.float32)
        self.uvs = np.ascontiguousarray(self.uvs, dtype=np.float32).reshape(-1, 2)
        self.face_material = np.ascontiguousarray(self.face_material, dtype=np.int32).reshape(-1)
        if self.normals is None:
            self.normals = vertex_normals(self.positions, self.faces)
        self.normals = np.ascontiguousarray(self.normals, dtype=np.float32).reshape(-1, 3)
        self.validate()

    def validate(self) -> None:
        n = self.name
        if not np.all(np.isfinite(self.positions)):
            bad = int(np.count_nonzero(~np.isfinite(self.positions).all(axis=1)))
            raise SceneError(f"mesh {n!r}: {bad} vertices have NaN or infinite coordinates")
        if len(self.faces) and (self.faces.min() < 0 or self.faces.max() >= len(self.positions)):
            raise SceneError(f"mesh {n!r}: face indices out of range 0..{len(self.positions) - 1}")
        if len(self.normals) != len(self.positions) or len(self.uvs) != len(self.positions):
            raise SceneError(f"mesh {n!r}: normals/uvs must have one entry per vertex")
        if len(self.face_material) != len(self.faces):
            raise SceneError(f"mesh {n!r}: face_material must have one entry per face")
        if not np.all(np.isfinite(self.normals)) or not np.all(np.isfinite(self.uvs)):
            raise SceneError(f"mesh {n!r}: normals or uvs contain NaN or infinite values")

    @property
    def triangle_count(self) -> int:
        return int(len(self.faces))


def vertex_normals(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals; vertices on no (non-degenerate) face get +y."""
    p = np.asarray(positions, np.float64)
    f = np.asarray(faces, np.int64)
    n = np.zeros_like(p)
    if len(f):
        fn = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
        for k in range(3):
            np.add.at(n, f[:, k], fn)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    out = np.where(ln > 1e-20, n / np.maximum(ln, 1e-30), np.array([0.0, 1.0, 0.0]))
    return out.astype(np.float32)


def vertex_tangents(positions: np.ndarray, normals: np.ndarray, uvs: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 4) float32 per-vertex tangents for tangent-space normal maps (MikkTSpace-like): each
    face's dP/du and dP/dv (v up) from its uvs, summed over the faces of a vertex weighted by the
    face's corner angle there, the tangent made orthogonal to the vertex normal (Gram–Schmidt);
    w = ±1 the handedness, so that the bitangent dP/dv ≈ w · (n × t). A vertex on no face with a
    usable uv gradient gets any unit vector orthogonal to its normal and w = 1."""
    p = np.asarray(positions, np.float64)
    n = np.asarray(normals, np.float64)
    uv = np.asarray(uvs, np.float64)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    t_sum = np.zeros_like(p)
    b_sum = np.zeros_like(p)
    if len(f):
        e1, e2 = p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]]
        d1, d2 = uv[f[:, 1]] - uv[f[:, 0]], uv[f[:, 2]] - uv[f[:, 0]]
        det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
        ok = np.abs(det) > 1e-20
        r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
        ft = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
        fb = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
        for k in range(3):
            a = p[f[:, (k + 1) % 3]] - p[f[:, k]]
            b = p[f[:, (k + 2) % 3]] - p[f[:, k]]
            la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
            cos = np.einsum("ij,ij->i", a, b) / np.maximum(la * lb, 1e-30)
            w = np.arccos(np.clip(cos, -1.0, 1.0))[:, None]
            np.add.at(t_sum, f[:, k], ft * w)
            np.add.at(b_sum, f[:, k], fb * w)
    t = t_sum - n * np.einsum("ij,ij->i", t_sum, n)[:, None]
    ln = np.linalg.norm(t, axis=1)
    bad = ln < 1e-20
    if bad.any():  # any unit vector orthogonal to n
        helper = np.where(np.abs(n[bad, 0:1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
        t[bad] = np.cross(n[bad], helper)
        ln[bad] = np.linalg.norm(t[bad], axis=1)
    t = t / np.maximum(ln, 1e-30)[:, None]
    w = np.where(np.einsum("ij,ij->i", np.cross(n, t), b_sum) < 0.0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1).astype(np.float32)


@dataclass
class Camera:
    """A pinhole camera. ``fov_y_deg`` is the full vertical field of view; near/far in metres."""

    position: np.ndarray
    target: np.ndarray
    up: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))
    fov_y_deg: float = 60.0
    near: float = 0.1
    far: float = 500.0

    def __post_init__(self):
        self.position = _vec3(self.position, "camera position")
        self.target = _vec3(self.target, "camera target")
        self.up = _unit(self.up, "camera up")
        if np.linalg.norm(self.target - self.position) < 1e-9:
            raise SceneError("camera target must differ from its position")
        if abs(float(np.dot(self.forward, self.up))) > 0.9999:
            raise SceneError("camera up vector is parallel to the view direction")
        if not (0.1 < self.fov_y_deg < 179.0):
            raise SceneError(f"camera fov_y_deg must be in (0.1, 179), got {self.fov_y_deg}")
        if not (0 < self.near < self.far):
            raise SceneError(f"camera needs 0 < near < far, got near={self.near}, far={self.far}")

    @property
    def forward(self) -> np.ndarray:
        d = self.target - self.position
        return d / np.linalg.norm(d)

    def view_matrix(self) -> np.ndarray:
        """World→camera (4,4) float64, OpenGL convention (camera looks down -z)."""
        f = self.forward
        r = np.cross(f, self.up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = r, u, -f
        m[:3, 3] = -m[:3, :3] @ self.position
        return m

    def projection_matrix(self, aspect: float) -> np.ndarray:
        """Camera→clip (4,4) float64, OpenGL convention (NDC z in [-1, 1])."""
        t = 1.0 / math.tan(math.radians(self.fov_y_deg) / 2)
        n, f = self.near, self.far
        m = np.zeros((4, 4))
        m[0, 0] = t / aspect
        m[1, 1] = t
        m[2, 2] = (f + n) / (n - f)
        m[2, 3] = 2 * f * n / (n - f)
        m[3, 2] = -1.0
        return m

    def primary_rays(self, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """Rays through pixel centres: origins (H*W,3), unit directions (H*W,3), row 0 = top."""
        t = math.tan(math.radians(self.fov_y_deg) / 2)
        aspect = width / height
        xs = ((np.arange(width) + 0.5) / width * 2 - 1) * t * aspect
        ys = (1 - (np.arange(height) + 0.5) / height * 2) * t
        f = self.forward
        r = np.cross(f, self.up)
        r /= np.linalg.norm(r)
        u = np.cross(r, f)
        d = f[None, None] + xs[None, :, None] * r[None, None] + ys[:, None, None] * u[None, None]
        d = d.reshape(-1, 3)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        o = np.broadcast_to(self.position, d.shape).copy()
        return o.astype(np.float32), d.astype(np.float32)


@dataclass
class Sun:
    """The sun as seen from the scene.

    Attributes:
        direction: unit vector **towards** the sun (world space, y up).
        irradiance: (3,) W·m⁻² per channel on a surface facing the sun, at the ground, used with a
            constant sky; with the "atmosphere" sky the atmosphere's transmittance gives it instead
            (``kernels.atmosphere_ref.scene_sun_irradiance``).
        angular_diameter_deg: the disc's apparent diameter (0.53° for the real sun).
        elevation_deg / azimuth_deg: the same direction as angles (azimuth from north to east).
    """

    direction: np.ndarray
    irradiance: np.ndarray = field(default_factory=lambda: np.array([1000.0, 960.0, 900.0]))
    angular_diameter_deg: float = SUN_ANGULAR_DIAMETER_DEG

    def __post_init__(self):
        self.direction = _unit(self.direction, "sun direction")
        self.irradiance = _vec3(self.irradiance, "sun irradiance")
        if np.any(self.irradiance < 0):
            raise SceneError("sun irradiance must be non-negative")
        if not (0.0 < self.angular_diameter_deg < 30.0):
            raise SceneError(f"sun angular diameter must be in (0, 30) degrees, got {self.angular_diameter_deg}")

    @property
    def elevation_deg(self) -> float:
        return math.degrees(math.asin(max(-1.0, min(1.0, float(self.direction[1])))))

    @property
    def azimuth_deg(self) -> float:
        # north = -z, east = +x
        return math.degrees(math.atan2(float(self.direction[0]), float(-self.direction[2]))) % 360.0

    @property
    def cos_angular_radius(self) -> float:
        """cos of the disc's angular radius (a direction within the disc has dot(d, direction) ≥ it)."""
        return math.cos(math.radians(self.angular_diameter_deg) / 2)

    @property
    def tan_angular_radius(self) -> float:
        """tan of the disc's angular radius (a blocker at height h casts a penumbra 2·h·tan wide)."""
        return math.tan(math.radians(self.angular_diameter_deg) / 2)

    @property
    def solid_angle(self) -> float:
        """Solid angle of the disc, sr."""
        return 2 * math.pi * (1 - math.cos(math.radians(self.angular_diameter_deg) / 2))

    @property
    def radiance(self) -> np.ndarray:
        """Radiance of the (uniform) disc, W·m⁻²·sr⁻¹ per channel."""
        return self.irradiance / self.solid_angle

    @property
    def is_up(self) -> bool:
        return self.direction[1] > 0.0


def direction_from_angles(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """Unit vector towards (elevation, azimuth): azimuth from north (-z) towards east (+x)."""
    if not (-90.0 <= elevation_deg <= 90.0) or not math.isfinite(azimuth_deg):
        raise SceneError(f"sun elevation must be in [-90, 90] degrees, got {elevation_deg}")
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.cos(el) * math.sin(az), math.sin(el), -math.cos(el) * math.cos(az)])


@dataclass
class OcclusionQuad:
    """A rectangle that blocks sky light (paper §7, Fig. 6).

    centre ± half_up·up ± half_right·right; ``up`` and ``right`` are orthogonal unit vectors,
    ``half_up``/``half_right`` half-lengths in metres. Two-sided.
    """

    center: np.ndarray
    up: np.ndarray
    right: np.ndarray
    half_up: float
    half_right: float

    def __post_init__(self):
        self.center = _vec3(self.center, "occlusion quad center")
        self.up = _unit(self.up, "occlusion quad up")
        self.right = _unit(self.right, "occlusion quad right")
        if abs(float(np.dot(self.up, self.right))) > 1e-3:
            raise SceneError("occlusion quad up and right vectors must be orthogonal")
        self.half_up, self.half_right = float(self.half_up), float(self.half_right)
        if not (self.half_up > 0 and self.half_right > 0):
            raise SceneError("occlusion quad half lengths must be positive")

    @property
    def normal(self) -> np.ndarray:
        return np.cross(self.right, self.up)

    def corners(self) -> np.ndarray:
        """(4,3) corners, counter-clockwise seen from ``normal``."""
        c, u, r = self.center, self.up * self.half_up, self.right * self.half_right
        return np.array([c - r - u, c + r - u, c + r + u, c - r + u])


@dataclass
class Sky:
    """Sky description: the clear-sky atmosphere model, or a constant-radiance sky.

    ``radiance``: (3,) W·m⁻²·sr⁻¹ of a uniform sky (the "constant" model's, and the constant
    ambient baseline's). ``model``: "constant" or "atmosphere".
    """

    radiance: np.ndarray = field(default_factory=lambda: np.array([20.0, 30.0, 45.0]))
    model: str = "atmosphere"

    def __post_init__(self):
        self.radiance = _vec3(self.radiance, "sky radiance")
        if self.model not in ("constant", "atmosphere"):
            raise SceneError(f"sky model must be 'constant' or 'atmosphere', got {self.model!r}")


def used_vertices(faces: np.ndarray, count: int) -> np.ndarray:
    """(count,) bool: the vertices some face uses (a mask, not ``np.unique``'s sort of every index)."""
    used = np.zeros(count, bool)
    used[np.asarray(faces).reshape(-1)] = True
    return used


@dataclass
class Scene:
    """Everything a frame needs: geometry, materials, camera, sun, sky and occlusion quads."""

    name: str
    meshes: list[Mesh]
    materials: list[Material]
    camera: Camera
    sun: Sun
    sky: Sky = field(default_factory=Sky)
    occlusion_quads: list[OcclusionQuad] = field(default_factory=list)
    source: str | None = None  # file the scene was loaded from, if any
    #: (latitude, longitude) in degrees where the scene stands (north/east positive), for suns set by time
    location: tuple[float, float] | None = None
    #: rigid motion of some meshes over time (``serenity.scene.animation.Animation``), or None: a
    #: still scene. The meshes hold their pose as loaded; ``pose_scene(scene, t)`` gives time t
    animation: object | None = None

    def __post_init__(self):
        self.validate()

    def validate(self) -> None:
        where = f"scene {self.name!r}" + (f" ({self.source})" if self.source else "")
        if not self.meshes or sum(m.triangle_count for m in self.meshes) == 0:
            raise SceneError(f"{where} is empty: it has no triangles")
        if not self.materials:
            raise SceneError(f"{where} has no materials")
        for m in self.meshes:
            if len(m.face_material) and (m.face_material.min() < 0 or m.face_material.max() >= len(self.materials)):
                raise SceneError(f"{where}: mesh {m.name!r} refers to a material that does not exist")
        names = [m.name for m in self.materials]
        if len(set(names)) != len(names):
            raise SceneError(f"{where}: material names must be unique")
        if self.animation is not None:
            meshes = {m.name for m in self.meshes}
            for name in sorted(self.animation.mesh_names - meshes):
                some = ", ".join(sorted(meshes)[:8]) + (", ..." if len(meshes) > 8 else "")
                raise SceneError(f"{where}: the animation moves mesh {name!r}, which the scene does not have "
                                 f"({some})")

    @property
    def bounds(self) -> np.ndarray:
        """(2,3) float64 [min, max] over all vertices used by faces."""
        pts = np.concatenate([m.positions[used_vertices(m.faces, len(m.positions))] for m in self.meshes
                              if m.triangle_count])
        return np.stack([pts.min(axis=0), pts.max(axis=0)]).astype(np.float64)

    def content_bounds(self, margin: float = 0.1) -> np.ndarray:
        """(2,3) float64 bounds of what stands on the ground: every triangle except those lying flat in
        the scene's lowest horizontal plane (a ground plane), widened by ``margin`` × the contents'
        horizontal extent on each side, down to the ground, and clipped to :attr:`bounds`. A ground
        plane that reaches far beyond the buildings on it adds nothing a volume of light must hold
        but open sky, so volumes fitted to this (``SkyConfig.fit = "content"``) spend their cells
        where the geometry is. A scene that is only a ground plane (or has none) gives ``bounds``."""
        full = self.bounds
        extent = float(np.max(full[1] - full[0]))
        eps = 1e-5 * max(extent, 1e-6)
        keep = []
        for m in self.meshes:
            if not m.triangle_count:
                continue
            tri = m.positions[m.faces]  # (T, 3, 3)
            flat = np.all(np.abs(tri[:, :, 1] - full[0, 1]) <= eps, axis=1)
            keep.append(tri[~flat].reshape(-1, 3))
        pts = np.concatenate(keep) if keep else np.zeros((0, 3))
        if len(pts) == 0:
            return full.copy()
        lo, hi = pts.min(axis=0).astype(np.float64), pts.max(axis=0).astype(np.float64)
        pad = margin * float(max(hi[0] - lo[0], hi[2] - lo[2]))
        lo[[0, 2]] -= pad
        hi[[0, 2]] += pad
        lo[1] = full[0, 1]
        return np.stack([np.maximum(lo, full[0]), np.minimum(hi, full[1])])

    @property
    def triangle_count(self) -> int:
        return sum(m.triangle_count for m in self.meshes)

    def material_index(self, name: str) -> int:
        for i, m in enumerate(self.materials):
            if m.name == name:
                return i
        raise SceneError(f"scene {self.name!r} has no material {name!r}")

    def merged(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """All meshes as one: positions (V,3) f32, normals (V,3) f32, uvs (V,2) f32,
        faces (F,3) i32, face_material (F,) i32 — the layout the ray tracer and GL upload use."""
        pos, nrm, uv, fac, fm = [], [], [], [], []
        base = 0
        for m in self.meshes:
            pos.append(m.positions)
            nrm.append(m.normals)
            uv.append(m.uvs)
            fac.append(m.faces + base)
            fm.append(m.face_material)
            base += len(m.positions)
        return (
            np.concatenate(pos).astype(np.float32),
            np.concatenate(nrm).astype(np.float32),
            np.concatenate(uv).astype(np.float32),
            np.concatenate(fac).astype(np.int32),
            np.concatenate(fm).astype(np.int32),
        )

    def merged_tangents(self) -> np.ndarray:
        """(V, 4) float32 tangents of :meth:`merged`'s vertices (:func:`vertex_tangents`, per mesh)."""
        return np.concatenate([vertex_tangents(m.positions, m.normals, m.uvs, m.faces) for m in self.meshes])

    @property
    def has_normal_maps(self) -> bool:
        return any(m.normal_texture is not None for m in self.materials)
