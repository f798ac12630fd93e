"""Give the memory a finished step freed back to the operating system.

CPython's small objects and numpy's mid-sized arrays come from the C allocator's heap; glibc
keeps what they free for reuse, and after a large temporary array is freed it also raises
the size below which arrays are put on that heap (its dynamic mmap threshold, up to 32 MiB),
so a long build's resident memory creeps up stage after stage by memory no object holds.
``malloc_trim(0)`` returns the free pages of every heap (glibc >= 2.8 also those inside it).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools


@functools.cache
def _trim():
    name = ctypes.util.find_library("c")
    try:
        return getattr(ctypes.CDLL(name), "malloc_trim", None) if name else None
    except OSError:
        return None


def release_free_memory() -> bool:
    """Return the C heap's free pages to the system (glibc); False where there is no
    ``malloc_trim`` (another C library), which is harmless."""
    trim = _trim()
    if trim is None:
        return False
    trim(0)
    return True
