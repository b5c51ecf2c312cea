"""Specialised kernels: a flag that would otherwise be tested inside a hot loop (the LPV's geometry
volume and leak guard, the sky volume's direction sequence, ...) is compiled in with ``wp.static`` by
a cached factory, one kernel per value, as ``lpv.propagate.propagate_kernel`` does.

``@kernel_factory(flag=(False, True))`` is ``functools.cache`` plus a declaration of the values each
parameter can take, so that ``tests/kernels/test_cuda_compile.py`` builds every kernel a factory can
produce (``specialisations()``). The factory's kernels use ``module="unique"`` (one Warp module each).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator, Sequence
from functools import cache
from typing import Any

_FACTORIES: list[Callable] = []


def kernel_factory(**domains: Sequence) -> Callable[[Callable], Callable]:
    """Decorator: cache the factory and record ``domains`` (parameter name → every value it may take)."""

    def wrap(fn: Callable) -> Callable:
        cached = cache(fn)
        cached.domains = {k: tuple(v) for k, v in domains.items()}
        _FACTORIES.append(cached)
        return cached

    return wrap


def is_factory(obj: Any) -> bool:
    return any(obj is f for f in _FACTORIES)


def factories() -> list[Callable]:
    """Every factory registered so far (by the kernel modules imported so far)."""
    return list(_FACTORIES)


def specialisations(factory: Callable) -> Iterator[tuple[dict, Any]]:
    """(arguments, kernel) for every combination of the factory's declared parameter values."""
    names = list(factory.domains)
    for values in itertools.product(*(factory.domains[n] for n in names)):
        kwargs = dict(zip(names, values, strict=True))
        yield kwargs, factory(**kwargs)
