"""Handing freed host memory back to the operating system after the large host passes.

The sparse-frame build and the host Gram rows of OMP allocate and free many temporaries of
tens of MB, some in XLA's callback threads (each with its own glibc malloc arena).  glibc keeps
freed blocks below its (dynamic, up to 32 MB) mmap threshold mapped for reuse, so after such a
pass the process can stay GBs above what it holds (on the 445K-vertex benchmark ~0.3–1 GiB per
stage).  ``malloc_trim(0)`` releases the free pages of every arena.  Elsewhere (no glibc) this
is a no-op.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

__all__ = ["release_free_memory"]


@functools.cache
def _malloc_trim():
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name).malloc_trim if name else None
    except (OSError, AttributeError):  # not glibc (macOS, musl, Windows)
        return None


def release_free_memory() -> None:
    """Return freed heap pages to the OS (glibc ``malloc_trim``; no-op without glibc)."""
    trim = _malloc_trim()
    if trim is not None:
        trim(0)
