"""The sweep's files, written atomically (``serenity.io.atomic.atomic_write``): a file in the results
directory is either its old version or its new one, never half."""

from __future__ import annotations

import json

import numpy as np

from serenity.io.atomic import atomic_write


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
