"""Shared fixtures: the real-mesh folder and small synthetic meshes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

#: ``../shared/data`` beside the repository (see its README for origin and terms).
DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def pytest_configure(config):
    """One persistent JAX compilation cache for the whole run, new for each run (set before
    xdist starts its workers, so they, the notebook kernels and the CLI subprocesses share it),
    outside the user's own cache folder: a cache left by an earlier run, or one that a killed
    run wrote half of, is never read."""
    import os
    import tempfile

    # Compile fast: the suite is mostly XLA compiling many small programs once each (838 s
    # of 1522 s of summed test time, measured by timing backend_compile_and_load per test).
    # The whole suite on 2 cores, the same afternoon: 687 s with XLA's defaults; with the
    # older fusion emitters 591 s, and with LLVM at -O1 as well 475 s (at -O0 489–546 s: the
    # fastest compiles, but the FAUST-sized tests ran 1.5–2.5× slower).  Same arithmetic,
    # other fusions: only the last bits of rounding differ.  Set before xdist starts its
    # workers, so they and the subprocess tests inherit them (those that set XLA_FLAGS append
    # to it); flags that the environment already gives are kept as given.
    flags = os.environ.get("XLA_FLAGS", "")
    for flag in ("--xla_cpu_use_fusion_emitters=false", "--xla_backend_optimization_level=1"):
        if flag.split("=")[0] not in flags:
            flags = f"{flags} {flag}".strip()
    os.environ["XLA_FLAGS"] = flags
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:
        folder = tempfile.mkdtemp(prefix="bsfjax-tests-jax-cache-")
        os.environ["JAX_COMPILATION_CACHE_DIR"] = folder
        config._bsfjax_cache = folder  # this process made it: it removes it at the end
    import jax

    jax.config.update("jax_compilation_cache_dir", os.environ["JAX_COMPILATION_CACHE_DIR"])


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Free the compiled programs (``jax.clear_caches``) after a test file that leaves this
    worker process above three quarters of its limit of memory maps (a file adds a few
    thousand at most).  XLA's CPU JIT maps each compiled program's code into about 7 memory
    regions, freed only with the program; a worker that kept the several thousand programs
    of its files reached Linux's limit of 65,530 regions per process
    (``vm.max_map_count``), and the next compilation died in LLVM ("Unable to
    allocate section memory": SIGABRT or SIGSEGV inside ``backend_compile_and_load``, late in
    about a third of the CI runs; a core dump of one held 65,533 maps).  Clearing after every
    file instead cost time (the suite in 1018 s against 913–964 s on the same 2-core machine:
    the programs that files share compiled again)."""
    yield
    try:
        with open("/proc/self/maps") as fh:
            n_maps = sum(1 for _ in fh)
        with open("/proc/sys/vm/max_map_count") as fh:
            limit = int(fh.read())
    except (OSError, ValueError):  # not Linux: no such limit to keep below
        return
    if n_maps > 3 * limit // 4:
        import jax

        jax.clear_caches()


def pytest_unconfigure(config):
    import shutil

    folder = getattr(config, "_bsfjax_cache", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)


def cpu_devices_env(n: int) -> dict[str, str]:
    """The environment for a subprocess with ``n`` CPU devices: this run's own ``XLA_FLAGS``
    (``pytest_configure``'s) kept, so that its results compare bit for bit with this
    process's."""
    import os

    return dict(os.environ, JAX_PLATFORMS="cpu", XLA_FLAGS=os.environ.get("XLA_FLAGS", "")
                + f" --xla_force_host_platform_device_count={n}")


def data_path(*parts: str) -> Path:
    """Path of a file in the shared data folder, or skip the test with the reason."""
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real-mesh data not found at {p} (expected ../shared/data beside the repo)")
    return p


def icosphere(subdivisions: int = 2, radius: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed, well-shaped triangulated sphere (vertices, faces) by icosahedron subdivision."""
    t = (1 + 5 ** 0.5) / 2
    v = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t],
                  [0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    f = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        uniq, inv = np.unique(edges, axis=0, return_inverse=True)
        mid = len(v) + inv.reshape(3, -1).T  # midpoint index of edges (01, 12, 20) per face
        v = np.concatenate([v, 0.5 * (v[uniq[:, 0]] + v[uniq[:, 1]])])
        a, b, c = f[:, 0], f[:, 1], f[:, 2]
        ab, bc, ca = mid[:, 0], mid[:, 1], mid[:, 2]
        f = np.concatenate([np.stack(s, 1) for s in ([a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca])])
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return v, f


@pytest.fixture(scope="module")
def small_pair():
    """The built-in example pair (levels=2) and spectra of 40 eigenpairs."""
    import bsfjax

    pair = bsfjax.example_pair(levels=2)
    return pair, bsfjax.spectrum(pair.source, 40), bsfjax.spectrum(pair.target, 40)


@pytest.fixture(scope="session")
def sphere_mesh():
    import bsfjax

    v, f = icosphere(3)
    return bsfjax.Mesh(v, f, name="icosphere3")


@pytest.fixture(scope="session")
def faust_mesh():
    import bsfjax

    return bsfjax.load_mesh(data_path("faust", "tr_reg_000.off"))
