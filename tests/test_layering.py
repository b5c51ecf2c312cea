"""The package's import graph, read from the source with ``ast`` (nothing is imported): no cycles,
the layers of docs/architecture.md ("Layers"), ``kernels/`` and ``raster/`` apart, ``config``
free of Warp and OpenGL, imports at module top except where the rule allows them inside a
function, and no module longer than ``MAX_LINES``."""

from __future__ import annotations

import ast
from dataclasses import dataclass
from pathlib import Path

import pytest

PACKAGE_DIR = Path(__file__).resolve().parents[1] / "serenity"

LAYERS: list[tuple[str, ...]] = [
    # 0: leaves: no serenity imports beyond each other
    ("serenity", "serenity.errors", "serenity.colour", "serenity.optional", "serenity.gbuffer_layout"),
    # 1: settings, devices, files and the scene model
    ("serenity.config", "serenity.device", "serenity.io", "serenity.scene"),
    # 2: the two halves of the renderer (which must not import each other, see below)
    ("serenity.kernels", "serenity.raster"),
    # 3: the frame, where the halves meet
    ("serenity.frame",),
    # 4: what is built on frames: the benchmark, the accuracy harness, the viewer, sweeps
    ("serenity.bench", "serenity.eval", "serenity.view", "serenity.sweep"),
    # 5: the command line
    ("serenity.commands", "serenity.cli", "serenity.__main__"),
]
"""Each module may import modules of its own layer or of the layers above it in this list (a
name stands for the module and everything below it)."""

OPTIONAL_PACKAGES = {"mitsuba", "flip_evaluator", "matplotlib", "embreex", "pyoidn", "dask", "distributed",
                     "imgui_bundle", "moderngl_window", "glfw"}
"""Third-party packages of the extras: imported inside the function that uses them (or through
``serenity.optional.require``), never at a module's top."""

HEAVY_PACKAGES = {"trimesh", "scipy", "fast_simplification"}
"""Required packages that take a large part of a second to import (trimesh, and the scipy it pulls
in; the mesh simplifier) and that a few functions use (reading and writing mesh files, building
spheres, simplifying a dense mesh): imported inside those functions, so that the tracer process and
a scene without a mesh file or a dense mesh never load them."""

LAZY_IMPORT_PACKAGES = ("serenity.commands",)
"""Where a function may import anything: a command imports what it runs when it runs, so that
``serenity --help`` does not load Warp, OpenGL or trimesh."""

MAX_LINES = 700
"""The most lines a module of the package may have: past it a file holds more than one seam, and is
split along them (as ``kernels/kdtree/`` and ``kernels/lpv/`` are)."""

PENDING_LOCAL_IMPORTS: set[str] = set()
"""Modules allowed, for now, to import required packages or serenity modules inside functions (while
being rewritten when the rule came in; empty since every module follows it). A name here exempts
that module only; a module missing from the package is ignored."""


@dataclass(frozen=True)
class Import:
    module: str  # the importing module
    target: str  # the imported module, fully qualified
    line: int
    local: bool  # inside a function (or class body), not at the module's top


def _module_name(path: Path) -> str:
    parts = list(path.relative_to(PACKAGE_DIR.parent).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


MODULES = {_module_name(p): p for p in sorted(PACKAGE_DIR.rglob("*.py"))}


def _imports_of(name: str, path: Path) -> list[Import]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    is_package = path.name == "__init__.py"
    found: list[Import] = []

    def visit(node: ast.AST, local: bool) -> None:
        for child in ast.iter_child_nodes(node):
            inner = local or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef))
            if isinstance(child, ast.Import):
                found.extend(Import(name, a.name, child.lineno, local) for a in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    anchor = name.split(".") if is_package else name.split(".")[:-1]
                    anchor = anchor[: len(anchor) - (child.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                for a in child.names:
                    sub = f"{base}.{a.name}"
                    found.append(Import(name, sub if sub in MODULES else base, child.lineno, local))
            visit(child, inner)

    visit(tree, False)
    return found


IMPORTS = [imp for name, path in MODULES.items() for imp in _imports_of(name, path)]
INTERNAL = [i for i in IMPORTS if i.target == "serenity" or i.target.startswith("serenity.")]


def _under(module: str, prefix: str) -> bool:
    return module == prefix or module.startswith(prefix + ".")


def _layer(module: str) -> int:
    best = None
    for k, names in enumerate(LAYERS):
        for prefix in names:
            if _under(module, prefix) and (best is None or len(prefix) > len(best[1])):
                best = (k, prefix)
    if best is None:
        raise AssertionError(f"{module} is in no layer: add it to LAYERS here and to docs/architecture.md")
    return best[0]


def _where(i: Import) -> str:
    return f"{MODULES[i.module].relative_to(PACKAGE_DIR.parent)}:{i.line}"


def test_the_walk_sees_the_package():
    """The walker finds the modules and the edges it must (guards the tests below against vacuity)."""
    assert {"serenity.cli", "serenity.frame", "serenity.config", "serenity.kernels.raytrace"} <= set(MODULES)
    edges = {(i.module, i.target) for i in INTERNAL}
    assert ("serenity.frame.renderer", "serenity.config") in edges
    assert ("serenity.kernels.raytrace", "serenity.kernels.launch") in edges
    assert any(i.target == "warp" for i in IMPORTS)


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module, or a module importing itself (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def strongconnect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                strongconnect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1 or v in edges.get(v, ()):
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            strongconnect(v)
    return out


def _graph() -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for i in INTERNAL:
        if i.target in MODULES:
            edges.setdefault(i.module, set()).add(i.target)
    return edges


def test_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert _cycles({"a": {"b"}, "b": set()}) == []


def test_no_import_cycles():
    """Function-local imports count: a cycle hidden inside a function is still a cycle."""
    cycles = _cycles(_graph())
    assert not cycles, "import cycles: " + "; ".join(" -> ".join(c) for c in cycles)


def test_kernels_and_raster_do_not_import_each_other():
    """Nor each other's library: kernels/ is Warp only, raster/ moderngl only."""
    bad = [f"{_where(i)} {i.module} imports {i.target}" for i in IMPORTS
           if (_under(i.module, "serenity.kernels") and (_under(i.target, "serenity.raster")
                                                          or _under(i.target, "moderngl")))
           or (_under(i.module, "serenity.raster") and (_under(i.target, "serenity.kernels")
                                                         or _under(i.target, "warp")))]
    assert not bad, "\n".join(bad)


def test_imports_follow_the_layers():
    bad = [f"{_where(i)} {i.module} (layer {_layer(i.module)}) imports {i.target} (layer {_layer(i.target)})"
           for i in INTERNAL if i.target in MODULES and _layer(i.target) > _layer(i.module)]
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("heavy", ["warp", "moderngl"])
@pytest.mark.parametrize("module", ["serenity.config", "serenity.colour", "serenity.eval.metrics"])
def test_plain_modules_do_not_import_warp_or_moderngl(module, heavy):
    """The settings, the numpy colour functions and the metrics: not directly, and not through any
    serenity module they import (at top or in a function)."""
    graph = _graph()
    seen, todo = set(), [module]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo.extend(graph.get(m, ()))
    bad = [f"{_where(i)} {i.module} imports {i.target}" for i in IMPORTS
           if i.module in seen and _under(i.target, heavy)]
    assert not bad, f"importing {module} would import {heavy}:\n" + "\n".join(bad)


def test_function_local_imports_only_where_the_rule_allows():
    """Inside a function: an optional or a heavy package, or anything in a command module; nothing else."""
    bad = []
    for i in IMPORTS:
        if not i.local or i.target.split(".")[0] in OPTIONAL_PACKAGES | HEAVY_PACKAGES \
                or i.module in PENDING_LOCAL_IMPORTS:
            continue
        if any(_under(i.module, p) for p in LAZY_IMPORT_PACKAGES):
            continue
        bad.append(f"{_where(i)} imports {i.target} inside a function")
    assert not bad, "move these imports to the module's top (docs/architecture.md, 'Imports'):\n" + "\n".join(bad)


def test_no_module_is_over_max_lines():
    """Every .py file under serenity/ (packages' ``__init__`` included) has at most ``MAX_LINES`` lines."""
    assert len(MODULES) > 100  # the walk found the package
    long = {str(p.relative_to(PACKAGE_DIR.parent)): n for p in MODULES.values()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > MAX_LINES}
    assert not long, f"modules over {MAX_LINES} lines (split them along their seams): {long}"
