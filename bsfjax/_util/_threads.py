"""One BLAS thread where more threads only spin.

OpenBLAS (numpy's and scipy's builds) keeps its worker threads busy-waiting for about 2²⁸
cycles (~0.1 s) after each threaded call, ready for the next one.  XLA CPU runs its own thread
pool over the same cores, and its LAPACK calls (``eigh``, ``solve``, ``svd`` of ``k × k``
matrices inside our jitted stages) go through scipy's OpenBLAS.  So every such call, and every
host eigensolve just before the stages, leaves a thread spinning on a core that XLA's next
matrix product wanted: on this project's 2-core machine the nearest-neighbour search after the
descriptors' ``eigh`` ran 1.5× slower (0.11 s against 0.074 s at 5K × 6.9K vertices), and the
three stages of a 5K target 0.10 s slower (``docs/benchmarks.md``).

The matrices OpenBLAS sees on these paths are small (``k × k``, or the eigensolver's ``n × b``
blocks at ``n`` ≲ 10⁴), where a second thread gains nothing: the block eigensolver takes the
same time on one thread at 5K vertices (0.25–0.26 s) and is ~10 % slower at 28K (1.26 against
1.14 s), so it keeps the default from `ONE_THREAD_BELOW` vertices on, and beside an
accelerator (`eigensolve_on_one_thread`).  The limit is
`threadpoolctl`'s (restored on exit, so a user's own setting is kept outside these calls).
OpenBLAS's thread count is one setting for the whole process, and threadpoolctl (≥ 3.8) lets
one Python thread control it (the first that set a limit, while it lives); in other threads
the limit is a no-op.  Called from such a thread these functions run on the default threads:
slower, and an eigensolve's vectors differ in the last digits (1e-12 at 4K vertices).
"""

from __future__ import annotations

import contextlib
import functools

import jax
from threadpoolctl import ThreadpoolController

__all__ = ["one_blas_thread", "on_one_blas_thread", "eigensolve_on_one_thread", "ONE_THREAD_BELOW"]

#: Eigensolves of meshes with fewer vertices run on one BLAS thread (see the module doc).
ONE_THREAD_BELOW = 20_000


def eigensolve_on_one_thread(n: int) -> bool:
    """Whether the eigensolve of ``n`` vertices runs on one BLAS thread: below
    `ONE_THREAD_BELOW`, when JAX computes on the CPU (beside an accelerator, the host's
    cores are free for BLAS while the device computes)."""
    return n < ONE_THREAD_BELOW and jax.default_backend() == "cpu"


@functools.lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    # created on first use: by then numpy's and scipy's BLAS (and jaxlib's LAPACK, which is
    # scipy's) are loaded, since bsfjax imports them
    return ThreadpoolController()


def one_blas_thread(active: bool = True):
    """A context in which every loaded BLAS library uses one thread (``active=False``: a no-op
    context, for a caller that decides by problem size)."""
    if not active:
        return contextlib.nullcontext()
    return _controller().limit(limits=1, user_api="blas")


def on_one_blas_thread(fn):
    """Run ``fn`` on one BLAS thread when JAX runs on the CPU, its result awaited inside (the
    LAPACK calls of JAX programs still running after the return would see the default): so
    every public route to a computation sees the same threads and gives the same numbers."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with one_blas_thread(jax.default_backend() == "cpu"):
            return jax.block_until_ready(fn(*args, **kwargs))

    return wrapper
