"""GL textures of the sky: the paraboloid sky map and the 7 textures of the sky irradiance volume.

``SkyTexturesGL(ctx)`` owns them; ``upload_sky_map`` / ``upload_volume`` take the arrays the
kernels produce (``atmosphere.SkyMapCache.sky_map``, ``SkyVolume.textures()`` and its grid) — this
module never imports a kernel (docs/architecture.md, Layers), it only takes numpy arrays. ``bind(program,
first_unit)`` binds the sky map to ``first_unit`` and the volume to the 7 units after it and sets
the uniforms of ``glsl/sky.glsl`` that the program uses:

    sampler2D u_sky_map;  sampler3D u_sky_volume[7];
    vec3 u_sky_origin (m);  vec3 u_sky_cell (m);  vec3 u_sky_res (X, Y, Z probes);
    float u_sky_normal_offset (m);  vec3 u_sky_open[9] (the open sky's coefficients, ``set_open_sky``)
    sampler3D u_sky_vis, u_sky_probe_offset (the gathered probes' visibility, ``upload_visibility``;
    read by programs built with ``SKY_VISIBILITY``)

A shader ``#include "sky.glsl"`` and calls ``sky_map_radiance(u_sky_map, dir)`` (the dome) and
``sky_irradiance(p, n)`` (adds albedo/π × it), or ``sky_irradiance_glossy(p, n, r, m, glossy)``
(also the radiance around r filtered by the Phong lobe of exponent m), which a lighting pass
multiplies by ``sky_horizon_occlusion(r, ng, m)``, the lobe's share above the surface's flat face
(``ng`` from ``gbuffer_flat_normal``: glsl/sky.glsl says why). Before any upload the textures are
1×1 black, so binding is always valid.

Uploads do not flip rows: sky-map array row i is texture row i (the mapping in sky.glsl and
``atmosphere.direction_to_paraboloid`` use that), volume arrays (Z, Y, X, C) are indexed as stored.
"""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.raster.context import fullscreen_vao, load_program, uniform
from serenity.raster.interop import upload_texture3d

VOLUME_TEXTURES = 7


def _texture2d(ctx, a: np.ndarray):
    a = np.ascontiguousarray(a, np.float32)
    h, w, c = a.shape
    tex = ctx.texture((w, h), c, a.tobytes(), dtype="f4")
    tex.filter = (moderngl.LINEAR, moderngl.LINEAR)
    tex.repeat_x = tex.repeat_y = False
    return tex


class SkyTexturesGL:
    def __init__(self, ctx):
        self.ctx = ctx
        self.sky_map = _texture2d(ctx, np.zeros((1, 1, 3), np.float32))
        self.volume = [upload_texture3d(ctx, np.zeros((1, 1, 1, 4 if t < 6 else 3), np.float32))
                       for t in range(VOLUME_TEXTURES)]
        self.origin = np.zeros(3)
        self.cell = np.ones(3)
        self.res = np.ones(3)
        self.normal_offset = 0.0
        self.open_sky = np.zeros((9, 3))
        #: the probes' depth moments and relocation offsets (``upload_visibility``; 1×1 until then)
        self.vis = upload_texture3d(ctx, np.zeros((1, 1, 1, 2), np.float32))
        self.probe_offset = upload_texture3d(ctx, np.zeros((1, 1, 1, 3), np.float32))
        self.visibility = False
        self._eval = None
        self._target = None

    def upload_sky_map(self, array: np.ndarray) -> None:
        """(S, S, 3) float32 paraboloid sky map (rewritten in place when the size is unchanged)."""
        a = np.ascontiguousarray(np.asarray(array, np.float32)[..., :3])
        if (self.sky_map.height, self.sky_map.width) == a.shape[:2]:
            self.sky_map.write(a.tobytes())
        else:
            self.sky_map.release()
            self.sky_map = _texture2d(self.ctx, a)

    def upload_volume(self, textures: list[np.ndarray], origin, cell_size, res, normal_offset: float = 0.0) -> None:
        """The 7 arrays of ``SkyVolume.textures()`` and the grid: origin (3,) m, cell_size (3,) or
        scalar m, res (X, Y, Z), normal_offset m (``SkyVolume.normal_offset_m``)."""
        if len(textures) != VOLUME_TEXTURES:
            raise ValueError(f"expected {VOLUME_TEXTURES} volume textures, got {len(textures)}")
        for t, arr in enumerate(textures):
            a = np.ascontiguousarray(arr, np.float32)
            want = 4 if t < 6 else 3
            if a.ndim != 4 or a.shape[3] != want:
                raise ValueError(f"volume texture {t} must be (Z, Y, X, {want}), got {a.shape}")
            tex = self.volume[t]
            if (tex.depth, tex.height, tex.width) == a.shape[:3]:
                tex.write(a)  # contiguous float32: written from its buffer, no bytes copy
            else:
                tex.release()
                self.volume[t] = upload_texture3d(self.ctx, a)
        self.origin = np.asarray(origin, np.float64).reshape(3)
        self.cell = np.broadcast_to(np.asarray(cell_size, np.float64), (3,)).copy()
        self.res = np.asarray(res, np.float64).reshape(3)
        self.normal_offset = float(normal_offset)

    def upload_visibility(self, atlas: np.ndarray, offsets: np.ndarray) -> None:
        """The gathered probes' visibility (``SkyVolume.visibility_textures``): the depth-moment atlas
        (Z·T, Y, X·T, 2) and the relocation offsets (Z, Y, X, 3), float32, read by programs built with
        ``SKY_VISIBILITY`` (texelFetch: no filtering)."""
        for name, arr in (("vis", atlas), ("probe_offset", offsets)):
            getattr(self, name).release()
            tex = upload_texture3d(self.ctx, np.asarray(arr, np.float32))
            tex.filter = (moderngl.NEAREST, moderngl.NEAREST)
            setattr(self, name, tex)
        self.visibility = True

    def set_open_sky(self, coefficients) -> None:
        """(9, 3) irradiance coefficients of the open sky (``SkyVolume.open_coefficients``): what the
        lookup fades to beyond the grid's sides and top."""
        self.open_sky = np.asarray(coefficients, np.float64).reshape(9, 3).copy()

    def upload_volume_layers(self, textures: list[np.ndarray], first_layer: int) -> None:
        """Overwrite y-layers ``first_layer`` .. of the uploaded volume with the 7 slab arrays of
        ``SkyVolume.textures(layers=...)`` ((Z, n, X, ·); the grid is unchanged)."""
        if len(textures) != VOLUME_TEXTURES:
            raise ValueError(f"expected {VOLUME_TEXTURES} volume textures, got {len(textures)}")
        for t, arr in enumerate(textures):
            a = np.ascontiguousarray(arr, np.float32)
            tex = self.volume[t]
            depth, n, width = a.shape[:3]
            if (depth, width) != (tex.depth, tex.width) or not 0 <= first_layer <= tex.height - n:
                raise ValueError(f"volume slab {a.shape[:3]} at layer {first_layer} does not fit the uploaded "
                                 f"volume ({tex.depth}, {tex.height}, {tex.width})")
            tex.write(a, viewport=(0, int(first_layer), 0, width, n, depth))

    def bind(self, program, first_unit: int) -> int:
        """Bind to texture units first_unit..first_unit+9 (the sky map, the volume's 7 textures, the
        visibility's 2) and set sky.glsl's uniforms; returns the next free unit."""
        self.sky_map.use(location=first_unit)
        for t, tex in enumerate(self.volume):
            tex.use(location=first_unit + 1 + t)
        vis_unit = first_unit + 1 + VOLUME_TEXTURES
        self.vis.use(location=vis_unit)
        self.probe_offset.use(location=vis_unit + 1)
        values = {
            "u_sky_map": first_unit,
            "u_sky_volume": tuple(range(first_unit + 1, first_unit + 1 + VOLUME_TEXTURES)),
            "u_sky_origin": tuple(float(x) for x in self.origin),
            "u_sky_cell": tuple(float(x) for x in self.cell),
            "u_sky_res": tuple(float(x) for x in self.res),
            "u_sky_normal_offset": self.normal_offset,
            "u_sky_open": tuple(tuple(float(x) for x in row) for row in self.open_sky),
            "u_sky_vis": vis_unit,
            "u_sky_probe_offset": vis_unit + 1,
        }
        for name, value in values.items():
            if (u := uniform(program, name)) is not None:
                u.value = value
        return vis_unit + 2

    # -- evaluation on the GPU (tests, debugging)

    def _run(self, mode: int, a: np.ndarray, b: np.ndarray | None, c: np.ndarray | None = None,
             shininess: float = 0.0) -> np.ndarray:
        ctx = self.ctx
        if self._eval is None or self._eval[2] != self.visibility:
            prog = load_program(ctx, "sky_eval.glsl", defines={"SKY_VISIBILITY": int(self.visibility)})
            self._eval = (prog, fullscreen_vao(ctx, prog), self.visibility)
        prog, vao, _ = self._eval
        a = np.asarray(a, np.float32).reshape(-1, 3)
        n = len(a)
        w = min(n, 256)
        h = -(-n // w)
        pad = np.zeros((w * h, 3), np.float32)

        def tex_of(x):
            p = pad.copy()
            p[:n] = x
            t = ctx.texture((w, h), 3, p.tobytes(), dtype="f4")
            return t

        ta = tex_of(a)
        tb = tex_of(np.asarray(b, np.float32).reshape(-1, 3) if b is not None else a)
        tc = tex_of(np.asarray(c, np.float32).reshape(-1, 3) if c is not None else a)
        # the target is kept (released only when the size changes, while another FBO is bound):
        # deleting the bound framebuffer makes moderngl rebind a dead id on the next FBO creation
        if self._target is None or self._target[0] != (w, h):
            out = ctx.texture((w, h), 4, dtype="f4")
            fbo = ctx.framebuffer(color_attachments=[out])
            fbo.use()
            if self._target is not None:
                self._target[1].release()
                self._target[2].release()
            self._target = ((w, h), fbo, out)
        _, fbo, out = self._target
        try:
            with ctx.debug_scope("sky_eval"):
                fbo.use()
                ctx.viewport = (0, 0, w, h)
                unit = self.bind(prog, 0)
                ta.use(location=unit)
                tb.use(location=unit + 1)
                tc.use(location=unit + 2)
                prog["u_in_a"].value = unit
                for name, u in (("u_in_b", unit + 1), ("u_in_c", unit + 2)):
                    if (m := uniform(prog, name)) is not None:
                        m.value = u
                if (m := uniform(prog, "u_shininess")) is not None:
                    m.value = float(shininess)
                prog["u_mode"].value = mode
                vao.render(vertices=3)
            res = np.frombuffer(out.read(), np.float32).reshape(w * h, 4)[:n, :3].copy()
        finally:
            ta.release()
            tb.release()
            tc.release()
        return res

    def evaluate_sky_map(self, directions) -> np.ndarray:
        """(N,3) ``sky_map_radiance`` evaluated by GL at (N,3) directions."""
        return self._run(0, directions, None)

    def evaluate_volume(self, points, normals) -> np.ndarray:
        """(N,3) ``sky_irradiance`` evaluated by GL at (N,3) points and normals."""
        return self._run(1, points, normals)

    def evaluate_volume_glossy(self, points, normals, directions, shininess: float) -> np.ndarray:
        """(N,3) the glossy radiance of ``sky_irradiance_glossy`` evaluated by GL at (N,3) points,
        normals and directions, for one Phong exponent."""
        return self._run(2, points, normals, directions, shininess)

    def evaluate_horizon_occlusion(self, directions, geometric_normals, shininess: float) -> np.ndarray:
        """(N,) ``sky_horizon_occlusion`` evaluated by GL for (N,3) mirror directions and geometric
        normals, for one Phong exponent: the share of the glossy lobe above the surface's face."""
        return self._run(3, directions, geometric_normals, None, shininess)[:, 0]
