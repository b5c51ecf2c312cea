"""The disk cache's folder, shared by what it holds: ``$SERENITY_CACHE`` or ``~/.cache/serenity``.

Read mesh files (:mod:`.mesh_io`), built kd-trees (``kernels/kdtree_build.py``) and traced probes
(``kernels/probegather.py``) are cached there, each under a key of everything it depends on, so that
a renderer started again on the same scene skips that work.
"""

from __future__ import annotations

import os
from pathlib import Path


def cache_dir() -> Path:
    """``$SERENITY_CACHE`` or ``~/.cache/serenity``."""
    env = os.environ.get("SERENITY_CACHE")
    return Path(env).expanduser() if env else Path.home() / ".cache" / "serenity"
