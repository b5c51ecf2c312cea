"""One headless OpenGL 4.3+ context per process (EGL: Mesa llvmpipe without a GPU, the
vendor driver with one), and the shader-program loader every pass uses.

Shaders live in ``serenity/raster/glsl/*.glsl``: one file per program, with
``#if defined VERTEX_SHADER`` / ``FRAGMENT_SHADER`` sections; ``#include "file.glsl"`` pulls in
shared code. ``load_program(ctx, "gbuffer.glsl", defines={...})`` builds it.
"""

from __future__ import annotations

import ctypes
import re
import threading
from contextlib import contextmanager
from dataclasses import dataclass
from importlib import resources

import moderngl

from serenity.errors import GLUnavailableError, SerenityError

GLSL_VERSION = "#version 430 core"
_SYSTEM_PACKAGES = "libegl1 libgl1-mesa-dri libgles2"

_lock = threading.Lock()
_context = None
_native_finish: tuple | None = None  # (the context made here, its glFinish through ctypes)
_native_clear: tuple | None = None   # (the context made here, its glClearTexSubImage through ctypes)


def get_context():
    """The process-wide headless moderngl context (created on first use)."""
    global _context
    with _lock:
        if _context is None:
            _context = _create_context()
        return _context


def use_context(ctx) -> None:
    """Make ``ctx`` (a window's moderngl context, current on this thread) the process's context, so
    that every pass created afterwards draws with it — the viewer's way to render into its window.
    Must come before anything has called :func:`get_context`."""
    global _context
    with _lock:
        if _context is not None and _context is not ctx:
            raise SerenityError("an OpenGL context is already in use in this process; "
                                "install the window's context before creating any pass")
        _context = ctx


def _create_context():
    global _native_finish, _native_clear
    try:
        ctx = moderngl.create_standalone_context(backend="egl", require=430)
    except Exception as e:
        raise GLUnavailableError(
            f"no headless OpenGL 4.3 context via EGL ({str(e).splitlines()[0] if str(e) else type(e).__name__}). "
            f"On Debian/Ubuntu install the system packages: sudo apt-get install {_SYSTEM_PACKAGES}"
        ) from None
    gl_finish = _egl_proc(b"glFinish", ctypes.CFUNCTYPE(None))
    _native_finish = (ctx, gl_finish) if gl_finish is not None else None
    clear = _egl_proc(b"glClearTexSubImage", ctypes.CFUNCTYPE(None, *[ctypes.c_uint] + [ctypes.c_int] * 7,
                                                             ctypes.c_uint, ctypes.c_uint, ctypes.c_void_p))
    _native_clear = (ctx, clear) if clear is not None and ctx.version_code >= 440 else None
    return ctx


def _egl_proc(name: bytes, prototype):
    """GL function ``name`` as EGL resolves it for the current context (as moderngl's EGL loader
    does), wrapped by ctypes with ``prototype`` (ctypes releases the GIL for the call); None where
    it cannot be resolved."""
    try:
        egl = ctypes.CDLL("libEGL.so.1")
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        ptr = egl.eglGetProcAddress(name)
    except (OSError, AttributeError):
        return None
    return prototype(ptr) if ptr else None


def finish(ctx) -> None:
    """Wait until ``ctx`` has done the GL work queued so far, as ``ctx.finish()`` does, but with
    Python's GIL released during the wait when ``ctx`` is the headless context made here. moderngl
    holds the GIL through the call, and on llvmpipe the wait *is* the rendering: a thread running
    Warp launches and numpy beside the GL passes (``Renderer``'s volume worker) would stall behind
    every pass. Measured on the 2-core machine (``benchmarks/experiments/bench_gil_finish.py``: a thread issuing
    small Warp launches beside a 15–20 ms fragment-bound pass): 73–76 launches/s through
    ``ctx.finish()``, 405–408 through this, 474 alone (``benchmarks/experiments/results/gil_finish.json``).
    Call it also before a draw that reads what the draws before it rendered (the SSAO blur, the
    deferred pass): llvmpipe would wait for them inside the draw call, with the GIL held
    (``tools/profile_gl_calls.py`` shows where the main thread sits in GL).
    Other contexts (the viewer's window) wait through moderngl."""
    native = _native_finish
    if native is not None and native[0] is ctx:
        native[1]()
    else:
        ctx.finish()


_GL_DEPTH_COMPONENT = 0x1902
_GL_FLOAT = 0x1406
_ONE = ctypes.c_float(1.0)


def clear_depth_rect(ctx, fbo, texture, rect) -> None:
    """Set ``rect`` ((x, y, w, h) texels) of depth ``texture`` (``fbo``'s depth attachment) to 1.0.
    On the headless context made here through ``glClearTexSubImage`` (GL 4.4), which writes the
    texels directly; elsewhere by ``fbo.clear`` with that viewport. llvmpipe clears a whole
    framebuffer fast but a part of one by drawing it: a 1024² tile of the shadow atlas took 1.36 ms
    that way and 0.22 ms this way (``benchmarks/experiments/bench_shadow_clear.py``)."""
    native = _native_clear
    x, y, w, h = (int(v) for v in rect)
    if native is not None and native[0] is ctx:
        native[1](texture.glo, 0, x, y, 0, w, h, 1, _GL_DEPTH_COMPONENT, _GL_FLOAT, ctypes.addressof(_ONE))
    else:
        fbo.clear(depth=1.0, viewport=(x, y, w, h))


def is_software(ctx) -> bool:
    """True on a CPU rasteriser (Mesa llvmpipe/softpipe/lavapipe): some GPU-cheap features are
    very slow there and are turned down (see ``anisotropy``)."""
    name = str(ctx.info.get("GL_RENDERER", "")).lower()
    return any(k in name for k in ("llvmpipe", "softpipe", "software"))


#: Trilinear filtering of the sky and LPV volumes done in the shader (8 ``texelFetch`` and float
#: weights, ``#define EXACT_FILTER``) instead of by the texture unit. GPUs weight the 8 texels with
#: 8-bit fixed-point fractions: the sky volume's SH coefficients of neighbouring probes can differ
#: ~30x and cancel in the irradiance sum, so on an NVIDIA H200 the filtered irradiance was off by up
#: to 37 % (relative to the point's own value) at dim points between bright probes, and the LPV
#: lookups by 0.24 %. llvmpipe filters in float. ``None``: on hardware GL only; tests set ``True`` to
#: run the exact path on llvmpipe too.
EXACT_FILTER: bool | None = None


def exact_filter(ctx) -> bool:
    """Whether shaders built now filter the volumes by hand (``EXACT_FILTER``)."""
    return (not is_software(ctx)) if EXACT_FILTER is None else bool(EXACT_FILTER)


def anisotropy(ctx) -> float:
    """Anisotropic filtering level for scene textures: 8 on a GPU; 1 on a CPU rasteriser, where
    llvmpipe's anisotropic path made the courtyard's 320×180 G-buffer take ~650 ms instead of 3 ms
    (and binding such a texture slowed even passes that never sample it)."""
    return 1.0 if is_software(ctx) else 8.0


def renderer_name() -> str:
    ctx = get_context()
    return f"{ctx.info['GL_RENDERER']} (OpenGL {ctx.info['GL_VERSION']})"


def check_gl_error(ctx, where: str) -> None:
    """Raise if the GL error flag is set (tests call this after every GL test)."""
    err = ctx.error
    if err != "GL_NO_ERROR":
        raise SerenityError(f"OpenGL error after {where}: {err}")


_INCLUDE = re.compile(r'^\s*#include\s+"([^"]+)"\s*$', re.M)


def shader_source(name: str, _seen: frozenset = frozenset()) -> str:
    """Text of ``glsl/<name>`` with its ``#include``s expanded (once each)."""
    if name in _seen:
        return ""
    return expand_includes(resources.files("serenity.raster").joinpath("glsl", name).read_text(), _seen | {name})


def expand_includes(text: str, _seen: frozenset = frozenset()) -> str:
    """GLSL ``text`` with its ``#include "x.glsl"`` lines replaced by ``shader_source("x.glsl")`` (looked
    up in this module when called, so a benchmark may substitute its own), files in ``_seen`` left out."""
    return _INCLUDE.sub(lambda m: shader_source(m.group(1), _seen), text)


def load_program(ctx, name: str, defines: dict | None = None, stages=("VERTEX_SHADER", "FRAGMENT_SHADER")):
    """Compile ``glsl/<name>`` for the given stages with ``#define``s prepended."""
    return compile_program(ctx, shader_source(name), name, defines, stages)


def compile_program(ctx, body: str, name: str, defines: dict | None = None,
                    stages=("VERTEX_SHADER", "FRAGMENT_SHADER")):
    """Compile GLSL text ``body`` (one file with ``#if defined VERTEX_SHADER`` / ``FRAGMENT_SHADER``
    sections, includes expanded) for the given stages, with the version line, the ``#define``s and
    the stage's define prepended; ``name`` names it in the error (a benchmark's shader uses this)."""
    defines = {**({"EXACT_FILTER": 1} if exact_filter(ctx) else {}), **(defines or {})}
    head = [GLSL_VERSION] + [f"#define {k} {v}" for k, v in defines.items()]
    srcs = {}
    for stage in stages:
        key = {"VERTEX_SHADER": "vertex_shader", "FRAGMENT_SHADER": "fragment_shader",
               "GEOMETRY_SHADER": "geometry_shader"}[stage]
        srcs[key] = "\n".join(head + [f"#define {stage} 1", "#line 1", body])
    try:
        return ctx.program(**srcs)
    except Exception as e:
        raise SerenityError(f"shader {name} failed to compile: {e}") from None


def uniform(program, name: str):
    """``program``'s uniform (or attribute) ``name``, or None where the variant has none (the
    compiler drops what a program never reads). Use this, not ``name in program``: moderngl's
    ``Program`` has no ``__contains__``, so ``in`` walks every member through ``__iter__`` — a few
    hundred such tests per frame were ~0.5 ms of the main thread's Python at 320×180."""
    return program.get(name, None)


def fullscreen_vao(ctx, program):
    """A VAO with no buffers: fullscreen passes draw one triangle from gl_VertexID."""
    return ctx.vertex_array(program, [])


class FullscreenPass:
    """A fullscreen-triangle program (``SHADER``, which includes ``fullscreen.glsl``) drawing into
    its own colour targets, named with (components, dtype) in ``TARGETS`` and (re)allocated as
    attributes of those names, plus ``fbo``, by :meth:`resize` — at :meth:`target_size` of the
    view (the view's size unless a pass says otherwise)."""

    SHADER: str = ""
    TARGETS: dict[str, tuple[int, str]] = {}

    def __init__(self, ctx):
        self.ctx = ctx
        self.program = load_program(ctx, self.SHADER)
        self.vao = fullscreen_vao(ctx, self.program)
        self.size = None

    def resize(self, width: int, height: int) -> None:
        if self.size == (width, height):
            return
        if self.size is not None:
            self.fbo.release()
            for name in self.TARGETS:
                getattr(self, name).release()
        targets = []
        for name, (components, dtype) in self.TARGETS.items():
            tex = self.ctx.texture(self.target_size(width, height), components, dtype=dtype)
            setattr(self, name, tex)
            targets.append(tex)
        self.fbo = self.ctx.framebuffer(color_attachments=targets)
        self.size = (width, height)

    def target_size(self, width: int, height: int) -> tuple[int, int]:
        """Size of the targets for a width×height view."""
        return width, height


class BlendedTargets:
    """One framebuffer per target texture (cached), drawn into with blending onto what it already
    holds: additive (ONE, ONE) by default — the indirect light and its upsampling add onto an image
    that holds the rest — or any ``blend_func`` (the composite's premultiplied (ONE, SRC_ALPHA))."""

    def __init__(self, ctx, blend_func=(moderngl.ONE, moderngl.ONE)):
        self.ctx = ctx
        self.blend_func = blend_func
        self._fbos: dict[int, object] = {}

    def adding_to(self, target):
        """Context: draw into ``target`` (a texture), blending onto what it holds."""
        fbo = self._fbos.get(target.glo)
        if fbo is None:
            fbo = self._fbos[target.glo] = self.ctx.framebuffer(color_attachments=[target])
        return self.adding_to_framebuffer(fbo)

    @contextmanager
    def adding_to_framebuffer(self, fbo):
        """Context: draw into ``fbo``, blending onto what its targets hold."""
        ctx = self.ctx
        fbo.use()
        ctx.enable(moderngl.BLEND)
        ctx.blend_func = self.blend_func
        ctx.blend_equation = moderngl.FUNC_ADD
        try:
            yield
        finally:
            ctx.disable(moderngl.BLEND)


def low_res_size(width: int, height: int, scale: int) -> tuple[int, int]:
    """Size of a pass run at 1/scale of a width×height view (``glsl/lowres.glsl``)."""
    s = max(1, int(scale))
    return (width + s - 1) // s, (height + s - 1) // s


#: llvmpipe (Mesa's CPU rasteriser) bins a draw into tiles of this many pixels per side and hands
#: whole tiles to its threads
RASTER_TILE = 64


@dataclass(frozen=True)
class LowResLayout:
    """Where a reduced-resolution image (``low_res_size``) lies in its render targets: ``size``
    texels from target texel ``origin`` (GL's bottom-left convention); the targets are
    ``texture_size``, padded below and to the left of the image.

    Why padded: llvmpipe rasterises 64×64 tiles, each on one thread, so a small image's work is
    split by where the tile borders cut it. At 320×180 a quarter-resolution pass is 80×45 texels,
    one tile of 64 columns and one of 16: one of two threads shaded 4/5 of it. Centred on the
    borders (origin 24), each tile holds 40 columns. It never adds a tile (the image stays within
    the same number of tiles per axis) and changes nothing on a GPU but a few unused texels."""

    size: tuple[int, int]
    origin: tuple[int, int] = (0, 0)

    @property
    def texture_size(self) -> tuple[int, int]:
        return self.origin[0] + self.size[0], self.origin[1] + self.size[1]

    @property
    def viewport(self) -> tuple[int, int, int, int]:
        return (*self.origin, *self.size)

    def set_uniforms(self, program) -> None:
        """``u_lowres_origin`` / ``u_lowres_size`` (``glsl/lowres.glsl``) of ``program``, where it has them."""
        for name, value in (("u_lowres_origin", self.origin), ("u_lowres_size", self.size)):
            if (u := uniform(program, name)) is not None:
                u.value = value

    def crop(self, image):
        """The image's texels of a read-back of the targets ((rows, cols, ...), top row first)."""
        (ox, oy), (w, h) = self.origin, self.size
        rows = image.shape[0]
        return image[rows - oy - h:rows - oy, ox:ox + w]


def _tile_centred(n: int) -> int:
    tiles = -(-n // RASTER_TILE)
    return (tiles * RASTER_TILE - n) // 2


def low_res_layout(width: int, height: int, scale: int, balance: bool = True) -> LowResLayout:
    """The layout of a 1/scale pass of a width×height view: the image centred on llvmpipe's tile
    borders (``balance``, and scale > 1), else at the targets' origin."""
    size = low_res_size(width, height, scale)
    if not balance or scale <= 1:
        return LowResLayout(size)
    return LowResLayout(size, (_tile_centred(size[0]), _tile_centred(size[1])))


def draw_fullscreen(ctx, vao, rects=None) -> None:
    """Draw a fullscreen pass, restricted to ``rects`` ((x, y, w, h) in framebuffer pixels, GL
    origin bottom-left) when given: the ray-traced views light only the rectangles that hold
    traced pixels (llvmpipe runs a fragment shader's every path for every covered pixel, so an
    early-out per pixel saves nothing there; a scissor does)."""
    if rects is None:
        vao.render(vertices=3)
        return
    try:
        for r in rects:
            ctx.scissor = tuple(int(v) for v in r)
            vao.render(vertices=3)
    finally:
        ctx.scissor = None
