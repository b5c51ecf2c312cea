"""Every Warp kernel builds for CUDA, on this CPU-only machine too: Warp compiles CUDA C++ through NVRTC
without a driver, so ``wp.compile_aot_module(module, arch=[75, 90])`` catches a kernel that would not
build on a GPU (sm_75 Turing, sm_90 Hopper). The kernel modules are discovered (every module under
``serenity.kernels`` that defines a kernel, including ones added later), and so are the specialised
kernels: every value combination each ``kernels.factory.kernel_factory`` declares. Running them on a
GPU is another matter (see ``serenity.device``): this only proves they compile."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
import types

import pytest

import serenity.kernels
from serenity.device import init_warp
from serenity.kernels import factory as F

wp = init_warp()
ARCHS = [75, 90]


def _kernel_modules() -> list[types.ModuleType]:
    mods = [importlib.import_module(m.name)
            for m in pkgutil.walk_packages(serenity.kernels.__path__, serenity.kernels.__name__ + ".")]
    return [m for m in mods if any(isinstance(v, wp.Kernel) and v.module.name == m.__name__ for v in vars(m).values())]


MODULES = _kernel_modules()
SPECIALISED = [(f"{f.__module__}.{f.__name__}({', '.join(f'{k}={v!r}' for k, v in kw.items())})", k)
               for f in F.factories() for kw, k in F.specialisations(f)]


def _compile(module, tmp_path):
    paths = wp.compile_aot_module(module, arch=ARCHS, module_dir=str(tmp_path))
    assert len(paths) == len(ARCHS) and all(p.exists() and p.stat().st_size > 0 for p in paths), paths
    return paths


def test_discovery_finds_the_kernel_modules_and_factories():
    names = {m.__name__ for m in MODULES}
    assert {"serenity.kernels.lpv.propagate", "serenity.kernels.atmosphere", "serenity.kernels.launch"} <= names
    assert len(SPECIALISED) >= 6  # propagate ×2, leak guard ×2, sky sequence ×2
    assert sum(n.startswith("serenity.kernels.dynamic.trace_dynamic_kernel(") for n, _ in SPECIALISED) == 4


def test_every_kernel_factory_is_declared():
    """A cached function returning kernels must declare its values, or its kernels go unchecked."""
    for m in MODULES:
        for name, obj in vars(m).items():
            if name.endswith("_kernel") and callable(obj) and hasattr(obj, "cache_info"):
                assert F.is_factory(obj), f"{m.__name__}.{name}: use kernels.factory.kernel_factory"
            if inspect.isfunction(obj) and name.endswith("_kernel") and obj.__module__ == m.__name__:
                pytest.fail(f"{m.__name__}.{name} looks like a kernel factory: use kernels.factory.kernel_factory")


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.__name__)
def test_module_compiles_for_cuda(module, tmp_path):
    _compile(module.__name__, tmp_path)


@pytest.mark.parametrize("kernel", [k for _, k in SPECIALISED], ids=[n for n, _ in SPECIALISED])
def test_specialised_kernel_compiles_for_cuda(kernel, tmp_path):
    _compile(kernel.module, tmp_path)
