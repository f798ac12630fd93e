"""The C heap's free pages handed back to the system between build stages."""

from __future__ import annotations

import platform

import pytest

from vid2sim.base.memory import release_free_memory


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="malloc_trim is glibc's")
def test_glibc_heap_is_trimmed():
    assert release_free_memory() is True
    assert release_free_memory() is True  # the library is looked up once, the call repeats
