"""Sun shadow map: one orthographic depth map fitted to the scene's bounding sphere.

(Cascaded shadow maps + PCSS replace the single map in issue #7; overlapped shadow maps for the
ray-traced views in #5.) Biases, applied where the map is read (``deferred.glsl``): a constant
depth bias and a normal offset, both in units of one shadow-map texel, the normal offset scaled
by the slope tan(θ) (clamped to [1, 4]) so grazing surfaces do not acne.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from serenity.raster.context import load_program


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    f = target - eye
    f = f / np.linalg.norm(f)
    if abs(float(np.dot(f, up))) > 0.999:
        up = np.array([1.0, 0.0, 0.0]) if abs(f[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    r = np.cross(f, up)
    r /= np.linalg.norm(r)
    u = np.cross(r, f)
    m = np.eye(4)
    m[0, :3], m[1, :3], m[2, :3] = r, u, -f
    m[:3, 3] = -m[:3, :3] @ eye
    return m


def ortho(left, right, bottom, top, near, far) -> np.ndarray:
    m = np.eye(4)
    m[0, 0] = 2 / (right - left)
    m[1, 1] = 2 / (top - bottom)
    m[2, 2] = -2 / (far - near)
    m[0, 3] = -(right + left) / (right - left)
    m[1, 3] = -(top + bottom) / (top - bottom)
    m[2, 3] = -(far + near) / (far - near)
    return m


@dataclass
class ShadowMap:
    depth: object            # depth texture
    view_proj: np.ndarray    # world → light clip (4,4)
    texel_world: float       # one texel in metres
    depth_range: float       # light-space depth extent in metres
    size: int


class ShadowPass:
    def __init__(self, ctx, scene_gl, size: int = 2048):
        self.ctx = ctx
        self.size = size
        self.program = load_program(ctx, "shadow_depth.glsl")
        self.vao = scene_gl.vao(self.program, with_attributes=("in_position",))
        self.depth = ctx.depth_texture((size, size))
        import moderngl

        self.depth.filter = (moderngl.NEAREST, moderngl.NEAREST)
        self.depth.repeat_x = self.depth.repeat_y = False
        self.depth.compare_func = ""  # sampled as plain depth; the shader compares (PCF)
        self.fbo = ctx.framebuffer(depth_attachment=self.depth)

    @staticmethod
    def fit(sun_direction: np.ndarray, bounds: np.ndarray) -> tuple[np.ndarray, float]:
        """Light view-projection covering the bounding sphere of ``bounds``; returns (M, radius)."""
        center = bounds.mean(axis=0)
        radius = max(float(np.linalg.norm(bounds[1] - bounds[0])) / 2, 1e-3) * 1.01
        eye = center + np.asarray(sun_direction, np.float64) * radius * 2
        view = look_at(eye, center, np.array([0.0, 1.0, 0.0]))
        proj = ortho(-radius, radius, -radius, radius, radius * 0.5, radius * 3.5)
        return proj @ view, radius

    def render(self, sun_direction: np.ndarray, bounds: np.ndarray) -> ShadowMap:
        import moderngl

        ctx = self.ctx
        vp, radius = self.fit(sun_direction, bounds)
        with ctx.debug_scope("shadow"):
            self.fbo.use()
            self.fbo.clear(depth=1.0)
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.disable(moderngl.CULL_FACE)
            self.program["u_light_view_proj"].write(vp.T.astype(np.float32).tobytes())
            self.vao.render(moderngl.TRIANGLES)
            ctx.disable(moderngl.DEPTH_TEST)
        return ShadowMap(self.depth, vp, 2 * radius / self.size, 3.0 * radius, self.size)
