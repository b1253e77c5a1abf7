"""The C heap of an OCSLAM process: one malloc arena, and handing freed pages back to the OS (glibc).

The loop runs its stages on worker threads (detector, fusion, estimator: ``sim.parallel_stages``) that
end with their pipeline. glibc gives such threads arenas of their own (up to 8 per core) and never
destroys an arena: a thread arena that grew to a large world's working set keeps most of it resident
after the world is closed, collected and ``malloc_trim``-ed, and a new world's threads reuse the arenas
without giving it back. Measured (docs/benchmarks.md, "What the loop process keeps after a world"):
+27 MiB that stays after one large world with the default arenas, none with one arena (or with the
stages run sequentially), at the same speed.

So an OCSLAM process uses one arena unless ``MALLOC_ARENA_MAX`` says otherwise (the user's choice wins).
Nothing here does anything where the C library is not glibc.
"""

from __future__ import annotations

import ctypes
import os

#: glibc's ``mallopt`` parameter number of ``M_ARENA_MAX`` (malloc.h)
_M_ARENA_MAX = -8


def _libc() -> ctypes.CDLL | None:
    try:
        return ctypes.CDLL(None)  # the process' own symbols: no library search, no subprocess
    except OSError:
        return None


def limit_malloc_arenas(n: int = 1) -> bool:
    """At most ``n`` glibc malloc arenas for this process, unless ``MALLOC_ARENA_MAX`` is set (then
    glibc already obeys it). Call before threads start allocating. True if applied."""
    if os.environ.get("MALLOC_ARENA_MAX"):
        return False
    libc = _libc()
    fn = getattr(libc, "mallopt", None) if libc is not None else None
    if fn is None or getattr(libc, "gnu_get_libc_version", None) is None:
        return False  # not glibc (musl, macOS): its allocator has no such arenas
    fn.argtypes, fn.restype = [ctypes.c_int, ctypes.c_int], ctypes.c_int
    return bool(fn(_M_ARENA_MAX, int(n)))


def malloc_trim() -> bool:
    """Hand the C heap's free pages back to the OS (glibc ``malloc_trim(0)``); False where there is no glibc.

    A closed pipeline's memory is freed but stays resident: glibc keeps freed heap pages below live
    blocks, and after the first world frees its large blocks it serves later large blocks from the heap
    too (its dynamic mmap threshold), so the RSS after a world change stays at the world's peak."""
    libc = _libc()
    fn = getattr(libc, "malloc_trim", None) if libc is not None else None
    if fn is None:
        return False
    fn.argtypes, fn.restype = [ctypes.c_size_t], ctypes.c_int
    fn(0)
    return True
