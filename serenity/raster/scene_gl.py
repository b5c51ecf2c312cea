"""The scene's geometry and textures on the GL side, uploaded once (static scenes).

Faces are sorted by material; each mesh's triangles of one material are one indexed draw range
with the world box of its triangles (``DrawRange.lo``/``hi``, for frustum culling: ``culling.py``);
vertex buffer
layout: position (3 f4), normal (3 f4), uv (2 f4); a scene with normal maps has a second buffer of
tangents (4 f4: xyz and the handedness w, ``Scene.merged_tangents``).

Index buffer order: the shadow casters' opaque triangles, then the casters of alpha-tested
materials (cut-outs: ``Material.alpha_tested``), then the bottom plane's triangles, each group by
material and within it by mesh — so the shadow pass draws the opaque casters it does not cull in
one call per run of adjacent ranges and the cut-outs, which need their texture's alpha, range by
range. After them come the coarser levels of detail of the dense meshes (``serenity.scene.lod``;
only meshes of opaque, rasterised materials off the bottom plane have them), mesh by mesh, level by
level and material by material: index lists into the same vertices. ``SceneGL.levels`` picks a
level per mesh for a view; a pass draws the ranges of those levels (``CulledRanges.visible``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from serenity.config import RenderConfig
from serenity.raster.context import anisotropy
from serenity.raster.culling import CulledRanges
from serenity.raster.interop import upload_texture
from serenity.scene.lod import scene_levels
from serenity.scene.model import used_vertices, vertex_tangents

#: the default bound on a level of detail's error, in pixels of the image it is drawn into (or texels
#: of a shadow map): a mesh is drawn at the coarsest level whose surface lies at most this far from
#: its own, measured at the mesh's nearest point (0 = always the full mesh)
LOD_PIXEL_ERROR = RenderConfig.lod_pixel_error


@dataclass
class DrawRange:
    material: int
    first: int   # first index in the index buffer
    count: int   # number of indices
    lo: np.ndarray | None = None  # (3,) world box of its triangles (float32 values)
    hi: np.ndarray | None = None
    mesh: int = -1   # the scene mesh its triangles belong to (-1: several)
    level: int = 0   # its level of detail (0: the mesh's own triangles; ``serenity.scene.lod``)


def bottom_plane_triangles(positions: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F,) bool: the triangles lying in the plane of the scene's lowest point (y = min y, within
    1e-6 of the scene's height): a ground under everything. Nothing lies below it, so it shadows
    nothing — the shadow maps leave it out (on a CPU rasteriser a shadow tile costs its covered
    texels, and the ground covers most of every tile); where it would have been, the map holds
    the far plane, which lights a receiver just as the ground's own depth did."""
    if not len(faces):
        return np.zeros(0, bool)
    y = np.asarray(positions, np.float64)[:, 1]
    eps = 1e-6 * max(float(y.max() - y.min()), 1.0)
    return np.all(y[faces] <= y.min() + eps, axis=1)


class SceneGL:
    """VBO/IBO and per-material textures of a ``Scene``."""

    def __init__(self, ctx, scene):
        self.ctx = ctx
        animation = getattr(scene, "animation", None)
        #: indices of the meshes the scene's animation moves (``update_meshes`` rewrites their vertices)
        self.animated = sorted(i for i, m in enumerate(scene.meshes)
                               if animation is not None and m.name in animation.mesh_names)
        #: first vertex of each mesh in the vertex buffer (and one past the last)
        self.vertex_base = np.concatenate([[0], np.cumsum([len(m.positions) for m in scene.meshes])]).astype(np.int64)
        self._culled = []  # the CulledRanges made by ``culled``, refreshed when meshes move
        self.bounds = scene.bounds
        """(2, 3) the uploaded geometry's bounds (``Scene.bounds`` gathers every mesh's vertices: ~0.6 ms
        for the courtyard's, which the frame asked for up to four times)."""
        pos, nrm, uv, faces, fmat = scene.merged()
        floor = bottom_plane_triangles(pos, faces)
        mesh = np.repeat(np.arange(len(scene.meshes)), [len(m.faces) for m in scene.meshes])
        # casters first, then the bottom plane's triangles, each grouped by material (a stable sort:
        # within a material the meshes stay in their order)
        cut = np.array([m.alpha_tested for m in scene.materials], bool)
        masked = cut[fmat] if len(fmat) else np.zeros(0, bool)
        order = np.lexsort((fmat, masked, floor))
        faces, fmat, floor, masked, mesh = faces[order], fmat[order], floor[order], masked[order], mesh[order]
        self.ranges: list[DrawRange] = []
        #: the coarser levels' draw ranges (after ``ranges`` in the index buffer)
        self.lod_ranges: list[DrawRange] = []
        if len(fmat):
            group = np.stack([fmat, floor, mesh], axis=1)
            starts = np.concatenate([[0], np.flatnonzero(np.any(np.diff(group, axis=0), axis=1)) + 1])
            ends = np.concatenate([starts[1:], [len(fmat)]])
            corners = pos[faces]  # (F, 3, 3)
            lo = np.minimum.reduceat(corners.min(axis=1), starts).astype(np.float64)
            hi = np.maximum.reduceat(corners.max(axis=1), starts).astype(np.float64)
            for k, (s, e) in enumerate(zip(starts, ends, strict=True)):
                self.ranges.append(DrawRange(int(fmat[s]), int(s) * 3, int(e - s) * 3, lo[k], hi[k],
                                             mesh=int(mesh[s])))
        self.caster_index_count = int(np.count_nonzero(~floor)) * 3
        """Indices of the triangles that can cast a sun shadow: all but the bottom plane's, which
        come last in the index buffer (``bottom_plane_triangles``)."""
        self.opaque_caster_index_count = int(np.count_nonzero(~floor & ~masked)) * 3
        """The casters that need no alpha test: the first indices of the buffer."""
        self.opaque_caster_ranges = [r for r in self.ranges if r.first < self.opaque_caster_index_count]
        """Draw ranges of those casters (together the first ``opaque_caster_index_count`` indices)."""
        self.masked_caster_ranges = [r for r in self.ranges if scene.materials[r.material].alpha_tested
                                     and r.first < self.caster_index_count]
        """Draw ranges of the alpha-tested casters (drawn with the alpha test by the shadow pass)."""
        tangents = scene.merged_tangents() if scene.has_normal_maps else None
        lod_vertices, lod_faces = self._levels_of_detail(scene, floor, mesh, len(faces) * 3, len(pos))
        vertices = np.hstack([pos, nrm, uv]).astype(np.float32)
        # a level's vertex: its own position, the normal, uv and tangent of the vertex it came from
        levels = [np.hstack([p, vertices[src, 3:]]) for p, src in lod_vertices]
        self.vbo = ctx.buffer(np.concatenate([vertices, *levels]).astype(np.float32).tobytes())
        self.ibo = ctx.buffer(np.concatenate([faces.astype(np.int32), *lod_faces]).tobytes())
        self.tangent_vbo = None if tangents is None else ctx.buffer(
            np.concatenate([tangents, *(tangents[src] for _, src in lod_vertices)]).astype(np.float32).tobytes())
        self.materials = scene.materials
        self.textures = {}
        aniso = anisotropy(ctx)
        self.mean_texture_albedo = {}
        """material index → mean linear RGB of its albedo texture (passes coarser than the texture use it)."""
        self.normal_textures = {}
        """material index → its normal map (GL texture)."""
        for i, m in enumerate(scene.materials):
            t = m.albedo_texture
            # a cut-out keeps its texture's alpha (RGBA); one without a texture reads a white texel
            c = 4 if m.alpha_tested else 3
            if t is None and m.alpha_tested:
                white = np.ones((1, 1, 4), np.float32)
                self.textures[i] = upload_texture(ctx, white, dtype="f2", mips=[white])
            elif t is not None:
                self.mean_texture_albedo[i] = t.mips[0][..., :3].reshape(-1, 3).astype(np.float64).mean(axis=0)
                self.textures[i] = upload_texture(ctx, _channels(t.mips[0], c), dtype="f2",
                                                  mips=[_channels(mm, c) for mm in t.mips], anisotropy=aniso)
            if m.normal_texture is not None:
                nt = m.normal_texture
                self.normal_textures[i] = upload_texture(ctx, nt.mips[0][..., :3], dtype="f2",
                                                         mips=[mm[..., :3] for mm in nt.mips], anisotropy=aniso)
        self.triangle_count = len(faces)

    def _levels_of_detail(self, scene, floor: np.ndarray, face_mesh: np.ndarray, first: int, vertex_base: int):
        """Build the coarser levels (``lod_ranges``, the per-mesh boxes and errors ``levels`` reads);
        returns their vertices, as (positions, merged index of the vertex whose attributes each takes)
        per level, appended to the vertex buffer from ``vertex_base`` on, and their faces in
        index-buffer order from index ``first``."""
        meshes = scene.meshes
        n = len(meshes)
        self.mesh_lo = np.zeros((n, 3))
        self.mesh_hi = np.zeros((n, 3))
        for i, m in enumerate(meshes):
            if len(m.faces):
                self.mesh_lo[i], self.mesh_hi[i] = _used_box(m)
        on_floor = np.zeros(n, bool)
        on_floor[face_mesh[floor]] = True
        kept = [bool(m.faces.size) and not on_floor[i] and i not in self.animated
                and not any(scene.materials[k].alpha_tested or scene.materials[k].needs_ray_tracing
                            for k in np.unique(m.face_material))
                for i, m in enumerate(meshes)]
        levels = scene_levels(meshes, kept)
        depth = max((len(lv) for lv in levels if lv is not None), default=0)
        #: (meshes, 1 + levels) metres each level's surface may lie from the mesh's (inf: no such level)
        self.lod_error = np.full((n, depth + 1), np.inf)
        self.lod_error[:, 0] = 0.0
        vertices, out = [], []
        base = np.concatenate([[0], np.cumsum([len(m.positions) for m in meshes])])
        for i, lv in enumerate(levels):
            if lv is None:
                continue
            self.lod_error[i, 1:len(lv) + 1] = lv.error
            material = meshes[i].face_material
            for k in range(len(lv)):
                vertices.append((lv.positions[k], lv.vertex_source[k] + base[i]))
                fm = material[lv.source[k]]
                order = np.argsort(fm, kind="stable")
                faces, fm = lv.faces[k][order] + vertex_base, fm[order]
                vertex_base += len(lv.positions[k])
                starts = np.concatenate([[0], np.flatnonzero(np.diff(fm)) + 1, [len(fm)]])
                for a, b in zip(starts[:-1], starts[1:], strict=True):
                    self.lod_ranges.append(DrawRange(int(fm[a]), first, int(b - a) * 3, self.mesh_lo[i],
                                                     self.mesh_hi[i], mesh=i, level=k + 1))
                    first += int(b - a) * 3
                out.append(faces.astype(np.int32))
        return vertices, out

    def levels(self, view_proj: np.ndarray, width: int, height: int,
               max_error: float = LOD_PIXEL_ERROR) -> np.ndarray | None:
        """The level of detail to draw each mesh at in a ``width``×``height`` view through ``view_proj``
        (world → clip; perspective or orthographic): the coarsest whose error, projected at the point
        of the mesh's box nearest the eye (the smallest clip w), is at most ``max_error`` pixels.
        None when no mesh has levels or ``max_error`` is 0 (draw every mesh whole)."""
        if self.lod_error.shape[1] == 1 or max_error <= 0.0:
            return None
        m = np.asarray(view_proj, np.float64)
        c, e = (self.mesh_lo + self.mesh_hi) * 0.5, (self.mesh_hi - self.mesh_lo) * 0.5
        w = c @ m[3, :3] - e @ np.abs(m[3, :3]) + m[3, 3]     # the box's smallest clip w
        # pixels per metre: clip x and y change by at most |row| per metre, NDC spans 2 per image side
        per_m = max(np.linalg.norm(m[0, :3]) * width, np.linalg.norm(m[1, :3]) * height) * 0.5
        px = self.lod_error * (per_m / np.maximum(w, 1e-9))[:, None]
        ok = px <= max_error
        ok[w <= 1e-6] = False                                  # the eye inside or behind its box's near side
        ok[:, 0] = True
        return ok.shape[1] - 1 - np.argmax(ok[:, ::-1], axis=1)

    def culled(self, ranges) -> CulledRanges:
        """``CulledRanges`` of ``ranges`` whose boxes follow ``update_meshes``."""
        c = CulledRanges(ranges)
        self._culled.append(c)
        return c

    def update_meshes(self, scene) -> None:
        """Move the animated meshes to their pose in ``scene`` (this scene posed at another time,
        ``serenity.scene.animation.pose_scene``: the same meshes in the same order): their vertices
        in the vertex buffers, their draw ranges' boxes and the uploaded bounds."""
        if not self.animated:
            return
        for i in self.animated:
            m = scene.meshes[i]
            a, b = int(self.vertex_base[i]), int(self.vertex_base[i + 1])
            if len(m.positions) != b - a:
                raise ValueError(f"mesh {m.name!r}: {len(m.positions)} vertices, uploaded with {b - a}")
            block = np.hstack([m.positions, m.normals, m.uvs]).astype(np.float32)
            self.vbo.write(block.tobytes(), offset=a * block.shape[1] * 4)
            if self.tangent_vbo is not None:  # this mesh's only (Scene.merged_tangents computes every mesh's)
                t = vertex_tangents(m.positions, m.normals, m.uvs, m.faces)
                self.tangent_vbo.write(np.ascontiguousarray(t, np.float32).tobytes(), offset=a * 16)
            self.mesh_lo[i], self.mesh_hi[i] = _used_box(m)
        for r in self.ranges:
            if r.mesh in self.animated:
                m = scene.meshes[r.mesh]
                sel = m.faces[m.face_material == r.material]
                corners = m.positions[sel.reshape(-1)]
                r.lo, r.hi = corners.min(axis=0).astype(np.float64), corners.max(axis=0).astype(np.float64)
        self.bounds = scene.bounds
        for c in self._culled:
            c.refresh()

    def vao(self, program, with_attributes=("in_position", "in_normal", "in_uv", "in_tangent")):
        """A VAO binding this scene's buffers to ``program``'s attributes (unused ones skipped)."""
        fmt, names = [], []
        for attr, f, skip in (("in_position", "3f", "12x"), ("in_normal", "3f", "12x"), ("in_uv", "2f", "8x")):
            if attr in with_attributes and attr in program:
                fmt.append(f)
                names.append(attr)
            else:
                fmt.append(skip)
        fmt = " ".join(fmt)
        buffers = [(self.vbo, fmt, *names)]
        if self.tangent_vbo is not None and "in_tangent" in with_attributes and "in_tangent" in program:
            buffers.append((self.tangent_vbo, "4f", "in_tangent"))
        return self.ctx.vertex_array(program, buffers, index_buffer=self.ibo, index_element_size=4)

    def bind_alpha_test(self, program, material: int, location: int = 0) -> None:
        """Bind the texture and set the uniforms an ALPHA_MASK program variant (shadow_depth.glsl,
        rsm.glsl, gbuffer.glsl) reads for cut-out material ``material``."""
        m = self.materials[material]
        self.textures[material].use(location=location)
        program["u_albedo_tex"].value = location
        for k in range(2):
            program[f"u_albedo_uv{k}"].value = tuple(float(x) for x in m.albedo_uv_transform[k])
        program["u_alpha"].value = float(m.alpha)
        program["u_alpha_cutoff"].value = float(m.alpha_cutoff)

    def release(self):
        self.vbo.release()
        self.ibo.release()
        if self.tangent_vbo is not None:
            self.tangent_vbo.release()
        for t in (*self.textures.values(), *self.normal_textures.values()):
            t.release()


def _used_box(mesh) -> tuple[np.ndarray, np.ndarray]:
    """The box of the vertices ``mesh``'s faces use."""
    p = mesh.positions[used_vertices(mesh.faces, len(mesh.positions))]
    return p.min(axis=0), p.max(axis=0)


def _channels(a: np.ndarray, c: int) -> np.ndarray:
    """(H, W, c) of an (H, W, 3|4) mip level: RGB, or RGBA with alpha 1 where it has none."""
    if c == 3 or a.shape[2] == 4:
        return a[..., :c]
    return np.concatenate([a[..., :3], np.ones(a.shape[:2] + (1,), a.dtype)], axis=2)
