"""Errors a user can act on. The CLI prints their message on one line and exits non-zero."""


class SerenityError(Exception):
    """Base of every error Serenity reports to a user (bad input, missing system packages...)."""


class SceneError(SerenityError, ValueError):
    """A scene, mesh, material, camera, sun or file that cannot be used, with the reason."""


class GLUnavailableError(SerenityError, RuntimeError):
    """No headless OpenGL context could be created; the message names the packages to install."""


class ConfigError(SerenityError, ValueError):
    """A render setting out of range or of the wrong type; the message starts with ``Class.field``."""


def first_line(e: BaseException) -> str:
    """``Type: first line of its message`` (at most 200 characters): another library's error quoted
    inside a one-line message."""
    text = str(e).strip().splitlines()
    msg = text[0] if text else ""
    return f"{type(e).__name__}: {msg}"[:200] if msg else type(e).__name__
