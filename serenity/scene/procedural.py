"""Built-in procedural scenes: deterministic (no randomness without a fixed seed), metres, y up,
+x east, −z north. ``build_scene(name)`` makes one; ``scene_names()`` / ``scene_descriptions()``
list them (``serenity scenes``). Each mesh holds one material, so a GLB export keeps vertex order.

- ``courtyard`` (default): a 30 × 30 m square enclosed by four buildings of different heights;
  arched passages (an arcade of three through the north building, a gate through the south one),
  glass windows (transparency 0.9, ior 1.5), a mirror door (reflectivity 0.9) on the east facade,
  columns, a fountain basin and crates; the ground carries a procedural sRGB tile texture (1 m
  tiles, repeating every 4 m). Occlusion quads: each building's four walls and roof. Camera at eye
  height in the south-west of the square looking north-east; sun at
  :data:`~serenity.scene.sun.DEFAULT_TIME` in Lisbon.
- ``cornell``: the classic Cornell box (Cornell's measured geometry, mm → m; white, red and green
  walls; short and tall blocks; the classic camera: 35 mm lens on a 25 mm film, fov 39.3°).
  Our only light is the sun, so the ceiling light is replaced by a **hole of the same size**: the
  sun (elevation 70°, azimuth 170°, i.e. from behind the back wall, so no direct light enters by the
  open front) shines through it onto the floor and blocks. The sky is black (constant 0) so that the
  box is lit by the sun patch and its bounces only.
- ``thin-wall``: a 5 cm thick wall (thinner than an LPV cell) lit on its south side next to a red box;
  the camera looks at its shadowed north side, where no light may leak through.
- ``terrain``: an 80 × 80 m height field (ridge, hills, seeded noise; 12.8k triangles) with four
  least-squares occlusion quads that fit it badly on purpose.
- ``mirror-box``: a roofless 8 × 8 m room with a mirror on the north wall; coloured objects behind the
  camera are visible only in the mirror.
- ``glass``: a glass slab, sphere and prism (ior 1.5; total internal reflection in the prism) in front
  of coloured columns on a tiled floor.
- ``night``: the courtyard at 23:30 local time — the sun is below the horizon.
- ``plane``: one diffuse plane (albedo 0.5) under the sun at elevation 60° (zenith 30°), black sky:
  radiance = ρ/π · E · cos θ exactly (analytic shading tests; :func:`plane_scene` takes parameters).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np

from serenity.errors import SceneError
from serenity.scene.animation import Animation, Track
from serenity.scene.model import (
    Camera,
    Material,
    Mesh,
    OcclusionQuad,
    Scene,
    Sky,
    Sun,
    Texture,
    direction_from_angles,
    vertex_normals,
)
from serenity.scene.sun import DEFAULT_LOCATION, DEFAULT_TIME, sun_from_time
from serenity.scene.texture import texture_from_array

__all__ = ["SceneBuilder", "scene_names", "scene_descriptions", "build_scene", "plane_scene", "tile_texture",
           "lumpy_mesh"]

_Y = np.array([0.0, 1.0, 0.0])


# ----------------------------------------------------------------------------------------- geometry builder


class SceneBuilder:
    """Builds a :class:`Scene` from primitives (the built-in scenes here, and small test scenes made
    for one measurement).

    Declare each material (``material``), add shapes made of it (``rect``, ``quad``, ``box``,
    ``cylinder``, ``sphere``, ``prism``, ``arch_wall``, or raw triangles with ``add``), then call
    ``scene()``, which makes one :class:`Mesh` per material that has triangles. Metres, y up::

        b = SceneBuilder()
        b.material("floor", albedo=(0.5, 0.5, 0.5))
        b.rect("floor", (0, 0, 0), (10, 0, 0), (0, 0, -10))   # a 20 × 20 m floor facing +y
        scene = b.scene("floor", Camera((0, 2, 8), (0, 0, 0)), Sun((0.3, 1.0, 0.2)))
    """

    def __init__(self):
        self.materials: list[Material] = []
        self._index: dict[str, int] = {}
        self._parts: dict[int, list[tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]]] = {}

    def material(self, name: str, **kw) -> str:
        """Declare material ``name`` (keywords: :class:`Material`'s fields); returns ``name``, the key
        the shapes take. Materials keep their order of declaration (the scene's material indices)."""
        self._index[name] = len(self.materials)
        self.materials.append(Material(name, **kw))
        return name

    def add(self, mat: str, pos, nrm, uv, faces) -> None:
        """Raw triangles of material ``mat``: positions and normals (V, 3), uvs (V, 2), faces (F, 3)
        indices into them (counter-clockwise seen from the side the normals face)."""
        self._parts.setdefault(self._index[mat], []).append(
            (np.asarray(pos, np.float64), np.asarray(nrm, np.float64), np.asarray(uv, np.float64),
             np.asarray(faces, np.int64)))

    def quad(self, mat: str, corners, normal=None, uv_scale: float = 1.0, uvs=None) -> None:
        """A planar quad (4 corners in order around it), two triangles facing ``normal`` (default: the
        corners' own winding). uvs default to the corners projected on the quad's edge axes × uv_scale."""
        c = np.asarray(corners, np.float64)
        keep = [k for k in range(4) if np.linalg.norm(c[k] - c[(k + 1) % 4]) > 1e-12]
        c = c[keep]  # a quad with two coincident corners is a triangle
        if uvs is not None:
            uvs = np.asarray(uvs)[keep]
        n = np.cross(c[1] - c[0], c[2] - c[0])
        if normal is not None and np.dot(n, normal) < 0:
            order = [0, *range(len(c) - 1, 0, -1)]
            c = c[order]
            if uvs is not None:
                uvs = uvs[order]
            n = -n
        n = n / np.linalg.norm(n)
        if uvs is None:
            e1 = c[1] - c[0]
            e1 /= np.linalg.norm(e1)
            e2 = np.cross(n, e1)
            uvs = np.stack([c @ e1, c @ e2], axis=1) * uv_scale
        self.add(mat, c, np.tile(n, (len(c), 1)), uvs, [[0, 1, 2], [0, 2, 3]][: len(c) - 2])

    def rect(self, mat: str, center, u, v, uv_scale: float = 1.0) -> None:
        """Rectangle center ± u ± v facing u × v (u, v: half-edge vectors); uvs = world metres on û, v̂."""
        c, u, v = (np.asarray(a, np.float64) for a in (center, u, v))
        corners = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
        uh, vh = u / np.linalg.norm(u), v / np.linalg.norm(v)
        uvs = np.stack([corners @ uh, corners @ vh], axis=1) * uv_scale
        self.add(mat, corners, np.tile(np.cross(uh, vh), (4, 1)), uvs, [[0, 1, 2], [0, 2, 3]])

    def box(self, mat: str, lo, hi, uv_scale: float = 1.0, skip: tuple[str, ...] = ()) -> None:
        """Axis-aligned box with flat faces; ``skip`` names faces to leave out ('+x', '-y', ...)."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        c, h = (lo + hi) / 2, (hi - lo) / 2
        for axis in range(3):
            for sign in (1.0, -1.0):
                key = ("+" if sign > 0 else "-") + "xyz"[axis]
                if key in skip:
                    continue
                n = np.zeros(3)
                n[axis] = sign
                t2 = _Y if axis != 1 else np.array([0.0, 0.0, -1.0])
                t1 = np.cross(t2, n)
                self.rect(mat, c + n * h[axis], t1 * (np.abs(t1) @ h), t2 * (np.abs(t2) @ h), uv_scale)

    def cylinder(self, mat: str, base, radius: float, height: float, sections: int = 16) -> None:
        """Vertical cylinder standing on ``base`` (smooth sides, flat top cap; no bottom)."""
        b = np.asarray(base, np.float64)
        th = np.linspace(0.0, 2 * math.pi, sections + 1)
        ring = np.stack([np.cos(th), np.zeros_like(th), -np.sin(th)], axis=1)  # CCW seen from above
        pos = np.concatenate([b + ring * radius, b + ring * radius + _Y * height])
        nrm = np.concatenate([ring, ring])
        uv = np.concatenate([np.stack([th * radius, np.zeros_like(th)], 1),
                             np.stack([th * radius, np.full_like(th, height)], 1)])
        k = sections + 1
        i = np.arange(sections)
        faces = np.concatenate([np.stack([i, i + 1, k + i + 1], 1), np.stack([i, k + i + 1, k + i], 1)])
        self.add(mat, pos, nrm, uv, faces)
        top = b + _Y * height
        cap = np.concatenate([[top], top + ring[:-1] * radius])
        cf = np.stack([np.zeros(sections, int), 1 + i, 1 + (i + 1) % sections], 1)
        self.add(mat, cap, np.tile(_Y, (len(cap), 1)), cap[:, [0, 2]] * np.array([1.0, -1.0]), cf)

    def sphere(self, mat: str, center, radius: float, subdivisions: int = 3) -> None:
        import trimesh.creation  # here: trimesh (and scipy) take most of a second to import

        s = trimesh.creation.icosphere(subdivisions=subdivisions, radius=1.0)
        d = np.asarray(s.vertices, np.float64)
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        uv = np.stack([np.arctan2(d[:, 0], d[:, 2]) / (2 * math.pi) + 0.5, np.arcsin(d[:, 1]) / math.pi + 0.5], 1)
        self.add(mat, np.asarray(center) + d * radius, d, uv, s.faces)

    def prism(self, mat: str, tri_xy, z0: float, z1: float, skip_sides=()) -> None:
        """A triangular prism: the triangle ``tri_xy`` (3 × (x, y)) extruded from z0 to z1, flat faces;
        side k (from corner k to k+1) is left out for k in ``skip_sides`` (a side resting on the
        floor: coplanar faces would make rays pick one at random)."""
        t = np.asarray(tri_xy, np.float64)
        a = np.array([[p[0], p[1], z0] for p in t])
        b = np.array([[p[0], p[1], z1] for p in t])
        centre = np.concatenate([a, b]).mean(axis=0)
        for tri, zc in ((a, -1.0), (b, 1.0)):
            n = np.array([0.0, 0.0, zc])
            f = [0, 1, 2] if np.dot(np.cross(tri[1] - tri[0], tri[2] - tri[0]), n) > 0 else [0, 2, 1]
            self.add(mat, tri, np.tile(n, (3, 1)), tri[:, :2], [f])
        for k in range(3):
            if k in skip_sides:
                continue
            q = np.array([a[k], a[(k + 1) % 3], b[(k + 1) % 3], b[k]])
            out = q.mean(axis=0) - centre
            self.quad(mat, q, normal=out)

    def arch_wall(self, mat: str, axis: str, s0: float, s1: float, y1: float, t0: float, t1: float,
                  openings: list[tuple[float, float, float]], sections: int = 12, uv_scale: float = 0.5) -> None:
        """A solid wall block from the ground to ``y1``, spanning s ∈ [s0, s1] along ``axis`` ('x' or 'z')
        and t ∈ [t0, t1] across it, pierced by round-arched passages ``(centre_s, half_width, spring_y)``
        through its whole depth (jambs up to spring_y, semicircular vault of radius half_width)."""
        def world(s, y, t):
            return np.array([s, y, t]) if axis == "x" else np.array([t, y, s])

        def box(sa, sb, ya, yb):
            lo, hi = world(sa, ya, t0), world(sb, yb, t1)
            self.box(mat, np.minimum(lo, hi), np.maximum(lo, hi), uv_scale, skip=("-y",))

        cursor = s0
        for c, w, spring in sorted(openings):
            crown = spring + w
            if c - w < cursor - 1e-9 or c + w > s1 + 1e-9 or crown >= y1:
                raise SceneError("arch opening does not fit its wall")
            if c - w > cursor:
                box(cursor, c - w, 0.0, y1)
            box(c - w, c + w, crown, y1)
            th = np.linspace(math.pi, 0.0, sections + 1)
            arc_s, arc_y = c + w * np.cos(th), spring + w * np.sin(th)
            for k in range(sections):
                for t, sign in ((t0, -1.0), (t1, 1.0)):  # the spandrels on both faces
                    q = [world(arc_s[k], arc_y[k], t), world(arc_s[k + 1], arc_y[k + 1], t),
                         world(arc_s[k + 1], crown, t), world(arc_s[k], crown, t)]
                    if abs(arc_y[k] - crown) + abs(arc_y[k + 1] - crown) > 1e-9:
                        self.quad(mat, q, normal=world(0.0, 0.0, sign), uv_scale=uv_scale)
            # the vault's underside: smooth normals towards the arch centre
            pos, nrm, uv = [], [], []
            for k in range(sections + 1):
                inward = world(-math.cos(th[k]), -math.sin(th[k]), 0.0)
                for t in (t0, t1):
                    pos.append(world(arc_s[k], arc_y[k], t))
                    nrm.append(inward)
                    uv.append([th[k] * w * uv_scale, t * uv_scale])
            faces = []
            for k in range(sections):
                a, b, cc, d = 2 * k, 2 * k + 1, 2 * k + 3, 2 * k + 2
                tri = np.array(pos)[[a, b, cc]]
                if np.dot(np.cross(tri[1] - tri[0], tri[2] - tri[0]), nrm[a] + nrm[cc]) > 0:
                    faces += [[a, b, cc], [a, cc, d]]
                else:
                    faces += [[a, cc, b], [a, d, cc]]
            self.add(mat, pos, nrm, uv, faces)
            cursor = c + w
        if s1 > cursor:
            box(cursor, s1, 0.0, y1)

    def scene(self, name: str, camera: Camera, sun: Sun, sky: Sky | None = None,
              quads: list[OcclusionQuad] | None = None, location=None) -> Scene:
        """The :class:`Scene` of everything added: ``sky`` defaults to ``Sky()`` (the atmosphere),
        ``quads`` (the sky volume's occlusion quads) to none; ``location`` as :class:`Scene`'s."""
        meshes = []
        for mi, mat in enumerate(self.materials):
            parts = self._parts.get(mi)
            if not parts:
                continue
            pos, nrm, uv, fac = [], [], [], []
            base = 0
            for p, n, u, f in parts:
                pos.append(p)
                nrm.append(n)
                uv.append(u)
                fac.append(f + base)
                base += len(p)
            faces = np.concatenate(fac)
            meshes.append(Mesh(mat.name, np.concatenate(pos), np.concatenate(nrm), np.concatenate(uv), faces,
                               np.full(len(faces), mi)))
        return Scene(name, meshes, self.materials, camera, sun, sky or Sky(), quads or [], location=location)


def _wall_quads(lo, hi, roof: bool = True) -> list[OcclusionQuad]:
    """Occlusion quads on the four vertical faces (and the roof) of an axis-aligned block."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c, h = (lo + hi) / 2, (hi - lo) / 2
    out = []
    for axis in (0, 2):
        for sign in (-1.0, 1.0):
            centre = c.copy()
            centre[axis] += sign * h[axis]
            right = np.array([0.0, 0.0, 1.0]) if axis == 0 else np.array([1.0, 0.0, 0.0])
            out.append(OcclusionQuad(centre, _Y, right, h[1], h[2 - axis]))
    if roof:
        out.append(OcclusionQuad(c + _Y * h[1], np.array([0.0, 0.0, -1.0]), np.array([1.0, 0.0, 0.0]), h[2], h[0]))
    return out


# ----------------------------------------------------------------------------------------------- textures


def tile_texture(size: int = 256, tiles: int = 4, seed: int = 7) -> Texture:
    """A deterministic stone-tile albedo texture: ``tiles`` × ``tiles`` tiles in a two-tone checker with
    per-tile and per-texel variation and dark grout, generated as 8-bit sRGB and decoded to linear
    (so a PNG/GLB export reproduces it exactly)."""
    rng = np.random.default_rng(seed)
    cell = size // tiles
    yy, xx = np.mgrid[0:size, 0:size]
    ti, tj = yy // cell, xx // cell
    light = np.array([205.0, 190.0, 160.0])
    dark = np.array([160.0, 140.0, 115.0])
    base = np.where(((ti + tj) % 2 == 0)[..., None], light, dark)
    base = base + rng.uniform(-14, 14, size=(tiles, tiles, 1))[ti, tj]
    base = base + rng.normal(0.0, 4.0, size=(size, size, 1))
    gy, gx = yy % cell, xx % cell
    grout = (np.minimum(gy, cell - 1 - gy) < 2) | (np.minimum(gx, cell - 1 - gx) < 2)
    base[grout] = [95.0, 90.0, 85.0]
    return texture_from_array(np.clip(np.rint(base), 0, 255).astype(np.uint8), name="tiles", srgb=True)


# ------------------------------------------------------------------------------------------------- scenes


def _default_sun(when: str | None = None) -> tuple[Sun, tuple[float, float]]:
    return sun_from_time(when or DEFAULT_TIME, *DEFAULT_LOCATION), DEFAULT_LOCATION


def courtyard_scene(time: str | None = None, name: str = "courtyard") -> Scene:
    b = SceneBuilder()
    b.material("ground", albedo=(1.0, 1.0, 1.0), albedo_texture=tile_texture(), specular=0.04, shininess=16.0)
    plaster = [
        b.material("plaster_north", albedo=(0.78, 0.70, 0.55), specular=0.02, shininess=8.0),
        b.material("plaster_south", albedo=(0.72, 0.52, 0.40), specular=0.02, shininess=8.0),
        b.material("plaster_west", albedo=(0.80, 0.78, 0.72), specular=0.02, shininess=8.0),
        b.material("plaster_east", albedo=(0.62, 0.66, 0.70), specular=0.02, shininess=8.0),
    ]
    roof = b.material("roof", albedo=(0.45, 0.20, 0.12), specular=0.05, shininess=16.0)
    stone = b.material("stone", albedo=(0.60, 0.60, 0.57), specular=0.05, shininess=24.0)
    wood = b.material("wood", albedo=(0.42, 0.28, 0.16), specular=0.03, shininess=12.0)
    glass = b.material("glass", albedo=(0.95, 0.95, 0.95), specular=0.5, shininess=500.0, transparency=0.9, ior=1.5)
    mirror = b.material("mirror", albedo=(0.05, 0.05, 0.05), specular=0.9, shininess=2000.0, reflectivity=0.9)
    water = b.material("water", albedo=(0.10, 0.18, 0.22), specular=0.3, shininess=200.0)

    g = 60.0
    b.rect("ground", (0.0, 0.0, 0.0), (g, 0.0, 0.0), (0.0, 0.0, -g), uv_scale=0.25)

    # buildings: (material, lo, hi); the square is x, z in [-15, 15]
    north = (plaster[0], (-23.0, 0.0, -23.0), (23.0, 12.0, -15.0))
    south = (plaster[1], (-23.0, 0.0, 15.0), (23.0, 9.0, 23.0))
    west = (plaster[2], (-23.0, 0.0, -15.0), (-15.0, 10.0, 15.0))
    east = (plaster[3], (15.0, 0.0, -15.0), (23.0, 11.0, 15.0))
    # north: an arcade of three arches through its depth; south: one gate
    b.arch_wall(north[0], "x", -23.0, 23.0, 12.0, -23.0, -15.0, [(-6.0, 1.6, 2.6), (0.0, 1.6, 2.6), (6.0, 1.6, 2.6)])
    b.arch_wall(south[0], "x", -23.0, 23.0, 9.0, 15.0, 23.0, [(0.0, 2.5, 3.5)])
    b.box(west[0], west[1], west[2], 0.5, skip=("-y",))
    b.box(east[0], east[1], east[2], 0.5, skip=("-y",))
    quads = []
    for _, lo, hi in (north, south, west, east):
        lo, hi = np.array(lo), np.array(hi)
        b.box(roof, (lo[0] - 0.3, hi[1], lo[2] - 0.3), (hi[0] + 0.3, hi[1] + 0.3, hi[2] + 0.3), 0.5)
        quads += _wall_quads(lo, hi + [0, 0.3, 0])

    # glass windows in front of the facades facing the square
    for x in (-12.0, -3.0, 3.0, 12.0):
        b.box(glass, (x - 0.8, 5.0, -15.0 + 0.05), (x + 0.8, 7.0, -15.0 + 0.12))
        b.box(stone, (x - 0.95, 4.85, -15.0), (x + 0.95, 5.0, -15.0 + 0.25))  # sills
    for z in (-9.0, 9.0):
        b.box(glass, (15.0 - 0.12, 4.5, z - 0.9), (15.0 - 0.05, 6.5, z + 0.9))
        b.box(glass, (-15.0 + 0.05, 4.5, z - 0.9), (-15.0 + 0.12, 6.5, z + 0.9))
    # the mirror door on the east facade, in a stone frame
    b.box(mirror, (15.0 - 0.06, 0.0, -0.9), (15.0 - 0.02, 2.6, 0.9))
    b.box(stone, (15.0 - 0.2, 0.0, -1.15), (15.0, 2.85, -0.9))
    b.box(stone, (15.0 - 0.2, 0.0, 0.9), (15.0, 2.85, 1.15))
    b.box(stone, (15.0 - 0.2, 2.6, -0.9), (15.0, 2.85, 0.9))

    # fountain basin with water, four columns, crates
    b.box(stone, (-2.5, 0.0, -2.5), (2.5, 0.6, -2.2), 0.5, skip=("-y",))
    b.box(stone, (-2.5, 0.0, 2.2), (2.5, 0.6, 2.5), 0.5, skip=("-y",))
    b.box(stone, (-2.5, 0.0, -2.2), (-2.2, 0.6, 2.2), 0.5, skip=("-y",))
    b.box(stone, (2.2, 0.0, -2.2), (2.5, 0.6, 2.2), 0.5, skip=("-y",))
    b.rect(water, (0.0, 0.45, 0.0), (2.2, 0.0, 0.0), (0.0, 0.0, -2.2))
    b.box(stone, (-0.4, 0.0, -0.4), (0.4, 1.6, 0.4), 0.5, skip=("-y",))
    for x, z in ((-6.0, -6.0), (6.0, -6.0), (-6.0, 6.0), (6.0, 6.0)):
        b.box(stone, (x - 0.5, 0.0, z - 0.5), (x + 0.5, 0.4, z + 0.5), 0.5, skip=("-y",))
        b.cylinder(stone, (x, 0.4, z), 0.3, 4.0, sections=16)
        b.box(stone, (x - 0.45, 4.4, z - 0.45), (x + 0.45, 4.7, z + 0.45), 0.5)
    for lo, hi in (((10.0, 0.0, 8.0), (11.2, 1.2, 9.2)), ((11.3, 0.0, 8.2), (12.3, 1.0, 9.2)),
                   ((10.3, 1.2, 8.3), (11.1, 2.0, 9.1)), ((-12.0, 0.0, -10.0), (-10.5, 0.8, -8.5))):
        b.box(wood, lo, hi, 1.0, skip=("-y",))

    sun, location = _default_sun(time)
    camera = Camera(position=(-10.0, 1.7, 11.0), target=(6.0, 4.0, -8.0), fov_y_deg=60.0, near=0.1, far=300.0)
    return b.scene(name, camera, sun, Sky(), quads, location)


# the classic Cornell box, millimetres (Cornell University Program of Computer Graphics data)
_CB_FLOOR = [[552.8, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 559.2], [549.6, 0.0, 559.2]]
_CB_BACK = [[549.6, 0.0, 559.2], [0.0, 0.0, 559.2], [0.0, 548.8, 559.2], [556.0, 548.8, 559.2]]
_CB_RIGHT = [[0.0, 0.0, 559.2], [0.0, 0.0, 0.0], [0.0, 548.8, 0.0], [0.0, 548.8, 559.2]]  # green
_CB_LEFT = [[552.8, 0.0, 0.0], [549.6, 0.0, 559.2], [556.0, 548.8, 559.2], [556.0, 548.8, 0.0]]  # red
_CB_CEILING_Y = 548.8
_CB_CEILING = (0.0, 556.0, 0.0, 559.2)  # x0, x1, z0, z1
_CB_HOLE = (213.0, 343.0, 227.0, 332.0)  # where the light was
_CB_SHORT = [[130.0, 65.0], [82.0, 225.0], [240.0, 272.0], [290.0, 114.0]], 165.0  # (x, z) footprint, height
_CB_TALL = [[423.0, 247.0], [265.0, 296.0], [314.0, 456.0], [472.0, 406.0]], 330.0


def lumpy_mesh(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float32, faces (F, 3) int32) of a displaced icosphere (radius ~1) standing on
    a wavy terrain grid of about as many triangles: an uneven triangle soup of any size for the
    kd-tree's tests and benchmark (not a scene)."""
    import trimesh.creation

    s = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = s.vertices * (1 + 0.1 * np.sin(5 * s.vertices[:, :1]) * np.cos(7 * s.vertices[:, 1:2]))
    n = int(np.sqrt(len(s.faces) / 2)) + 1
    xs = np.linspace(-3, 3, n)
    gx, gz = np.meshgrid(xs, xs)
    gy = -1.2 + 0.1 * np.sin(3 * gx) * np.cos(2 * gz)
    tv = np.stack([gx, gy, gz], -1).reshape(-1, 3)
    idx = np.arange(n * n).reshape(n, n)
    q = np.stack([idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]], -1).reshape(-1, 4)
    tf = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    return (np.concatenate([v, tv]).astype(np.float32),
            np.concatenate([s.faces, tf + len(v)]).astype(np.int32))


def cornell_scene() -> Scene:
    mm = 0.001
    b = SceneBuilder()
    b.material("white", albedo=(0.725, 0.71, 0.68))
    b.material("red", albedo=(0.63, 0.065, 0.05))
    b.material("green", albedo=(0.14, 0.45, 0.091))
    b.quad("white", np.array(_CB_FLOOR) * mm, normal=_Y, uv_scale=1.0)
    b.quad("white", np.array(_CB_BACK) * mm, normal=(0.0, 0.0, -1.0))
    b.quad("green", np.array(_CB_RIGHT) * mm, normal=(1.0, 0.0, 0.0))
    b.quad("red", np.array(_CB_LEFT) * mm, normal=(-1.0, 0.0, 0.0))
    x0, x1, z0, z1 = _CB_CEILING
    hx0, hx1, hz0, hz1 = _CB_HOLE
    y = _CB_CEILING_Y
    pieces = [(x0, x1, z0, hz0), (x0, x1, hz1, z1), (x0, hx0, hz0, hz1), (hx1, x1, hz0, hz1)]
    quads = []
    for a0, a1, c0, c1 in pieces:
        corners = np.array([[a0, y, c0], [a1, y, c0], [a1, y, c1], [a0, y, c1]]) * mm
        b.quad("white", corners, normal=-_Y)
        quads.append(OcclusionQuad(corners.mean(0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), (c1 - c0) * mm / 2,
                                   (a1 - a0) * mm / 2))
    for footprint, height in (_CB_SHORT, _CB_TALL):
        fp = np.array(footprint) * mm
        h = height * mm
        bottom = np.stack([fp[:, 0], np.zeros(4), fp[:, 1]], 1)
        top = bottom + _Y * h
        centre = np.concatenate([bottom, top]).mean(0)
        b.quad("white", top, normal=_Y)
        for k in range(4):
            q = np.array([bottom[k], bottom[(k + 1) % 4], top[(k + 1) % 4], top[k]])
            b.quad("white", q, normal=q.mean(0) - centre)
    for corners, normal in ((_CB_BACK, (0, 0, -1)), (_CB_RIGHT, (1, 0, 0)), (_CB_LEFT, (-1, 0, 0))):
        c = np.array(corners) * mm
        centre = c.mean(0)
        right = np.cross(_Y, np.asarray(normal, float))
        ext = np.abs((c - centre) @ right).max()
        quads.append(OcclusionQuad(centre, _Y, right, 0.2744, ext))
    fov = math.degrees(2 * math.atan(12.5 / 35.0))
    camera = Camera(position=(0.278, 0.273, -0.8), target=(0.278, 0.273, 0.0), fov_y_deg=fov, near=0.01, far=10.0)
    sun = Sun(direction_from_angles(70.0, 170.0))
    return b.scene("cornell", camera, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"), quads)


def thin_wall_scene() -> Scene:
    b = SceneBuilder()
    b.material("ground", albedo=(0.5, 0.5, 0.5))
    b.material("wall", albedo=(0.8, 0.8, 0.8))
    b.material("red", albedo=(0.8, 0.1, 0.08))
    b.rect("ground", (0.0, 0.0, 0.0), (15.0, 0.0, 0.0), (0.0, 0.0, -15.0), 0.5)
    lo, hi = (-5.0, 0.0, -0.025), (5.0, 4.0, 0.025)
    b.box("wall", lo, hi, skip=("-y",))
    b.box("red", (-0.5, 0.0, 1.0), (0.5, 1.0, 2.0), skip=("-y",))
    quads = [OcclusionQuad((0.0, 2.0, 0.0), _Y, (1.0, 0.0, 0.0), 2.0, 5.0)]
    camera = Camera(position=(3.0, 1.7, -8.0), target=(0.0, 1.5, 0.0), fov_y_deg=60.0, near=0.05, far=100.0)
    sun = Sun(direction_from_angles(35.0, 180.0))
    return b.scene("thin-wall", camera, sun, Sky(), quads, None)


def _terrain_height(x: np.ndarray, z: np.ndarray, seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    h = 6.0 * np.sin(0.08 * x + 0.3) * np.cos(0.06 * z) + 3.0 * np.sin(0.19 * x - 0.13 * z)
    h += 10.0 * np.exp(-(((z + 25.0) / 6.0) ** 2)) * (0.6 + 0.4 * np.sin(0.1 * x))
    noise = rng.normal(0.0, 1.0, size=x.shape)
    for _ in range(3):  # smooth the noise a little (periodic box blur)
        noise = (noise + np.roll(noise, 1, 0) + np.roll(noise, -1, 0)
                 + np.roll(noise, 1, 1) + np.roll(noise, -1, 1)) / 5
    return h + 1.5 * noise


def terrain_scene() -> Scene:
    n, half = 81, 40.0
    xs = np.linspace(-half, half, n)
    x, z = np.meshgrid(xs, xs)
    y = _terrain_height(x, z)
    pos = np.stack([x, y, z], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing="ij")
    v00 = (i * n + j).ravel()
    v01, v10, v11 = v00 + 1, v00 + n, v00 + n + 1
    # rows go south (+z), columns east (+x): (v00, v10, v11) is counter-clockwise seen from above
    faces = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)])
    b = SceneBuilder()
    b.material("grass", albedo=(0.22, 0.32, 0.12), specular=0.02, shininess=8.0)
    b.add("grass", pos, vertex_normals(pos, faces), pos[:, [0, 2]] / 8.0, faces)
    quads = []
    for qx in (-20.0, 20.0):
        for qz in (-20.0, 20.0):
            sel = (np.abs(pos[:, 0] - qx) <= 20.0) & (np.abs(pos[:, 2] - qz) <= 20.0)
            p = pos[sel]
            c = p.mean(0)
            _, _, vt = np.linalg.svd(p - c)
            nrm = vt[2] if vt[2][1] > 0 else -vt[2]
            right = np.array([1.0, 0.0, 0.0]) - nrm * nrm[0]
            right /= np.linalg.norm(right)
            up = np.cross(nrm, right)
            quads.append(OcclusionQuad(c, up, right, 20.0 / max(abs(up[2]), 0.2), 20.0 / max(abs(right[0]), 0.2)))
    camera = Camera(position=(-30.0, 20.0, 32.0), target=(5.0, 2.0, -5.0), fov_y_deg=55.0, near=0.2, far=400.0)
    sun = Sun(direction_from_angles(25.0, 240.0))
    return b.scene("terrain", camera, sun, Sky(), quads, None)


def mirror_box_scene() -> Scene:
    b = SceneBuilder()
    b.material("floor", albedo=(1.0, 1.0, 1.0), albedo_texture=tile_texture(), specular=0.04, shininess=16.0)
    b.material("wall", albedo=(0.75, 0.75, 0.72))
    b.material("mirror", albedo=(0.05, 0.05, 0.05), specular=0.9, shininess=2000.0, reflectivity=0.95)
    b.material("red", albedo=(0.8, 0.1, 0.08))
    b.material("blue", albedo=(0.1, 0.2, 0.8))
    b.material("yellow", albedo=(0.85, 0.75, 0.1))
    b.rect("floor", (0.0, 0.0, 0.0), (4.0, 0.0, 0.0), (0.0, 0.0, -4.0), 0.5)
    h, t = 3.0, 0.2
    walls = [((-4.0 - t, 0.0, -4.0 - t), (4.0 + t, h, -4.0)), ((-4.0 - t, 0.0, 4.0), (4.0 + t, h, 4.0 + t)),
             ((-4.0 - t, 0.0, -4.0), (-4.0, h, 4.0)), ((4.0, 0.0, -4.0), (4.0 + t, h, 4.0))]
    quads = []
    for lo, hi in walls:
        b.box("wall", lo, hi, skip=("-y",))
        lo, hi = np.array(lo), np.array(hi)
        along_x = hi[0] - lo[0] > hi[2] - lo[2]
        right = np.array([1.0, 0.0, 0.0]) if along_x else np.array([0.0, 0.0, 1.0])
        quads.append(OcclusionQuad((lo + hi) / 2, _Y, right, h / 2, (hi - lo)[0 if along_x else 2] / 2))
    b.box("mirror", (-3.0, 0.3, -4.0), (3.0, 2.7, -3.96), skip=("-y", "-z"))
    b.box("red", (-2.5, 0.0, 2.5), (-1.5, 1.0, 3.5), skip=("-y",))
    b.cylinder("blue", (2.0, 0.0, 2.5), 0.5, 1.6, sections=24)
    b.sphere("yellow", (0.0, 0.6, 3.2), 0.6, subdivisions=3)
    camera = Camera(position=(0.0, 1.6, 1.0), target=(0.0, 1.4, -4.0), fov_y_deg=60.0, near=0.05, far=100.0)
    sun = Sun(direction_from_angles(50.0, 30.0))
    return b.scene("mirror-box", camera, sun, Sky(), quads, None)


def glass_scene() -> Scene:
    b = SceneBuilder()
    b.material("floor", albedo=(1.0, 1.0, 1.0), albedo_texture=tile_texture(), specular=0.04, shininess=16.0)
    b.material("glass", albedo=(0.95, 0.95, 0.95), specular=0.5, shininess=1000.0, transparency=0.95, ior=1.5)
    b.material("red", albedo=(0.8, 0.1, 0.08))
    b.material("blue", albedo=(0.1, 0.2, 0.8))
    b.rect("floor", (0.0, 0.0, 0.0), (10.0, 0.0, 0.0), (0.0, 0.0, -10.0), 0.5)
    b.box("glass", (-2.6, 0.0, -0.25), (-1.0, 1.2, 0.25), skip=("-y",))
    b.sphere("glass", (0.2, 0.8, 0.0), 0.8, subdivisions=3)
    b.prism("glass", [(1.4, 0.0), (2.8, 0.0), (2.1, 1.2)], -0.6, 0.6, skip_sides=(0,))  # rests on the floor
    for x, mat in ((-2.0, "red"), (0.2, "blue"), (2.1, "red")):
        b.box(mat, (x - 0.15, 0.0, -2.2), (x + 0.15, 2.0, -1.9), skip=("-y",))
    camera = Camera(position=(0.0, 1.5, 5.0), target=(0.0, 0.7, 0.0), fov_y_deg=50.0, near=0.05, far=100.0)
    sun = Sun(direction_from_angles(40.0, 210.0))
    return b.scene("glass", camera, sun, Sky(), [], None)


def courtyard_van_scene() -> Scene:
    """The courtyard with a van driving along its south side and back (8 s each way, ``pingpong``):
    a rigid body of four meshes that one animation track each moves alike
    (``serenity.scene.animation``; ``serenity render courtyard-van --at SECONDS``)."""
    scene = courtyard_scene(name="courtyard-van")
    b = SceneBuilder()
    b.material("van_paint", albedo=(0.70, 0.12, 0.08), specular=0.3, shininess=120.0)
    b.material("van_trim", albedo=(0.04, 0.04, 0.04), specular=0.05, shininess=16.0)
    b.material("van_window", albedo=(0.05, 0.06, 0.07), specular=0.6, shininess=800.0)
    x0, z0 = -12.0, 11.0  # the van's centre as built, on the ground
    b.box("van_paint", (x0 - 2.3, 0.35, z0 - 0.9), (x0 + 2.3, 1.35, z0 + 0.9), 0.5, skip=("-y",))
    b.box("van_paint", (x0 - 2.3, 1.35, z0 - 0.85), (x0 + 0.9, 2.2, z0 + 0.85), 0.5)
    b.box("van_window", (x0 + 0.9, 1.4, z0 - 0.8), (x0 + 0.95, 2.1, z0 + 0.8))
    for dx in (-1.5, 1.5):
        for dz in (-0.75, 0.75):
            b.box("van_trim", (x0 + dx - 0.35, 0.0, z0 + dz - 0.12), (x0 + dx + 0.35, 0.7, z0 + dz + 0.12), 0.5)
    van = b.scene("van", scene.camera, scene.sun)
    scene.camera = Camera(position=(-13.0, 3.2, 1.5), target=(3.0, 1.0, 11.0), fov_y_deg=60.0, near=0.1, far=300.0)
    offset = len(scene.materials)
    meshes = [dataclasses.replace(m, face_material=m.face_material + offset) for m in van.meshes]
    route = [[0.0, 0.0, 0.0], [24.0, 0.0, 0.0]]
    tracks = [Track(m.name, [0.0, 8.0], translation=route, repeat="pingpong") for m in meshes]
    return dataclasses.replace(scene, meshes=scene.meshes + meshes, materials=scene.materials + van.materials,
                               animation=Animation(tracks))


def night_scene() -> Scene:
    return courtyard_scene(time="2024-06-21 23:30 +01:00", name="night")


def plane_scene(elevation_deg: float = 60.0, azimuth_deg: float = 180.0, albedo: float = 0.5,
                irradiance: float = 1000.0) -> Scene:
    """A single 40 × 40 m diffuse plane at y = 0 (albedo ``albedo``), the sun at (elevation, azimuth)
    with ``irradiance`` W·m⁻² per channel, a black constant sky, the camera looking down at 40°."""
    b = SceneBuilder()
    b.material("plane", albedo=(albedo,) * 3)
    b.rect("plane", (0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, -20.0), 0.25)
    camera = Camera(position=(0.0, 10.0, 12.0), target=(0.0, 0.0, -1.0), fov_y_deg=50.0, near=0.1, far=200.0)
    sun = Sun(direction_from_angles(elevation_deg, azimuth_deg), irradiance=(irradiance,) * 3)
    return b.scene("plane", camera, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"), [], None)


def penumbra_scene() -> Scene:
    """A 6 m pole and a 1 m cube on a grey plane, the sun 30° high: the pole's shadow tip lies 10 m
    from its base, where the real sun's 0.53° disc spreads a ~9 cm penumbra (paper Fig. 4)."""
    b = SceneBuilder()
    b.material("ground", albedo=(0.5, 0.5, 0.5))
    b.material("pole", albedo=(0.7, 0.7, 0.7))
    b.rect("ground", (0.0, 0.0, 0.0), (20.0, 0.0, 0.0), (0.0, 0.0, -20.0), 0.25)
    b.box("pole", (-0.15, 0.0, -0.15), (0.15, 6.0, 0.15), skip=("-y",))
    b.box("pole", (1.5, 0.0, -1.5), (2.5, 1.0, -0.5), skip=("-y",))
    sun = Sun(direction_from_angles(30.0, 200.0))
    along = -np.array([sun.direction[0], 0.0, sun.direction[2]])
    along /= np.linalg.norm(along)
    tip = along * 6.0 / math.tan(math.radians(30.0))
    side = np.cross(along, _Y)
    camera = Camera(position=tip - along * 1.0 + side * 2.5 + _Y * 2.0, target=tip - along * 0.8,
                    fov_y_deg=40.0, near=0.05, far=100.0)
    return b.scene("penumbra", camera, sun, Sky(radiance=(0.0, 0.0, 0.0), model="constant"), [], None)


_SCENES: dict[str, tuple[Callable[[], Scene], str]] = {
    "courtyard": (courtyard_scene, "outdoor square enclosed by buildings: arches, glass windows, a mirror door "
                                   "(default)"),
    "cornell": (cornell_scene, "the classic Cornell box, lit by the sun through a hole where its light was"),
    "thin-wall": (thin_wall_scene, "a 5 cm wall lit on one side: light must not leak through (LPV stability)"),
    "terrain": (terrain_scene, "an irregular height field that occlusion quads fit badly"),
    "mirror-box": (mirror_box_scene, "a roofless room with a mirror reflecting objects behind the camera"),
    "glass": (glass_scene, "glass slab, sphere and prism: refraction and total internal reflection"),
    "night": (night_scene, "the courtyard at 23:30, the sun below the horizon"),
    "courtyard-van": (courtyard_van_scene, "the courtyard with a van driving across it and back (animated: "
                                           "--at SECONDS, 16 s a round)"),
    "penumbra": (penumbra_scene, "a 6 m pole's shadow under the 0.53 deg sun: hard vs PCF vs PCSS (paper Fig. 4)"),
    "plane": (lambda: plane_scene(), "one diffuse plane (albedo 0.5), sun at 60 deg elevation, black sky"),
}


def scene_names() -> list[str]:
    """Names of the built-in scenes, the default (``courtyard``) first."""
    return list(_SCENES)


def scene_descriptions() -> dict[str, str]:
    """One line per built-in scene, for ``serenity scenes``."""
    return {k: v[1] for k, v in _SCENES.items()}


def build_scene(name: str) -> Scene:
    """Build the built-in scene ``name`` (a fresh, independent Scene each call)."""
    if name not in _SCENES:
        raise SceneError(f"unknown built-in scene {name!r} (built-in: {', '.join(_SCENES)})")
    return _SCENES[name][0]()
