"""The C of the kd-tree's native functions (``wp.func_native``), read from the ``.h`` files beside
the Python that declares them.

A header holds complete C++ functions named and typed as the natives that use them (Warp's types:
``wp::array_t<float>``, ``wp::vec3``, ``long long`` for ``wp.int64``; a ``@wp.struct`` by its Python
name), each with its opening and closing brace alone on a line at column 0, so that it reads,
formats and lints as C++. :func:`native_body` returns one function's body as the native's snippet:

- each ``#include "file.h"`` inside the body replaced by that file's text (a header of this package
  with statements shared between natives, such as ``leaf8.h``, the 8-lane leaf test), recursively;
- the Python constants it uses (``defines``) as ``#define`` lines before it;
- an ``#undef`` after it for every macro defined in it, so a native's macros end with it;
- for a CPU-only native (``cpu_only``: clang's vector extensions, BMI2, prefetches), the body compiled
  only for the CPU: on CUDA the native is ``__trap()``, so that a kernel that calls it stops with
  an error there instead of returning a plausible value (the queries never launch one on CUDA:
  :mod:`serenity.kernels.kdtree.query`).

Warp hashes a snippet's text into its module's hash, so an edit of a header inside a body (or of a
file it includes) compiles the modules that use it anew; comments outside the bodies change nothing.
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path

from serenity.errors import SerenityError

_INCLUDE = re.compile(r'^[ \t]*#[ \t]*include[ \t]+"([^"]+)"[ \t]*\n', re.M)
_DEFINE = re.compile(r"^[ \t]*#[ \t]*define[ \t]+(\w+)", re.M)


@cache
def _read(path: Path) -> str:
    return path.read_text(encoding="utf-8")


def _expand(text: str, folder: Path, seen: tuple[Path, ...]) -> str:
    """``text`` with each ``#include "file"`` line replaced by the file's text (paths relative to
    ``folder``), recursively."""

    def include(m: re.Match) -> str:
        path = (folder / m.group(1)).resolve()
        if path in seen:
            raise SerenityError(f"{path}: includes itself")
        if not path.is_file():
            raise SerenityError(f"{seen[-1]}: no file {m.group(1)!r} to include")
        return _expand(_read(path), path.parent, (*seen, path))

    return _INCLUDE.sub(include, text)


def function(header: Path, name: str) -> tuple[str, str, str]:
    """(return type, parameter list, body) of function ``name`` in ``header``, as written there."""
    text = _read(header)
    m = re.search(rf"^((?:static |inline )*[\w:<> ]+?[\s*&]+){name}\(([^)]*)\)\s*\n\{{\n", text, re.M)
    if m is None:
        raise SerenityError(f"{header}: no function {name}(...) with its braces alone on their lines")
    end = text.find("\n}\n", m.end() - 1)
    if end < 0:
        raise SerenityError(f"{header}: function {name} has no closing brace alone on a line")
    ret = m.group(1).replace("static", "").replace("inline", "").strip()
    return ret, " ".join(m.group(2).split()), text[m.end():end + 1]


def parameter_names(header: Path, name: str) -> list[str]:
    """The names of function ``name``'s parameters in ``header`` (for the tests: the same as the
    Python declaration's)."""
    params = function(header, name)[1]
    return [p.split()[-1].lstrip("*&") for p in params.split(",") if p.strip()]


def native_body(header: Path, name: str, *, cpu_only: bool = False, defines: dict | None = None) -> str:
    """The snippet of native ``name``: its body in ``header`` (module docstring), with ``defines``
    (name → Python value) as macros and, if ``cpu_only``, a ``__trap()`` in its place on CUDA."""
    ret, _, body = function(header, name)
    body = _expand(body, header.parent, (header.resolve(),))
    head = "".join(f"#define {k} {_c_literal(v)}\n" for k, v in (defines or {}).items())
    macros = dict.fromkeys(_DEFINE.findall(head + body))
    tail = "".join(f"#undef {k}\n" for k in macros)
    text = head + body + tail
    if cpu_only:
        trap = "__trap();\n" + ("" if ret == "void" else "return 0;\n")
        text = f"#if defined(__CUDA_ARCH__)\n{trap}#else\n{text}#endif\n"
    return text


def _c_literal(value) -> str:
    """A Python constant as a C literal: an int as is, a float as a float literal with every digit."""
    if isinstance(value, bool):
        return str(int(value))
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return f"{value!r}f" if value == value and abs(value) != float("inf") else "__builtin_inff()"
    raise SerenityError(f"native constant {value!r}: an int or a float")
