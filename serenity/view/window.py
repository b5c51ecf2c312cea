"""The viewer's window: a GLFW window with an OpenGL 4.3 core context (moderngl-window), whose
moderngl context becomes the process's context (``serenity.raster.context.use_context``) so that
the renderer's passes draw with it. Every failure to get one is a one-line ``SerenityError``."""

from __future__ import annotations

import os

from serenity.errors import SerenityError
from serenity.optional import require
from serenity.raster.context import use_context


def _first_line(e: BaseException) -> str:
    text = str(e).strip().splitlines()
    return text[0] if text else type(e).__name__


def open_window(width: int, height: int, title: str, visible: bool = True):
    """A moderngl-window GLFW window of ``width`` × ``height`` pixels, its context installed as
    the renderer's."""
    glfw = require("glfw", "serenity view")
    require("imgui_bundle", "serenity view's panel")  # checked before a window opens
    Window = require("moderngl_window.context.glfw", "serenity view").Window
    display = os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
    if not display:
        raise SerenityError("cannot open a window: no display (DISPLAY is not set); on a machine without "
                            "one, run it under a virtual X server: xvfb-run -a serenity view ...")
    glfw.ERROR_REPORTING = "raise"
    try:
        wnd = Window(title=title, size=(int(width), int(height)), gl_version=(4, 3), resizable=True,
                     vsync=False, visible=visible)
    except Exception as e:
        raise SerenityError(f"cannot open a window with OpenGL 4.3 on display {display!r}: {_first_line(e)}") from None
    glfw.ERROR_REPORTING = "warn"  # from here on a GLFW hiccup (clipboard, focus) is not fatal
    use_context(wnd.ctx)
    return wnd
