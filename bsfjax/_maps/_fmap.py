"""Functional maps ↔ point maps, and their refinement (ZoomOut, ICP).

Notation (as in pyFM and the functional-map literature).  ``M`` is the *source* shape with
``n_M`` vertices and basis Φ_M ``(n_M, k_M)``; ``N`` is the *target*, Φ_N ``(n_N, k_N)``, lumped
mass ``A_N``.  A **point map** ``p2p`` ``(n_N,)`` sends target vertex ``i`` to source vertex
``p2p[i]``; its pull-back Π ``(n_N, n_M)``, Π[i, p2p[i]] = 1, carries a function ``f`` on ``M`` to
``Π f = f[p2p]`` on ``N``.  The **functional map** of ``p2p`` is that pull-back in the bases,

    C = Φ_Nᵀ A_N Π Φ_M            (k_N, k_M),

so spectral coefficients ``a`` of a function on ``M`` become ``C a`` on ``N``.  Back from ``C`` to
a point map: target vertex ``i`` goes to the source vertex whose *aligned* spectral embedding is
nearest,

    p2p[i] = argmin_j ‖Φ_N[i, :] − (Φ_M Cᵀ)[j, :]‖                (default), or
    p2p[i] = argmin_j ‖(Φ_N C)[i, :] − Φ_M[j, :]‖                 (``adjoint=True``).

The nearest-neighbour search is exact and chunked: target rows are processed ``chunk`` at a time
(``lax.map``), so at most ``chunk × n_M`` distances exist at once.  Both point sets are centred
on the reference mean, candidates are ranked by ``‖y‖² − 2 x·y`` (one GEMM per chunk), and the
rows of the few best blocks of ``_BLOCK`` reference rows (``_N_BLOCKS``) are re-scored with the
direct difference ``‖x − y‖²``, which removes the cancellation error of the expanded form.

Refinement (all jitted, one ``lax.fori_loop``):

* [`zoomout`][bsfjax.zoomout] — ZoomOut (Melzi et al., SIGGRAPH Asia 2019): alternate C → p2p → C while the
  basis grows from ``k₀`` to ``k`` by ``step``.  Arrays keep their final size and the inactive
  basis functions are masked to zero, so the whole loop compiles once.
* [`icp_refine`][bsfjax.icp_refine] — the orthogonal ICP of Ovsjanikov et al. 2012: C → p2p → C, then the
  nearest orthogonal matrix ``U Vᵀ``.  ``bijective=True`` also maps ``M → N`` with Cᵀ and averages
  the two functional maps before the projection, which favours maps that are bijective.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .._util import check_finite, check_indices
from .._util import BSFError
from .._spectral import Spectrum, map_to_unit_area, unit_area_pair

__all__ = ["fmap_from_p2p", "fmap_to_p2p", "zoomout", "icp_refine", "nearest_neighbors"]

#: The reference rows are searched in blocks of ``_BLOCK`` rows; the ``_N_BLOCKS`` blocks with the
#: smallest expanded-form distance are re-scored exactly (ties within float rounding).  16 × 2
#: instead of 32 × 4: the re-scoring, not the GEMM, dominated small searches (ZoomOut on 2000
#: samples, 2000 × 2000 × 60: 30–46 ms → 12–15 ms per search; FAUST 6890 × 6890 × 108: ≈ 0.26 →
#: 0.18 s), with the same point maps on the FAUST spectra measured.
_BLOCK = 16
_N_BLOCKS = 2
#: Default number of distances (chunk × n_M) alive at once in the nearest-neighbour search.
_DEFAULT_BUDGET = 1 << 21


# --------------------------------------------------------------------------- validation helpers


def _check_spectrum(s, name: str) -> None:
    if not isinstance(s, Spectrum):
        raise BSFError(f"{name} must be a bsfjax.Spectrum, got {type(s).__name__}")
    if np.ndim(s.evecs) != 2:
        raise BSFError(f"{name} must be a single (unstacked) Spectrum, got evecs of shape "
                       f"{np.shape(s.evecs)}")


def _as_index_array(p2p, n_rows: int, n_max: int, name: str) -> np.ndarray:
    arr = np.asarray(p2p)
    if arr.ndim != 1 or arr.shape[0] != n_rows:
        raise BSFError(f"{name} must have shape ({n_rows},) (one source vertex per target vertex), "
                       f"got {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        raise BSFError(f"{name} must hold integer vertex indices, got dtype {arr.dtype}")
    if arr.size and (arr.min() < 0 or arr.max() >= n_max):
        raise BSFError(f"{name} indices must be in [0, {n_max}) (source vertices), "
                       f"found range [{arr.min()}, {arr.max()}]")
    return arr.astype(np.int32)


def _check_fmap(C, k_source: int, k_target: int, name: str = "C") -> tuple[int, int]:
    shape = np.shape(C)
    if len(shape) != 2:
        raise BSFError(f"{name} must be a (k_target, k_source) matrix, got shape {shape}")
    kn, km = shape
    if km > k_source or kn > k_target:
        raise BSFError(f"{name} has shape {shape} = (k_target, k_source) but the spectra only have "
                       f"k_target={k_target}, k_source={k_source} eigenpairs")
    if km < 1 or kn < 1:
        raise BSFError(f"{name} must be non-empty, got shape {shape}")
    check_finite(C, name)
    return kn, km


def default_chunk(n_ref: int) -> int:
    """Queries per chunk against ``n_ref`` reference rows: about `_DEFAULT_BUDGET`
    distances, rounded down to a power of two (at least 8), since XLA CPU's GEMM of an
    odd-sized chunk is much slower (FAUST, 6890 × 6890 × 108: 304 rows 0.24–0.30 s per
    search, 256 rows 0.15–0.20 s)."""
    return 1 << max(3, (_DEFAULT_BUDGET // max(n_ref, 1)).bit_length() - 1)


def chunk_for(n_ref: int, n_query: int, chunk_size: int | None) -> int:
    if chunk_size is None:
        chunk_size = default_chunk(n_ref)
    if not isinstance(chunk_size, (int, np.integer)) or isinstance(chunk_size, bool) \
            or chunk_size < 1:
        raise BSFError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    return int(min(chunk_size, max(n_query, 1)))


# --------------------------------------------------------------------------- jitted kernels


def _nearest(ref: jax.Array, qry: jax.Array, chunk: int, n_valid=None) -> jax.Array:
    """Index of the nearest row of ``ref`` ``(n_r, d)`` for every row of ``qry`` ``(n_q, d)``.

    Exact up to ties: the expanded distance ‖r‖² − 2 q·r (one GEMM per chunk of queries) is
    reduced to its minimum over blocks of `_BLOCK` consecutive rows; every row of the
    `_N_BLOCKS` blocks with the smallest minima (which hold at least the rows of the
    `_N_BLOCKS` smallest expanded distances) is re-scored by the direct ‖q − r‖².  A block
    minimum is a plain vectorized reduction, while XLA CPU's argmin / top-k over all ``n_r``
    columns are several times slower than the GEMM itself.  Memory: ``chunk × n_r``.

    ``n_valid`` (traced, optional): only the first ``n_valid`` queries are real (a target
    padded to its size bucket); the chunks past them are skipped and answer 0.  A 5.0K target
    in the 8192 bucket of a small collection then searches 20 chunks instead of 32.  (Under
    ``vmap`` the skip becomes a select: the same answers, no saving.)
    """
    n_q, d = qry.shape
    n_r = ref.shape[0]
    n_chunks = -(-n_q // chunk)
    # Distances are translation invariant; centring keeps ‖r‖² small next to the gaps between
    # neighbours, so the expanded form loses little to cancellation.
    centre = jnp.mean(ref, axis=0)
    ref, qry = ref - centre, qry - centre
    qp = jnp.pad(qry, ((0, n_chunks * chunk - n_q), (0, 0)))
    n_blk = -(-n_r // _BLOCK)
    ref = jnp.pad(ref, ((0, n_blk * _BLOCK - n_r), (0, 0)))
    valid = jnp.arange(n_blk * _BLOCK) < n_r
    ref_sq = jnp.where(valid, jnp.sum(ref * ref, axis=1), jnp.inf)  # padding rows never win
    ref_blocks = ref.reshape(n_blk, _BLOCK, d)
    n_top = min(_N_BLOCKS, n_blk)
    offsets = jnp.arange(_BLOCK)

    def one_chunk(q):  # (chunk, d)
        # ‖q − r‖² − ‖q‖²: the ranking over r does not need ‖q‖².  HIGHEST keeps GPUs off TF32.
        score = ref_sq[None, :] - 2.0 * jnp.matmul(q, ref.T, precision=lax.Precision.HIGHEST)
        bmin = jnp.min(score.reshape(q.shape[0], n_blk, _BLOCK), axis=2)  # (chunk, n_blk)
        # top_k in float32 whatever the dtype (XLA CPU sorts in float64); subtracting the row
        # minimum first keeps the gaps near it in float32; the re-scoring below is exact.
        if bmin.dtype != jnp.float32:
            bmin = (bmin - jnp.min(bmin, axis=1, keepdims=True)).astype(jnp.float32)
        _, blk = lax.top_k(-bmin, n_top)  # (chunk, n_top)
        diff = q[:, None, None, :] - ref_blocks[blk]  # (chunk, n_top, _BLOCK, d)
        exact = jnp.sum(diff * diff, axis=-1).reshape(q.shape[0], n_top * _BLOCK)
        ids = (blk[:, :, None] * _BLOCK + offsets).reshape(q.shape[0], n_top * _BLOCK)
        exact = jnp.where(ids < n_r, exact, jnp.inf)
        best = jnp.argmin(exact, axis=1)
        return jnp.take_along_axis(ids, best[:, None], axis=1)[:, 0].astype(jnp.int32)

    chunks = qp.reshape(n_chunks, chunk, d)
    if n_valid is None:
        out = lax.map(one_chunk, chunks)
    else:
        skip = lambda q: jnp.zeros(q.shape[0], jnp.int32)  # noqa: E731
        out = lax.map(lambda a: lax.cond(a[0] * chunk < n_valid, one_chunk, skip, a[1]),
                      (jnp.arange(n_chunks), chunks))
    return out.reshape(-1)[:n_q]


def _to_p2p(C, evecs_m, evecs_n, chunk: int, adjoint: bool, n_valid=None):
    """Point map N → M of ``C`` (k_N, k_M) with Φ_M (n_M, k_M), Φ_N (n_N, k_N) (``n_valid``:
    as `_nearest`, the target's real vertices)."""
    if adjoint:
        ref, qry = evecs_m, evecs_n @ C
    else:
        ref, qry = evecs_m @ C.T, evecs_n
    return _nearest(ref, qry, chunk, n_valid)


def _from_p2p(p2p, evecs_m, evecs_n, mass_n):
    """C = Φ_Nᵀ A_N Π Φ_M: a gather and one GEMM, never the (n_N, n_M) matrix Π."""
    return evecs_n.T @ (mass_n[:, None] * evecs_m[p2p])


@functools.partial(jax.jit, static_argnames=("chunk", "adjoint"))
def _fmap_to_p2p_jit(C, evecs_m, evecs_n, *, chunk, adjoint):
    dt = jnp.result_type(float)
    return _to_p2p(jnp.asarray(C, dt), jnp.asarray(evecs_m, dt), jnp.asarray(evecs_n, dt),
                   chunk, adjoint)


@jax.jit
def _fmap_from_p2p_jit(p2p, evecs_m, evecs_n, mass_n):
    dt = jnp.result_type(float)
    return _from_p2p(p2p, jnp.asarray(evecs_m, dt), jnp.asarray(evecs_n, dt),
                     jnp.asarray(mass_n, dt))


@functools.partial(jax.jit, static_argnames=("chunk",))
def _nearest_jit(ref, qry, *, chunk):
    dt = jnp.result_type(float)
    return _nearest(jnp.asarray(ref, dt), jnp.asarray(qry, dt), chunk)


# --------------------------------------------------------------------------- public API


def nearest_neighbors(reference, queries, *, chunk_size: int | None = None) -> jax.Array:
    """Exact nearest neighbour in ``reference`` ``(n_r, d)`` of each row of ``queries`` ``(n_q, d)``
    (chunked brute force, as in [`fmap_to_p2p`][bsfjax.fmap_to_p2p]).

    Returns ``(n_q,)`` int32 indices into ``reference``; the same answer as
    ``scipy.spatial.cKDTree(reference).query(queries)[1]`` except between rows at equal distance.
    At most ``chunk_size × n_r`` distances are held at once (default: about 2 M).
    """
    ref = np.asarray(reference)
    qry = np.asarray(queries)
    if ref.ndim != 2 or qry.ndim != 2 or ref.shape[1] != qry.shape[1]:
        raise BSFError(f"reference (n_r, d) and queries (n_q, d) must be 2-D with the same d, got "
                       f"{ref.shape} and {qry.shape}")
    check_finite(ref, "reference")
    check_finite(qry, "queries")
    if ref.shape[0] == 0:
        raise BSFError("reference must have at least one row")
    if qry.shape[0] == 0:
        return jnp.zeros((0,), jnp.int32)
    return _nearest_jit(ref, qry, chunk=chunk_for(ref.shape[0], qry.shape[0], chunk_size))


def fmap_from_p2p(source_spectrum: Spectrum, target_spectrum: Spectrum, p2p) -> jax.Array:
    """The functional map of a point map: ``C = Φ_Nᵀ A_N Π Φ_M``, shape ``(k_N, k_M)``.

    **Arguments:**

    - `source_spectrum`: spectrum of the source shape ``M`` (its ``k`` sets ``k_M``).
    - `target_spectrum`: spectrum of the target shape ``N`` (``k_N``; ``A_N`` is its ``mass``).
    - `p2p`: ``(n_N,)`` integer array, ``p2p[i]`` the source vertex matched to target vertex ``i``.

    Use ``Spectrum.truncate(k)`` for a smaller map.  With ``p2p`` the identity between a shape
    and itself, ``C`` is the identity (Φᵀ A Φ = I).
    """
    _check_spectrum(source_spectrum, "source_spectrum")
    _check_spectrum(target_spectrum, "target_spectrum")
    idx = _as_index_array(p2p, target_spectrum.n_vertices, source_spectrum.n_vertices, "p2p")
    # unit-area bases in float64 first: areas of a mesh in units of 1e20 overflow float32
    sm, am, sn, an = unit_area_pair(source_spectrum, target_spectrum)
    C = _fmap_from_p2p_jit(idx, sm.evecs, sn.evecs, sn.mass)
    return map_to_unit_area(C, am, an, inverse=True)


def fmap_to_p2p(C, source_spectrum: Spectrum, target_spectrum: Spectrum, *,
                adjoint: bool = False, chunk_size: int | None = None,
                rows=None) -> jax.Array:
    """The point map of a functional map: nearest neighbours in the aligned spectral embedding.

    Each target vertex ``y`` takes the source vertex ``x`` minimizing ``‖Φ_M(x) Cᵀ − Φ_N(y)‖``
    (or ``‖Φ_M(x) − Φ_N(y) C‖`` with ``adjoint``) between the two shapes rescaled to one area
    (`bsfjax.unit_area_pair`; in the given bases, ``Φ_M Cᵀ·S_M/S_N`` against ``Φ_N``):
    the comparison presumes an orthogonal ``C``, which an isometry has between shapes of equal
    area, so the point map does not depend on either mesh's units.

    **Arguments:**

    - `C`: ``(k_N, k_M)`` functional map from source ``M`` to target ``N``.  The first ``k_M``
      (``k_N``) eigenvectors of the source (target) spectrum are used.
    - `source_spectrum`, `target_spectrum`: spectra of ``M`` and ``N``.
    - `adjoint`: compare Φ_N C with Φ_M instead of Φ_N with Φ_M Cᵀ (the two agree for an
      orthogonal C; pyFM's ``use_adj``).
    - `chunk_size`: target vertices per chunk (memory ``chunk_size × n_M``); default about
      2 M distances at once.
    - `rows`: target vertex indices to map (default: every vertex).  Each vertex's match is
      the one it has in the whole map; only the search is smaller.

    **Returns:**

    ``(n_N,)`` int32: ``p2p[i]`` is the source vertex matched to target vertex ``i``
    (with ``rows``, ``(len(rows),)``: the match of vertex ``rows[i]``).
    """
    _check_spectrum(source_spectrum, "source_spectrum")
    _check_spectrum(target_spectrum, "target_spectrum")
    kn, km = _check_fmap(C, source_spectrum.k, target_spectrum.k)
    if rows is not None:
        rows = check_indices(rows, "rows", target_spectrum.n_vertices,
                             what="target vertex indices")
        if rows.ndim != 1:
            raise BSFError(f"rows must be a 1-D array of target vertices, got shape {rows.shape}")
    n_query = target_spectrum.n_vertices if rows is None else rows.size
    chunk = chunk_for(source_spectrum.n_vertices, n_query, chunk_size)
    # the two shapes at one area near 1 before the float32 cast (bsfjax.unit_area_pair): the
    # default comparison presumes an orthogonal C, which an isometry has only at equal areas
    # (the adjoint one is invariant to the areas: Φ_N C and Φ_M both scale by √a_M)
    sm, am, sn, an = unit_area_pair(source_spectrum, target_spectrum)
    C = map_to_unit_area(C, am, an)
    evecs_n = sn.evecs[:, :kn] if rows is None else sn.evecs[rows, :kn]
    return _fmap_to_p2p_jit(C, sm.evecs[:, :km], evecs_n, chunk=chunk, adjoint=bool(adjoint))


# --------------------------------------------------------------------------- ZoomOut


@functools.partial(jax.jit, static_argnames=("sizes_n", "sizes_m", "chunk", "adjoint"))
def _zoomout_jit(C0, evecs_m, evecs_n, mass_n, *, sizes_n, sizes_m, chunk, adjoint):
    dt = jnp.result_type(float)
    evecs_m = jnp.asarray(evecs_m, dt)
    evecs_n = jnp.asarray(evecs_n, dt)
    mass_n = jnp.asarray(mass_n, dt)
    kn, km = sizes_n[-1], sizes_m[-1]
    kn0, km0 = C0.shape
    C = jnp.zeros((kn, km), dt).at[:kn0, :km0].set(jnp.asarray(C0, dt))
    sizes_n_arr = jnp.asarray(sizes_n, jnp.int32)
    sizes_m_arr = jnp.asarray(sizes_m, jnp.int32)
    cols_n = jnp.arange(kn)
    cols_m = jnp.arange(km)

    def body(it, C):
        # C is zero outside its active (k_n, k_m) block and the bases are masked to the block,
        # so every distance and projection equals the truncated computation.
        cur_n = (cols_n < sizes_n_arr[it]).astype(dt)
        cur_m = (cols_m < sizes_m_arr[it]).astype(dt)
        p2p = _to_p2p(C, evecs_m * cur_m, evecs_n * cur_n, chunk, adjoint)
        new_n = (cols_n < sizes_n_arr[it + 1]).astype(dt)
        new_m = (cols_m < sizes_m_arr[it + 1]).astype(dt)
        return _from_p2p(p2p, evecs_m * new_m, evecs_n * new_n, mass_n)

    return lax.fori_loop(0, len(sizes_n) - 1, body, C)


def _size_schedule(k0: int, k: int, step: int, n_iter: int) -> tuple[int, ...]:
    return tuple(min(k0 + i * step, k) for i in range(n_iter + 1))


def zoomout(C, source_spectrum: Spectrum, target_spectrum: Spectrum, k, *, step: int = 1,
            samples=None, adjoint: bool = False, chunk_size: int | None = None) -> jax.Array:
    """ZoomOut (Melzi et al. 2019): spectral upsampling of ``C`` from ``k₀`` to ``k``.

    Each iteration converts the current map to a point map ([`fmap_to_p2p`][bsfjax.fmap_to_p2p]) and back to a
    functional map ([`fmap_from_p2p`][bsfjax.fmap_from_p2p]) ``step`` basis functions larger, until the size is
    ``k``; the last step is clipped.  One jitted ``fori_loop``, on the two shapes at one area
    (as [`fmap_to_p2p`][bsfjax.fmap_to_p2p]; the result is converted back to the given bases).

    **Arguments:**

    - `C`: ``(k₀_N, k₀_M)`` initial functional map.
    - `source_spectrum`, `target_spectrum`: with at least ``k`` eigenpairs each.
    - `k`: final size, an int (square map) or ``(k_source, k_target)`` as in pyFM (the map is
      then ``(k_target, k_source)``).
    - `step`: basis functions added per iteration (pyFM's ``step``).
    - `samples`: ``None`` (every vertex), or ``(source, target)``
      [`Subsample`][bsfjax.Subsample] s ([`bsfjax.subsample`][bsfjax.subsample]): each iteration then maps
      the target samples to the nearest source samples and integrates over the target's
      sample cells, ``C = Φ_N[S_N]ᵀ diag(w) Φ_M[π(S_N)]`` with ``w`` the cell areas (the
      subsampled ZoomOut of pyFM and of Magnet & Ovsjanikov 2023).  The searches cost
      ``s_N × s_M`` instead of ``n_N × n_M``.  Measured on 9 FAUST / FAUST_5k pairs with
      2000 samples per shape: the same point-map accuracy as every vertex (SMPL parts
      94.30 % vs 94.41 %, ±1 point per pair either way).
    - `adjoint`, `chunk_size`: as in [`fmap_to_p2p`][bsfjax.fmap_to_p2p].

    **Returns:**

    ``(k_target, k_source)`` refined functional map; ``fmap_to_p2p`` gives its point map.
    """
    _check_spectrum(source_spectrum, "source_spectrum")
    _check_spectrum(target_spectrum, "target_spectrum")
    kn0, km0 = _check_fmap(C, source_spectrum.k, target_spectrum.k)
    if isinstance(k, (int, np.integer)) and not isinstance(k, bool):
        km = kn = k
    else:
        try:
            km, kn = k
        except (TypeError, ValueError) as exc:
            raise BSFError(f"k must be an int or a pair (k_source, k_target), got {k!r}") from exc
    if not all(isinstance(v, (int, np.integer)) and not isinstance(v, bool) for v in (kn, km)):
        raise BSFError(f"k must be an int or a pair of ints (k_source, k_target), got {k!r}")
    if kn < kn0 or km < km0:
        raise BSFError(f"k={k!r} must be at least the size of C {np.shape(C)}")
    if kn > target_spectrum.k or km > source_spectrum.k:
        raise BSFError(f"k={k!r} exceeds the eigenpairs available: target has "
                       f"{target_spectrum.k}, source has {source_spectrum.k}")
    if not isinstance(step, (int, np.integer)) or isinstance(step, bool) or step < 1:
        raise BSFError(f"step must be a positive integer, got {step!r}")
    n_iter = max(math.ceil((kn - kn0) / step), math.ceil((km - km0) / step))
    sizes_n = _size_schedule(int(kn0), int(kn), int(step), n_iter)
    sizes_m = _size_schedule(int(km0), int(km), int(step), n_iter)
    # the shapes at one area, as fmap_to_p2p: its nearest neighbours presume an orthogonal C
    sm, am, sn, an = unit_area_pair(source_spectrum, target_spectrum)
    evecs_m, evecs_n, mass_n = sm.evecs[:, :km], sn.evecs[:, :kn], sn.mass
    if samples is not None:
        sub_m, sub_n = check_samples(samples, source_spectrum.n_vertices,
                                      target_spectrum.n_vertices)
        mass_n = sub_n.weights(jnp.asarray(mass_n))
        evecs_m, evecs_n = jnp.asarray(evecs_m)[sub_m.indices], jnp.asarray(evecs_n)[sub_n.indices]
    chunk = chunk_for(evecs_m.shape[0], evecs_n.shape[0], chunk_size)
    C = map_to_unit_area(C, am, an)
    out = _zoomout_jit(C, evecs_m, evecs_n, mass_n, sizes_n=sizes_n, sizes_m=sizes_m,
                       chunk=chunk, adjoint=bool(adjoint))
    return map_to_unit_area(out, am, an, inverse=True)


def check_samples(samples, n_m: int, n_n: int):
    """``samples`` as two checked [`Subsample`][bsfjax.Subsample] s of ``n_m`` and ``n_n`` vertices."""
    try:
        sub_m, sub_n = samples
        pairs = [(np.asarray(s.indices), np.asarray(s.cells)) for s in (sub_m, sub_n)]
    except (TypeError, ValueError, AttributeError) as exc:
        raise BSFError("samples must be (source, target) bsfjax.Subsample s "
                       "(bsfjax.subsample(mesh, n))") from exc
    for name, (idx, cells), n in (("source", pairs[0], n_m), ("target", pairs[1], n_n)):
        if idx.ndim != 1 or cells.shape != (n,):
            raise BSFError(f"{name} samples: expected (s,) indices and ({n},) cells, got "
                           f"{idx.shape} and {cells.shape} (was the subsample made on this "
                           f"mesh?)")
        check_indices(idx, f"{name} samples: indices", n)
        check_indices(cells, f"{name} samples: cells", idx.size, what="positions in indices")
    return sub_m, sub_n


# --------------------------------------------------------------------------- ICP


def _nearest_orthogonal(C):
    """``U I Vᵀ`` from the SVD ``C = U S Vᵀ``: the closest (semi-)orthogonal matrix in Frobenius."""
    u, _, vt = jnp.linalg.svd(C, full_matrices=False)
    return u @ vt


@functools.partial(jax.jit, static_argnames=("n_iter", "chunk", "adjoint", "bijective"))
def _icp_jit(C0, evecs_m, evecs_n, mass_m, mass_n, *, n_iter, chunk, adjoint, bijective):
    dt = jnp.result_type(float)
    evecs_m = jnp.asarray(evecs_m, dt)
    evecs_n = jnp.asarray(evecs_n, dt)
    mass_m = jnp.asarray(mass_m, dt)
    mass_n = jnp.asarray(mass_n, dt)

    def body(_, C):
        p2p_nm = _to_p2p(C, evecs_m, evecs_n, chunk, adjoint)
        C_new = _from_p2p(p2p_nm, evecs_m, evecs_n, mass_n)
        if bijective:
            # M → N with the inverse map Cᵀ, pulled back as a (k_M, k_N) map, then transposed.
            p2p_mn = _to_p2p(C.T, evecs_n, evecs_m, chunk, adjoint)
            C_new = 0.5 * (C_new + _from_p2p(p2p_mn, evecs_n, evecs_m, mass_m).T)
        return _nearest_orthogonal(C_new)

    return lax.fori_loop(0, n_iter, body, jnp.asarray(C0, dt))


def icp_refine(C, source_spectrum: Spectrum, target_spectrum: Spectrum, *, n_iter: int = 10,
               adjoint: bool = False, bijective: bool = False,
               chunk_size: int | None = None) -> jax.Array:
    """Orthogonal ICP refinement (Ovsjanikov et al. 2012) of a ``(k_N, k_M)`` functional map.

    Each of ``n_iter`` iterations: point map of C, its functional map C', then
    C ← argmin_{OᵀO = I} ‖O − C'‖ = U Vᵀ.  With ``bijective=True`` the point map ``M → N`` of the
    inverse map Cᵀ is computed as well and its (transposed) functional map averaged with C'
    before the projection, so both directions must agree.  One jitted ``fori_loop``, on the two
    shapes at one area (`bsfjax.unit_area_pair`): in the given bases the result is
    orthogonal times ``√(S_N/S_M)``.
    """
    _check_spectrum(source_spectrum, "source_spectrum")
    _check_spectrum(target_spectrum, "target_spectrum")
    kn, km = _check_fmap(C, source_spectrum.k, target_spectrum.k)
    if not isinstance(n_iter, (int, np.integer)) or isinstance(n_iter, bool) or n_iter < 0:
        raise BSFError(f"n_iter must be a non-negative integer, got {n_iter!r}")
    n_m, n_n = source_spectrum.n_vertices, target_spectrum.n_vertices
    chunk = chunk_for(max(n_m, n_n), max(n_m, n_n), chunk_size)
    # orthogonal between the two shapes at one area (as fmap_to_p2p), back in the given bases
    sm, am, sn, an = unit_area_pair(source_spectrum, target_spectrum)
    C = map_to_unit_area(C, am, an)
    out = _icp_jit(C, sm.evecs[:, :km], sn.evecs[:, :kn], sm.mass, sn.mass, n_iter=int(n_iter),
                   chunk=chunk, adjoint=bool(adjoint), bijective=bool(bijective))
    return map_to_unit_area(out, am, an, inverse=True)
