"""Atomic writes: a file in the results directory is either its old version or its new one, never half.

``atomic_write(path, write)`` has ``write`` fill a temporary file beside ``path`` (same directory,
so the rename stays on one file system; same extension, so writers that go by it still work) and
renames it over ``path`` only once ``write`` returned.
"""

from __future__ import annotations

import json
import os
import threading

import numpy as np


def atomic_write(path: str, write) -> None:
    """``write(tmp)`` to a temporary file beside ``path`` (same extension), then rename it over ``path``;
    if ``write`` raises, ``path`` is left as it was and the temporary file is removed."""
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


def write_json(path: str, data) -> None:
    """``data`` as indented JSON (numpy scalars as numbers; NaN refused), atomically."""
    def w(tmp):
        with open(tmp, "w") as f:
            json.dump(data, f, indent=1, allow_nan=False, default=_json_default)
            f.write("\n")

    atomic_write(path, w)


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"not JSON serialisable: {type(x).__name__}")
