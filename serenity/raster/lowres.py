"""Reduced-resolution views of the G-buffer.

``LowResGuide`` (``glsl/lowres_guide.glsl``): per low-res texel, the normal and view depth of its
representative G-buffer pixel (``glsl/lowres.glsl``), drawn once per frame for the SSAO blur and the
indirect light's joint bilateral upsampling, whose taps each read one guide texel instead of two
G-buffer texels; and each texel's class (background, surface, glossy surface) as its depth, which
the low-res indirect passes depth-test against to shade only the texels they need.
``IndirectRefinement`` (``glsl/upsample_refine.glsl``): the full-resolution pixels that no low-res
texel stands for, whose indirect light the same passes then compute at full resolution.
``GBufferSamples`` (``glsl/gbuffer_samples.glsl``): every n-th G-buffer pixel
gathered on the GL side, so the LPV's sky VPLs read back 1/n² of the G-buffer."""

from __future__ import annotations

import moderngl
import numpy as np

from serenity.raster.context import FullscreenPass, LowResLayout, low_res_layout
from serenity.raster.interop import read_texture


class _ClassDepthPass(FullscreenPass):
    """A fullscreen pass whose targets share a depth texture holding each texel's class
    (``glsl/lowres.glsl``: background, surface, glossy surface), laid out by ``_layout``, which the
    low-res passes drawn into the same targets depth-test against."""

    def __init__(self, ctx):
        super().__init__(ctx)
        self.depth = None
        self.layout: LowResLayout | None = None

    def _layout(self, width: int, height: int) -> LowResLayout:
        raise NotImplementedError

    def target_size(self, width: int, height: int) -> tuple[int, int]:
        return self._layout(width, height).texture_size

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        super().resize(width, height)
        if self.depth is not None:
            self.depth.release()
        self.fbo.release()
        self.layout = self._layout(width, height)
        self.depth = self.ctx.depth_texture(self.layout.texture_size)
        self.fbo = self.ctx.framebuffer(color_attachments=[getattr(self, name) for name in self.TARGETS],
                                        depth_attachment=self.depth)

    def _draw_classes(self, scope: str, textures: dict, layout: LowResLayout, **uniforms) -> None:
        """Draw the pass over every texel, each writing its class as its depth (depth test "always"):
        ``textures`` (uniform name → texture) on units 0, 1, …, ``layout``'s uniforms (the low-res
        image the shader reads or writes) and the other ``uniforms`` set."""
        p, ctx = self.program, self.ctx
        with ctx.debug_scope(scope):
            self.fbo.use()
            for loc, (name, tex) in enumerate(textures.items()):
                tex.use(location=loc)
                p[name].value = loc
            layout.set_uniforms(p)
            for name, value in uniforms.items():
                p[name].value = value
            ctx.enable(moderngl.DEPTH_TEST)
            ctx.depth_func = "1"
            try:
                self.vao.render(vertices=3)
            finally:
                ctx.disable(moderngl.DEPTH_TEST)
                ctx.depth_func = "<"


class LowResGuide(_ClassDepthPass):
    """The guide texture, and a depth texture of the same size holding each texel's class (background,
    surface, glossy surface: ``glsl/lowres.glsl``), which the low-res passes depth-test against."""

    SHADER = "lowres_guide.glsl"
    TARGETS = {"guide": (4, "f4")}

    def __init__(self, ctx, scale: int, balance: bool = True):
        super().__init__(ctx)
        self.scale = max(1, int(scale))
        self.balance = balance

    def _layout(self, width: int, height: int) -> LowResLayout:
        return low_res_layout(width, height, self.scale, self.balance)

    def resize(self, width: int, height: int) -> None:
        super().resize(width, height)
        self.fbo.viewport = self.layout.viewport

    def render(self, gbuffer, camera_pos, camera_forward):
        """The RGBA32F guide texture of ``gbuffer``: (W/scale, H/scale) texels laid out by ``layout``
        (the class depth alike)."""
        self._draw_classes("lowres guide", {"g_position": gbuffer.position, "g_normal": gbuffer.normal}, self.layout,
                           u_scale=self.scale, u_camera_pos=tuple(float(x) for x in camera_pos),
                           u_camera_forward=tuple(float(x) for x in camera_forward))
        return self.guide


class IndirectRefinement(_ClassDepthPass):
    """Indirect light at full resolution where the upsampling of the low-res light fails.

    The joint bilateral upsampling (``glsl/upsample.glsl``) fills a pixel from the 2×2 low-res texels
    around it, weighed by how alike their representative pixels are to it; a surface narrower than
    the low-res grid (a table's rounded edge, a chair's leg, a window's frame at quarter resolution)
    may have no representative among them, and then took the light of the surface beside it: the
    blocky, too bright or too dark steps along silhouettes. :meth:`classify` marks those pixels
    (best similarity below ``below``) and writes their class as its depth; the low-res indirect
    passes, drawn into this object as their target at scale 1, then shade those pixels only
    (llvmpipe rejects the others by depth before shading), and the deferred pass reads their light
    from here (``UPSAMPLE_REFINE``). A duck-typed target of ``IndirectPass.render`` as
    :class:`~serenity.raster.indirect.LowResIndirect` is: ``fbo`` (with the class depth), ``scale``
    1, ``layout`` the whole view, ``ao_div`` the AO's texels per pixel."""

    SHADER = "upsample_refine.glsl"
    TARGETS = {"irr": (4, "f2"), "gloss": (4, "f2")}
    scale = 1

    def __init__(self, ctx, lowres_scale: int, below: float):
        super().__init__(ctx)
        self.ao_div = max(1, int(lowres_scale))
        self.below = float(below)

    def _layout(self, width: int, height: int) -> LowResLayout:
        return LowResLayout((width, height))

    def classify(self, gbuffer, guide: LowResGuide, camera_pos, camera_forward) -> None:
        """Mark this frame's refined pixels (and clear the targets) from the G-buffer and the low-res
        guide that ``guide`` (a :class:`LowResGuide`) drew this frame (its texture, scale and layout)."""
        self._draw_classes("indirect refinement",
                           {"g_position": gbuffer.position, "g_normal": gbuffer.normal, "u_guide": guide.guide},
                           guide.layout, u_scale=guide.scale, u_camera_pos=tuple(float(x) for x in camera_pos),
                           u_camera_forward=tuple(float(x) for x in camera_forward), u_refine_below=self.below)

    def refined_mask(self) -> np.ndarray:
        """(H, W) bool, top row first: the pixels the last :meth:`classify` marked (a read-back: for
        tests and diagnostics)."""
        return read_texture(self.irr)[..., 3] > 0.5


class GBufferSamples(FullscreenPass):
    """Every ``stride``-th pixel of the G-buffer's position, normal and albedo, starting at ``stride // 2``
    (``glsl/gbuffer_samples.glsl``), read back as (rows, cols, 4) float32 images, top row first — the
    same arrays as ``read_texture(target)[c::s, c::s]`` at 1/stride² of the read-back."""

    SHADER = "gbuffer_samples.glsl"
    TARGETS = {"position": (4, "f4"), "normal": (4, "f4"), "albedo": (4, "f4")}
    NAMES = tuple(TARGETS)

    def __init__(self, ctx, stride: int):
        super().__init__(ctx)
        self.stride = max(1, int(stride))

    def target_size(self, width: int, height: int) -> tuple[int, int]:
        first = self.stride // 2
        return len(range(first, width, self.stride)), len(range(first, height, self.stride))

    def read(self, gbuffer) -> dict[str, np.ndarray]:
        """{"position", "normal", "albedo"}: the sampled pixels, (rows, cols, 4) float32."""
        p = self.program
        with self.ctx.debug_scope("gbuffer samples"):
            self.fbo.use()
            for loc, name in enumerate(self.NAMES):
                getattr(gbuffer, name).use(location=loc)
                p[f"g_{name}"].value = loc
            p["u_first"].value = self.stride // 2
            p["u_stride"].value = self.stride
            p["u_rows_out"].value = self.position.height
            self.vao.render(vertices=3)
        return {name: read_texture(getattr(self, name), 4) for name in self.NAMES}
