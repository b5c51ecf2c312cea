"""The scene's geometry and textures on the GL side, uploaded once (static scenes).

Faces are sorted by material so that each material is one indexed draw range; vertex buffer
layout: position (3 f4), normal (3 f4), uv (2 f4).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from serenity.raster.context import anisotropy
from serenity.raster.interop import upload_texture


@dataclass
class DrawRange:
    material: int
    first: int   # first index in the index buffer
    count: int   # number of indices


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
        self.bounds = scene.bounds
        """(2, 3) the uploaded geometry's bounds (``Scene.bounds`` gathers every mesh's vertices: ~0.6 ms
        for the courtyard's, which the frame asked for up to four times)."""
        pos, nrm, uv, faces, fmat = scene.merged()
        floor = bottom_plane_triangles(pos, faces)
        # casters first, then the bottom plane's triangles, each grouped by material
        order = np.lexsort((fmat, floor))
        faces, fmat, floor = faces[order], fmat[order], floor[order]
        self.ranges: list[DrawRange] = []
        if len(fmat):
            group = fmat.astype(np.int64) * 2 + floor
            bounds = np.flatnonzero(np.diff(group)) + 1
            starts = np.concatenate([[0], bounds])
            ends = np.concatenate([bounds, [len(fmat)]])
            for s, e in zip(starts, ends, strict=True):
                self.ranges.append(DrawRange(int(fmat[s]), int(s) * 3, int(e - s) * 3))
        self.caster_index_count = int(np.count_nonzero(~floor)) * 3
        """Indices of the triangles that can cast a sun shadow: all but the bottom plane's, which
        come last in the index buffer (``bottom_plane_triangles``)."""
        vertices = np.hstack([pos, nrm, uv]).astype(np.float32)
        self.vbo = ctx.buffer(vertices.tobytes())
        self.ibo = ctx.buffer(faces.astype(np.int32).tobytes())
        self.materials = scene.materials
        self.textures = {}
        aniso = anisotropy(ctx)
        self.mean_texture_albedo = {}
        """material index → mean linear RGB of its albedo texture (passes coarser than the texture use it)."""
        for i, m in enumerate(scene.materials):
            if m.albedo_texture is not None:
                t = m.albedo_texture
                self.mean_texture_albedo[i] = t.mips[0][..., :3].reshape(-1, 3).astype(np.float64).mean(axis=0)
                self.textures[i] = upload_texture(ctx, t.mips[0][..., :3], dtype="f2",
                                                      mips=[mm[..., :3] for mm in t.mips], anisotropy=aniso)
        self.triangle_count = len(faces)

    def vao(self, program, with_attributes=("in_position", "in_normal", "in_uv")):
        """A VAO binding this scene's buffers to ``program``'s attributes (unused ones skipped)."""
        fmt, names = [], []
        for attr, f, skip in (("in_position", "3f", "12x"), ("in_normal", "3f", "12x"), ("in_uv", "2f", "8x")):
            if attr in with_attributes and attr in program:
                fmt.append(f)
                names.append(attr)
            else:
                fmt.append(skip)
        fmt = " ".join(fmt)
        return self.ctx.vertex_array(program, [(self.vbo, fmt, *names)], index_buffer=self.ibo,
                                     index_element_size=4)

    def release(self):
        self.vbo.release()
        self.ibo.release()
        for t in self.textures.values():
            t.release()
