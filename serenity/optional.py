"""Optional third-party packages: imported where they are used, with a message naming the extra.

The extras are those of ``pyproject.toml``. A module that needs one calls ``require`` inside the
function that uses it (never at its top), so that everything else works without the package and a
command that needs it fails with one line saying what to install::

    mi = require("mitsuba", "a reference render")
    # without it: SerenityError("a reference render needs the optional package Mitsuba 3 (mitsuba):
    #                            pip install 'serenity[eval]'")
"""

from __future__ import annotations

import importlib
from types import ModuleType

from serenity.errors import SerenityError

PACKAGES: dict[str, tuple[str, str]] = {
    "mitsuba": ("Mitsuba 3 (mitsuba)", "eval"),
    "flip_evaluator": ("flip-evaluator", "eval"),
    "matplotlib": ("matplotlib", "eval"),
    "embreex": ("embreex", "bench"),
    "glfw": ("glfw", "view"),
    "moderngl_window": ("moderngl-window", "view"),
    "imgui_bundle": ("imgui-bundle", "view"),
    "distributed": ("Dask (dask[distributed])", "eval"),
}
"""Import name → (what to call it in a message, the extra that installs it)."""


def require(module: str, purpose: str) -> ModuleType:
    """Import ``module`` (a key of ``PACKAGES``, or a submodule of one); if it is missing, a
    ``SerenityError`` saying that ``purpose`` needs it and which extra installs it."""
    top = module.split(".")[0]
    if top not in PACKAGES:
        raise KeyError(f"{top!r} is not an optional package (serenity.optional.PACKAGES)")
    try:
        return importlib.import_module(module)
    except ImportError:
        name, extra = PACKAGES[top]
        raise SerenityError(f"{purpose} needs the optional package {name}: pip install 'serenity[{extra}]'") \
            from None


def pyplot(purpose: str) -> ModuleType:
    """``matplotlib.pyplot`` on the non-interactive Agg backend (unless a backend is already chosen),
    or the one-line error of :func:`require`."""
    matplotlib = require("matplotlib", purpose)
    matplotlib.use("Agg", force=False)
    return require("matplotlib.pyplot", purpose)
