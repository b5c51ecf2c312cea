"""Rigid motion of a scene's meshes over time: keyframed tracks, and the scene posed at a time.

A ``Track`` moves one mesh (by name) rigidly: translation, rotation (unit quaternions, x y z w,
as glTF stores them) and uniform or per-axis scale, each a list of keyframes at the track's times,
interpolated LINEAR (rotations by slerp) or STEP, the way glTF's animation samplers are. The
rotation and scale act about the track's ``pivot`` (world space; by default the centre of the
mesh's bounds as loaded), so a track keyed in a mesh's own frame can be stated in world space:
at time t a point p of the mesh as loaded moves to ``pivot + T(t) + R(t)·S(t)·(p − pivot)``. Before
the first keyframe a track holds its first, after the last its last (``repeat = "once"``), or it
starts again (``"loop"``) or runs back (``"pingpong"``).

An ``Animation`` is a scene's tracks; ``pose_scene(scene, time)`` gives the scene at that time: a
new ``Scene`` whose moved meshes have their positions and normals transformed (everything else
shared with the scene as loaded), so any consumer of a static scene (the renderer, the reference,
the kd-tree) sees that instant. The meshes a track moves are the scene's dynamic meshes.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from serenity.errors import SceneError
from serenity.scene.model import used_vertices

INTERPOLATIONS = ("LINEAR", "STEP")
REPEATS = ("once", "loop", "pingpong")


def _keys(name: str, values, times: np.ndarray, width: int, where: str) -> np.ndarray | None:
    if values is None:
        return None
    a = np.asarray(values, np.float64)
    if a.ndim == 1 and width == 3 and len(a) == len(times) and name == "scale":
        a = np.repeat(a[:, None], 3, axis=1)  # uniform scale per keyframe
    if a.shape != (len(times), width):
        raise SceneError(f"{where}: {name} needs {len(times)} keyframes of {width} values, got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise SceneError(f"{where}: {name} has NaN or infinite values")
    return a


def quaternion_matrix(q: np.ndarray) -> np.ndarray:
    """(3, 3) rotation of the unit quaternion q = (x, y, z, w)."""
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def slerp(a: np.ndarray, b: np.ndarray, s: float) -> np.ndarray:
    """Spherical interpolation between unit quaternions a and b (the shorter way round)."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    d = float(np.dot(a, b))
    if d < 0.0:
        b, d = -b, -d
    if d > 0.9995:
        q = a + s * (b - a)
        return q / np.linalg.norm(q)
    theta = math.acos(min(d, 1.0))
    return (math.sin((1 - s) * theta) * a + math.sin(s * theta) * b) / math.sin(theta)


def axis_angle_quaternion(axis, degrees: float) -> np.ndarray:
    """The unit quaternion (x, y, z, w) of a rotation by ``degrees`` about ``axis``."""
    axis = np.asarray(axis, np.float64)
    axis = axis / np.linalg.norm(axis)
    h = math.radians(degrees) / 2
    return np.array([*(axis * math.sin(h)), math.cos(h)])


@dataclass
class Track:
    """The rigid motion of one mesh (module docstring). Times in seconds, translations in metres."""

    mesh: str
    times: np.ndarray
    translation: np.ndarray | None = None  # (K, 3)
    rotation: np.ndarray | None = None     # (K, 4) unit quaternions x y z w
    scale: np.ndarray | None = None        # (K, 3)
    interpolation: str = "LINEAR"
    repeat: str = "once"
    pivot: np.ndarray | None = None        # (3,) world space; None = the mesh's bounds centre

    def __post_init__(self):
        where = f"animation of mesh {self.mesh!r}"
        self.times = np.asarray(self.times, np.float64).reshape(-1)
        if len(self.times) == 0 or not np.all(np.isfinite(self.times)):
            raise SceneError(f"{where}: needs one or more finite keyframe times")
        if np.any(np.diff(self.times) <= 0):
            raise SceneError(f"{where}: keyframe times must increase, got {self.times.tolist()}")
        self.translation = _keys("translation", self.translation, self.times, 3, where)
        self.rotation = _keys("rotation", self.rotation, self.times, 4, where)
        self.scale = _keys("scale", self.scale, self.times, 3, where)
        if self.rotation is not None and np.any(np.linalg.norm(self.rotation, axis=1) < 1e-9):
            raise SceneError(f"{where}: a rotation quaternion is zero")
        if self.scale is not None and np.any(np.abs(self.scale) < 1e-9):
            raise SceneError(f"{where}: a scale is zero (the mesh would collapse)")
        self.interpolation = str(self.interpolation).upper()
        if self.interpolation not in INTERPOLATIONS:
            raise SceneError(f"{where}: interpolation must be linear or step, got {self.interpolation.lower()!r}")
        if self.repeat not in REPEATS:
            raise SceneError(f"{where}: repeat must be one of {', '.join(REPEATS)}, got {self.repeat!r}")
        if self.pivot is not None:
            self.pivot = np.asarray(self.pivot, np.float64).reshape(3)
            if not np.all(np.isfinite(self.pivot)):
                raise SceneError(f"{where}: pivot has NaN or infinite values")

    @property
    def duration(self) -> float:
        return float(self.times[-1] - self.times[0])

    def local_time(self, time: float) -> float:
        """The time within the keyframes that ``time`` plays (``repeat``)."""
        t0, span = float(self.times[0]), self.duration
        if span <= 0.0 or self.repeat == "once":
            return float(np.clip(time, t0, self.times[-1]))
        k = (time - t0) / span
        if self.repeat == "loop":
            return t0 + (k - math.floor(k)) * span
        k = k % 2.0
        return t0 + (k if k <= 1.0 else 2.0 - k) * span

    def _sample(self, keys: np.ndarray, t: float, rotation: bool = False) -> np.ndarray:
        i = int(np.searchsorted(self.times, t, side="right")) - 1
        if i < 0:
            return keys[0]
        if i >= len(self.times) - 1 or self.interpolation == "STEP":
            return keys[min(i, len(keys) - 1)]
        s = (t - self.times[i]) / (self.times[i + 1] - self.times[i])
        if rotation:
            return slerp(keys[i], keys[i + 1], s)
        return keys[i] + s * (keys[i + 1] - keys[i])

    def matrix(self, time: float, pivot: np.ndarray) -> np.ndarray:
        """(4, 4) world transform at ``time`` of the mesh as loaded (``pivot`` when the track has none)."""
        t = self.local_time(float(time))
        c = self.pivot if self.pivot is not None else np.asarray(pivot, np.float64)
        m = np.eye(3)
        if self.scale is not None:
            m = np.diag(self._sample(self.scale, t))
        if self.rotation is not None:
            m = quaternion_matrix(self._sample(self.rotation, t, rotation=True)) @ m
        out = np.eye(4)
        out[:3, :3] = m
        move = self._sample(self.translation, t) if self.translation is not None else np.zeros(3)
        out[:3, 3] = c + move - m @ c
        return out


@dataclass
class Animation:
    """A scene's tracks, at most one per mesh name."""

    tracks: list[Track]

    def __post_init__(self):
        names = [t.mesh for t in self.tracks]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise SceneError(f"animation: more than one track moves mesh {twice[0]!r}")

    @property
    def duration(self) -> float:
        """Seconds from the first keyframe of any track to the last."""
        if not self.tracks:
            return 0.0
        return float(max(t.times[-1] for t in self.tracks) - min(t.times[0] for t in self.tracks))

    @property
    def mesh_names(self) -> set[str]:
        return {t.mesh for t in self.tracks}


def _bounds_centre(mesh) -> np.ndarray:
    """The centre of the box of the vertices ``mesh``'s faces use (all of them for a mesh without faces)."""
    p = mesh.positions[used_vertices(mesh.faces, len(mesh.positions))] if len(mesh.faces) else mesh.positions
    return (p.min(axis=0).astype(np.float64) + p.max(axis=0)) * 0.5


def mesh_transforms(scene, time: float) -> dict[str, np.ndarray]:
    """Mesh name → (4, 4) world transform at ``time`` of each mesh the scene's animation moves."""
    anim = getattr(scene, "animation", None)
    if anim is None:
        return {}
    if not math.isfinite(float(time)):
        raise SceneError(f"scene {scene.name!r}: animation time must be finite, got {time!r}")
    by_name = {m.name: m for m in scene.meshes}
    return {t.mesh: t.matrix(time, _bounds_centre(by_name[t.mesh])) for t in anim.tracks if t.mesh in by_name}


def pose_scene(scene, time: float):
    """``scene`` at animation ``time`` (seconds): a new ``Scene`` sharing everything but the moved
    meshes, whose positions and normals are transformed (module docstring). A scene without an
    animation is returned as it is."""
    moves = mesh_transforms(scene, time)
    if not moves:
        return scene
    meshes = []
    for m in scene.meshes:
        mat = moves.get(m.name)
        if mat is None:
            meshes.append(m)
            continue
        lin = mat[:3, :3]
        pos = m.positions.astype(np.float64) @ lin.T + mat[:3, 3]
        nrm = m.normals.astype(np.float64) @ np.linalg.inv(lin)   # inverse transpose, as row vectors
        nrm /= np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-30)
        faces = m.faces if np.linalg.det(lin) > 0 else m.faces[:, ::-1]
        meshes.append(dataclasses.replace(m, positions=pos, normals=nrm, faces=faces))
    return dataclasses.replace(scene, meshes=meshes)
