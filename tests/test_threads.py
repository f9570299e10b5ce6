"""One BLAS thread where more threads only spin (bsfjax._util._threads)."""

from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_info

import bsfjax
import bsfjax._spectral._spectrum as _spectrum
import bsfjax._util._threads as _threads
from bsfjax.internal import on_one_blas_thread, one_blas_thread


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_one_blas_thread_limits_every_blas_and_restores():
    before = _blas_threads()
    assert before, "numpy and scipy load a BLAS"
    with one_blas_thread():
        assert _blas_threads() == [1] * len(before)
    assert _blas_threads() == before
    with one_blas_thread(False):
        assert _blas_threads() == before
    seen = on_one_blas_thread(_blas_threads)()  # JAX runs on the CPU here
    assert seen == [1] * len(before)
    assert _blas_threads() == before


def test_small_eigensolves_run_on_one_blas_thread(monkeypatch):
    """Below ONE_THREAD_BELOW vertices, with JAX on the CPU, the solver runs on one BLAS
    thread; from there on, or beside an accelerator, with the caller's setting; the spectrum is
    the same either way."""
    seen = []
    solve = _spectrum._eigensolve

    def recording(*args):
        seen.append(max(_blas_threads()))
        return solve(*args)

    monkeypatch.setattr(_spectrum, "_eigensolve", recording)
    mesh = bsfjax.example_pair(levels=1).source
    one = bsfjax.spectrum(mesh, 12, method="lanczos")
    monkeypatch.setattr(_threads, "ONE_THREAD_BELOW", 0)
    default = bsfjax.spectrum(mesh, 12, method="lanczos")
    monkeypatch.setattr(_threads, "ONE_THREAD_BELOW", 20_000)
    monkeypatch.setattr(_threads.jax, "default_backend", lambda: "gpu")
    bsfjax.spectrum(mesh, 12, method="lanczos")
    assert seen == [1, max(_blas_threads()), max(_blas_threads())]
    np.testing.assert_allclose(one.evals, default.evals, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(np.abs(np.sum(one.evecs * default.evecs * one.mass[:, None], 0)),
                               1.0, atol=1e-8)

