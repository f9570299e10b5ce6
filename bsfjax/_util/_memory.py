"""Handing freed host memory back to the operating system after the large host passes.

The sparse-frame build and the host Gram rows of OMP allocate and free many temporaries of
tens of MB, some in XLA's callback threads (each with its own glibc malloc arena).  glibc keeps
freed blocks below its (dynamic, up to 32 MB) mmap threshold mapped for reuse, so after such a
pass the process can stay GBs above what it holds (on the 445K-vertex benchmark ~0.3–1 GiB per
stage).  ``malloc_trim(0)`` releases the free pages of every arena.  Elsewhere (no glibc) this
is a no-op.

`available_memory` says how much a new allocation can take, for the checks that refuse a
run before it allocates more (the dense system of a functional-map estimate).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os

__all__ = ["available_memory", "format_bytes", "release_free_memory"]


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


def available_memory() -> int | None:
    """Bytes a new allocation can take now: the free memory of the first JAX device when it
    reports one (an accelerator), else the host's available memory (``MemAvailable`` of
    ``/proc/meminfo``, or free pages); ``None`` when neither is known."""
    import jax

    try:
        stats = jax.local_devices()[0].memory_stats()
    except Exception:  # noqa: BLE001 - a backend without memory statistics
        stats = None
    if stats and stats.get("bytes_limit"):
        return int(stats["bytes_limit"]) - int(stats.get("bytes_in_use", 0))
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):  # no /proc (not Linux): sysconf below
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def format_bytes(n: float) -> str:
    """``n`` bytes as a short figure: ``778 GB``, ``9.7 MB``."""
    for unit in ("B", "kB", "MB", "GB", "TB"):
        if n < 1000 or unit == "TB":
            return f"{n:.3g} {unit}"
        n /= 1000
    return f"{n:.3g} TB"  # pragma: no cover
