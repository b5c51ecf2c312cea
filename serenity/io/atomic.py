"""Atomic writes: a file is either its old version or its new one, never half.

``atomic_write(path, write)`` has ``write`` fill a temporary file beside ``path`` (same directory,
so the rename stays on one file system; same extension, so writers that go by it still work) and
renames it over ``path`` only once ``write`` returned.
"""

from __future__ import annotations

import os
import threading


def atomic_write(path, write) -> None:
    """``write(tmp)`` to a temporary file beside ``path`` (same extension), then rename it over ``path``;
    if ``write`` raises, ``path`` is left as it was and the temporary file is removed."""
    path = os.fspath(path)
    d = os.path.dirname(os.path.abspath(path))
    os.makedirs(d, exist_ok=True)
    stem, ext = os.path.splitext(os.path.basename(path))
    tmp = os.path.join(d, f".{stem}.tmp{os.getpid()}-{threading.get_ident()}{ext}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
