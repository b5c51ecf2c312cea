"""Light propagation volumes on the GL side (paper §8): the cascades as 3-D textures for
``glsl/lpv.glsl``'s ``lpv_irradiance`` / ``lpv_glossy``, and a probe pass that evaluates them at
arbitrary points (tests, debugging).

``LPVTexturesGL.upload(lpv)`` takes any object shaped like ``serenity.kernels.lpv
.LightPropagationVolume`` (``grids``, ``textures(c)``, ``config``, ``glossy_step_length()``) — this
module never imports a kernel module (docs/architecture.md, Layers). Four RGBA32F 3-D textures, each an
atlas of the active cascades stacked along z (cascade c from z texel ``zofs[c]`` on): R, G, B, RGBA =
L1 SH (Y0, x, y, z) of intensity in W/sr, LINEAR (the shader clamps to a cascade's block), and face
openness (``openness(c)``, the lookup occlusion; RGB = +x, +y, +z faces of each cell, A = where their
blockers lie, packed). One set of samplers for every cascade is what lets lpv.glsl loop over the
cascades and stop once a point's weight is spent.
"""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.config import LPV_MAX_CASCADES
from serenity.raster.context import fullscreen_vao, load_program, uniform
from serenity.raster.interop import upload_texture3d

MAX_CASCADES = LPV_MAX_CASCADES
CHANNELS = ("r", "g", "b")
UNITS = len(CHANNELS) + 1  # texture units ``bind`` uses, from ``first_unit`` on


def lookup_switches(cfg) -> dict[str, bool]:
    """lpv.glsl's lookup switches for an LPVConfig: the leak guard, the lookup occlusion (with the
    guard and the geometry volume) and the lookup planes (with the occlusion)."""
    occlusion = bool(cfg.leak_guard and cfg.lookup_occlusion and cfg.geometry_volume)
    return {"leak_guard": bool(cfg.leak_guard), "occlusion": occlusion, "planes": occlusion and bool(cfg.lookup_planes)}


def lookup_defines(cfg) -> dict[str, int]:
    """The same switches (and the self-illumination damping) as lpv.glsl's compile-time defines: a
    program built with them runs only the lookup paths the config takes (llvmpipe runs the code of a
    branch a uniform skips)."""
    sw = lookup_switches(cfg)
    return {"LPV_LEAK_GUARD": int(sw["leak_guard"]), "LPV_OCCLUSION": int(sw["occlusion"]),
            "LPV_PLANES": int(sw["planes"]), "LPV_DAMPING": int(cfg.self_damping > 0)}


class LPVTexturesGL:
    """The LPV's cascades as 4 sampler3D atlases (RGB + openness, the cascades stacked along z) plus the
    lookup uniforms of lpv.glsl."""

    def __init__(self, ctx):
        self.ctx = ctx
        zero = np.zeros((1, 1, 1, 4), np.float32)
        self._empty = upload_texture3d(ctx, zero)
        self.textures: list = [self._empty] * UNITS  # the atlases: R, G, B, openness
        self.count = 0
        self.zofs = np.zeros(MAX_CASCADES, np.int32)  # cascade c's first z texel in the atlases
        self.geom = np.zeros((MAX_CASCADES, 4), np.float32)
        self.res = np.ones(MAX_CASCADES, np.int32)
        self.lookup_offset = 0.5
        self.leak_guard = True
        self.occlusion = False
        self.planes = False
        self.damp_dist = 0.0
        self.damp_pow = 2.0
        self.margin = 0.5
        self.band = 2.0
        self.glossy_steps = 8
        self.glossy_step = 1.0

    def upload(self, lpv) -> None:
        """Copy the active cascades' accumulated SH (``lpv.textures(c)``) and their placement."""
        cfg = lpv.config
        grids = list(lpv.grids)[:MAX_CASCADES]
        self.count = len(grids)
        if not grids:
            self._drop()
        else:
            self.geom[:] = 0.0
            self.res[:] = 1
            self.zofs[:] = 0
            for c, g in enumerate(grids):
                self.geom[c, :3], self.geom[c, 3] = g.origin, g.cell_size
                self.res[c] = g.resolution
            side = int(self.res[:self.count].max())
            self.zofs[1:self.count] = np.cumsum(self.res[:self.count - 1])
            shape = (side, side, int(self.res[:self.count].sum()))  # (W, H, D)
            blocks = [(*lpv.textures(c), lpv.openness(c)) for c in range(self.count)]
            for k in range(UNITS):
                tex = self.textures[k]
                if tex is self._empty or tex.size != shape:  # (re)allocated when the cascades' sizes change
                    if tex is not self._empty:
                        tex.release()
                    tex = self.textures[k] = upload_texture3d(self.ctx, np.zeros((shape[2], side, side, 4), np.float32))
                for c, b in enumerate(blocks):  # each cascade's block in place
                    r = int(self.res[c])
                    tex.write(np.ascontiguousarray(b[k], np.float32).tobytes(),
                              viewport=(0, 0, int(self.zofs[c]), r, r, r))
        self.lookup_offset = float(cfg.lookup_offset)
        sw = lookup_switches(cfg)
        self.leak_guard, self.occlusion, self.planes = sw["leak_guard"], sw["occlusion"], sw["planes"]
        self.damp_dist = float(cfg.self_damping)
        self.damp_pow = float(cfg.self_damping_power)
        self.margin = float(cfg.edge_margin)
        self.band = float(cfg.blend_cells)
        self.glossy_steps = int(cfg.glossy_steps)
        self.glossy_step = float(lpv.glossy_step_length())

    def _drop(self) -> None:
        for k in range(UNITS):
            if self.textures[k] is not self._empty:
                self.textures[k].release()
                self.textures[k] = self._empty

    def bind(self, program, first_unit: int = 8) -> None:
        """Bind the 4 atlases to units first_unit..first_unit+3 and set lpv.glsl's uniforms on
        ``program`` (uniforms the compiler optimised away are skipped)."""
        for k, ch in enumerate((*CHANNELS, "o")):
            unit = first_unit + k
            self.textures[k].use(location=unit)
            if (u := uniform(program, f"u_lpv_{ch}")) is not None:
                u.value = unit
        self._write(program, "u_lpv_geom", self.geom, 4)
        self._write(program, "u_lpv_res", self.res, 1)
        self._write(program, "u_lpv_zofs", self.zofs, 1)
        if (u := uniform(program, "u_lpv_atlas")) is not None:
            u.value = tuple(float(x) for x in self.textures[0].size)
        for name, value in (("u_lpv_count", int(self.count)), ("u_lpv_leak_guard", self.leak_guard),
                            ("u_lpv_occlusion", self.occlusion), ("u_lpv_planes", self.planes),
                            ("u_lpv_glossy_steps", int(self.glossy_steps)),
                            ("u_lpv_lookup_offset", self.lookup_offset), ("u_lpv_margin", self.margin),
                            ("u_lpv_band", self.band), ("u_lpv_glossy_step", self.glossy_step),
                            ("u_lpv_damp_dist", self.damp_dist), ("u_lpv_damp_pow", self.damp_pow)):
            if (u := uniform(program, name)) is not None:
                u.value = value

    @staticmethod
    def _write(program, name: str, values: np.ndarray, width: int) -> None:
        u = uniform(program, name)
        if u is None:
            return
        n = max(1, int(u.array_length))
        u.write(np.ascontiguousarray(values.reshape(-1)[: n * width]).tobytes())

    def release(self) -> None:
        self._drop()
        self._empty.release()


class LPVProbeGL:
    """Evaluate ``lpv_irradiance`` and ``lpv_glossy`` at given points with a fullscreen pass
    (``glsl/lpv_probe.glsl``): the GL half of the Warp-vs-GLSL lookup check. ``defines``: the lookup's
    switches compiled in (``lookup_defines``, as the renderer's passes have them); else the uniforms."""

    def __init__(self, ctx, defines: dict | None = None):
        self.ctx = ctx
        self.program = load_program(ctx, "lpv_probe.glsl", defines=defines)
        self.vao = fullscreen_vao(ctx, self.program)
        self.textures = LPVTexturesGL(ctx)
        self._size = None
        self._inputs: list = []
        self._outputs: list = []
        self._fbo = None

    def _release_targets(self) -> None:
        if self._fbo is not None:
            # never leave a deleted framebuffer bound: moderngl re-binds the current one after
            # creating a framebuffer, which fails (GL_INVALID_OPERATION) if it was deleted
            if self.ctx.fbo is self._fbo:
                self.ctx.detect_framebuffer(0).use()
            self._fbo.release()
        for t in (*self._inputs, *self._outputs):
            t.release()
        self._fbo, self._inputs, self._outputs, self._size = None, [], [], None

    def evaluate(self, lpv, points, directions, shininess, width: int = 64) -> tuple[np.ndarray, np.ndarray]:
        """(irradiance (N,3) W/m², glossy radiance (N,3)) at points (N,3) with unit directions (N,3)
        (the normal for irradiance, the reflected direction for glossy) and Phong exponents."""
        ctx = self.ctx
        p = np.asarray(points, np.float32).reshape(-1, 3)
        n = p.shape[0]
        h = -(-n // width)
        pts = np.zeros((h * width, 4), np.float32)
        dirs = np.zeros((h * width, 4), np.float32)
        dirs[:, 1] = 1.0
        pts[:n, :3] = p
        dirs[:n, :3] = np.asarray(directions, np.float32).reshape(-1, 3)
        dirs[:n, 3] = np.broadcast_to(np.asarray(shininess, np.float32), (n,))
        # raw rows in, raw rows out: pixel (x, y) <-> item y·width + x (no flips needed)
        if self._size != (width, h):
            self._release_targets()
            self._inputs = [ctx.texture((width, h), 4, dtype="f4") for _ in range(2)]
            self._outputs = [ctx.texture((width, h), 4, dtype="f4") for _ in range(2)]
            for t in (*self._inputs, *self._outputs):
                t.filter = (moderngl.NEAREST, moderngl.NEAREST)
            self._fbo = ctx.framebuffer(color_attachments=self._outputs)
            self._size = (width, h)
        tp, td = self._inputs
        tp.write(pts.tobytes())
        td.write(dirs.tobytes())
        with ctx.debug_scope("lpv_probe"):
            self.textures.upload(lpv)
            self._fbo.use()
            self._fbo.clear(0.0, 0.0, 0.0, 0.0)
            tp.use(location=0)
            td.use(location=1)
            self.program["u_points"].value = 0
            self.program["u_dirs"].value = 1
            self.textures.bind(self.program, first_unit=2)
            self.vao.render(moderngl.TRIANGLES, vertices=3)
            res = [np.frombuffer(o.read(), np.float32).reshape(-1, 4)[:n, :3].copy() for o in self._outputs]
        return res[0], res[1]

    def release(self) -> None:
        self._release_targets()
        self.textures.release()
        self.vao.release()
        self.program.release()
