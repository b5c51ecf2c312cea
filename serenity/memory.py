"""Returning freed memory to the OS during the big one-off host computations (glibc only).

glibc's malloc serves a request below its mmap threshold from the heap, and raises that threshold
(up to 32 MiB) each time it frees a block it had mapped: after the first few MB-sized numpy arrays,
every array of a chunked computation lands on the heap, and a heap keeps the memory its freed blocks
leave between live ones. Tracing the probes' 14M rays of a 262k-triangle room in chunks of a million
left about 60 MB resident per chunk that way (0.7 GB by the end). :func:`mapped_large_blocks`
maps every block of at least ``THRESHOLD`` bytes for the duration of a ``with`` block (so each is
returned as it is freed) and trims the heap at the end; elsewhere (macOS, Windows, musl) it does
nothing."""

from __future__ import annotations

import ctypes
import ctypes.util
from collections.abc import Iterator
from contextlib import contextmanager

#: blocks of at least this many bytes are mapped inside ``mapped_large_blocks``
THRESHOLD = 1 << 20
#: the threshold afterwards: glibc's ceiling for its own dynamic threshold (its steady state)
AFTER = 32 << 20
_M_MMAP_THRESHOLD = -3

_libc = None


def _glibc():
    global _libc
    if _libc is None:
        _libc = False
        try:
            lib = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
            if hasattr(lib, "mallopt") and hasattr(lib, "malloc_trim") and hasattr(lib, "gnu_get_libc_version"):
                _libc = lib
        except OSError:
            pass
    return _libc


@contextmanager
def mapped_large_blocks() -> Iterator[None]:
    """Blocks of ``THRESHOLD`` bytes or more mapped, not taken from the heap, inside the block."""
    lib = _glibc()
    if lib:
        lib.mallopt(_M_MMAP_THRESHOLD, THRESHOLD)
    try:
        yield
    finally:
        if lib:
            lib.mallopt(_M_MMAP_THRESHOLD, AFTER)
            lib.malloc_trim(0)
