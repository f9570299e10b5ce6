r"""Descriptor-guided ZoomOut continuation: the point maps a refinement of a map visits.

ZoomOut (Melzi et al. 2019) alternates a point map and a functional map one block of
eigenpairs larger.  Here it restarts from a given point map ``T₀`` (target vertex → source
vertex) and its nearest-neighbour step also compares a few descriptor dimensions:

.. math::

    T_t(y) = \arg\min_x \big\| Φ_M(x) C_t^⊤ − Φ_N(y) \big\|^2
             + w^2 s_t^2 \big\| D_M(x) − D_N(y) \big\|^2,
    \qquad C_{t+1} = Φ_N^⊤ A_N Π_{T_t} Φ_M

with the bases truncated to the sizes ``k_start, k_start + step, …, k_max``, ``s_t`` the mean
row norm of the target's truncated basis (so ``w`` is relative to the spectral part) and
``D`` the wave kernel signatures of each shape (from ``k_start`` eigenpairs, each column
standardized on its own shape) projected on their ``descriptor_dims`` leading principal axes
on the source.  Plain ZoomOut converges to a map that is locally consistent in the spectral
embedding but may slide along regions with little spectral detail (a torso); the descriptor
term ties the point map to the local geometry.  [`bsfjax.RefinedPullBack`][bsfjax.RefinedPullBack] pulls
functions back through the last ``n_keep`` point maps and averages them (a vote for labels).
With samples ([`bsfjax.subsample`][bsfjax.subsample]) the steps whose maps are not kept run on them, as
[`bsfjax.zoomout`][bsfjax.zoomout] does: ``T_t`` maps the target samples to source samples and
``C_{t+1} = Φ_N[S]ᵀ diag(w) Φ_M[T_t(S)]`` with ``w`` the areas of the target's sample cells.

Measured (``docs/results/segmentation.md``, "Real segmentations"; SMPL parts, 9 FAUST / FAUST_5k
pairs):
the last map alone, the steps before it on the map's 2000 samples per shape (the default of
``"refined"``): +0.65 points of area accuracy over the pull-back of the CLI's estimated map on
average (−0.03 … +1.17), +4.1 with a crude k = 20 map; the vote of the last three maps on every
vertex: +0.51 / +3.9 for three searches over every vertex instead of one.  Steps of 10 instead
of 20 (every vertex, vote) gave +0.62 / +4.5; without the descriptor term, +0.27 / +4.2.  From
an exact map it loses 1–5 points: the continuation's fixed point is not the registration.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
from jax import lax

from ._descriptors import _auto_energies, _nonzero, _prepare, _signature
from .._util import BSFError
from ._fmap import _as_index_array, check_samples, chunk_for, _from_p2p, _nearest, _to_p2p
from .._spectral import Spectrum, unit_area_pair
from .._util import check_int, check_real

__all__ = ["refine_point_maps", "refinement_sizes", "REFINE_EIGENPAIRS"]

#: Eigenpairs the mesh-level commands (``bsfjax transfer``, ``bsfjax demo``, ``reproduce
#: segmentation``) compute for ``"refined"``: the continuation's last basis size.
REFINE_EIGENPAIRS = 100


def refinement_sizes(k_start: int, k_max: int, step: int) -> tuple[int, ...]:
    """``(k_start, k_start + step, …, k_max)``; ``k_start`` is clipped to ``k_max``."""
    k0 = min(k_start, k_max)
    n_it = math.ceil((k_max - k0) / step)
    return tuple(min(k0 + i * step, k_max) for i in range(n_it + 1))


def _wks_std(evals, evecs, mass, n_energies: int):
    """WKS (pyFM's automatic energies, variance 7) with each column standardized."""
    ev, phi = _prepare(evals, evecs, mass, True)
    keep, _ = _nonzero(ev)
    energies, sigma = _auto_energies(ev, n_energies, 7.0)
    gap = energies[:, None] - jnp.log(jnp.where(keep, ev, 1.0))[None, :]
    weights = jnp.where(keep[None, :], jnp.exp(-gap * gap / (2 * sigma ** 2)), 0.0)
    F = _signature(weights, phi, None, True)  # (n, E)
    # statistics over the shape's own vertices: zero-mass rows are padding (size buckets of
    # bsfjax.transfer_collection) and must not move them
    valid = (jnp.asarray(mass) > 0)[:, None]
    mean = _vertex_mean(F, valid)
    sd = jnp.sqrt(_vertex_mean((F - mean) ** 2, valid))
    return (F - mean) / jnp.where(sd > 0, sd, 1.0) / math.sqrt(n_energies)


def _vertex_mean(x, valid):
    """Mean over the rows of ``x`` where ``valid`` (the real vertices), per column."""
    return jnp.sum(jnp.where(valid, x, 0.0), axis=0) / jnp.maximum(jnp.sum(valid), 1)


def _descriptors(spec_m: Spectrum, spec_n: Spectrum, k: int, n_energies: int, dims: int):
    dm = _wks_std(spec_m.evals[:k], spec_m.evecs[:, :k], spec_m.mass, n_energies)
    dn = _wks_std(spec_n.evals[:k], spec_n.evecs[:, :k], spec_n.mass, n_energies)
    # principal axes of the source's descriptors: fewer columns in every distance, same maps
    # (8 of 100 dimensions changed the SMPL accuracy by ≤ 0.04 points on 9 FAUST pairs)
    # (eigh of the E × E covariance: XLA's SVD of the n × E matrix takes seconds on a CPU)
    _, vecs = jnp.linalg.eigh(dm.T @ dm)
    axes = vecs[:, ::-1][:, :dims]
    return dm @ axes, dn @ axes


def refine_core(p2p, spec_m: Spectrum, spec_n: Spectrum, *, sizes: tuple[int, ...],
                n_keep: int, weight: float, dims: int, n_energies: int, chunk: int,
                samples=None):
    """The last ``n_keep`` point maps ``(n_keep, n_N)`` of the continuation from ``p2p``
    (traceable: the engine runs it under jit and vmap).  ``sizes`` as
    `refinement_sizes`; the spectra must hold ``sizes[-1]`` eigenpairs.  ``samples``:
    ``None`` or ``(source, target)`` [`Subsample`][bsfjax.Subsample] s; the steps before the last
    ``n_keep`` then run on them (searches ``s_N × s_M``, ``C`` the quadrature over the target's
    sample cells, as [`bsfjax.zoomout`][bsfjax.zoomout] with ``samples``)."""
    k = sizes[-1]
    dt = jnp.result_type(float)
    phi_m = jnp.asarray(spec_m.evecs[:, :k], dt)
    phi_n = jnp.asarray(spec_n.evecs[:, :k], dt)
    mass_n = jnp.asarray(spec_n.mass, dt)
    if weight > 0:
        dm, dn = _descriptors(spec_m, spec_n, sizes[0], n_energies, dims)
        dm, dn = dm.astype(dt), dn.astype(dt)
    else:
        dm, dn = phi_m[:, :0], phi_n[:, :0]
    cols = jnp.arange(k)
    sizes_arr = jnp.asarray(sizes + (sizes[-1],), jnp.int32)
    C = _from_p2p(p2p, phi_m * (cols < sizes[0]), phi_n * (cols < sizes[0]), mass_n)

    def steps(C, its, phi_m, phi_n, w_n, dm, dn, chunk, to_vertices):
        """The continuation's steps ``its`` on these rows; ``to_vertices`` maps a row of
        ``phi_m`` to its source vertex."""
        def body(C, it):
            # bases masked to the current size: the distances equal the truncated computation
            cur = (cols < sizes_arr[it]).astype(dt)
            ref, qry = phi_m * cur @ C.T, phi_n * cur
            if weight > 0:
                # the spectral part's mean row norm over the real rows (padding has w = 0)
                s = weight * _vertex_mean(jnp.linalg.norm(qry, axis=1), w_n > 0)
                ref = jnp.concatenate([ref, s * dm], axis=1)
                qry = jnp.concatenate([qry, s * dn], axis=1)
            p = _nearest(ref, qry, chunk, jnp.sum(w_n > 0))  # (padding last: skipped)
            nxt = (cols < sizes_arr[it + 1]).astype(dt)
            return _from_p2p(p, phi_m * nxt, phi_n * nxt, w_n), to_vertices(p)

        return lax.scan(body, C, its)

    n_full = len(sizes) if samples is None else n_keep
    first_full = len(sizes) - n_full
    if first_full > 0:
        sub_m, sub_n = samples
        idx_m, idx_n = jnp.asarray(sub_m.indices), jnp.asarray(sub_n.indices)
        C, _ = steps(C, jnp.arange(first_full), phi_m[idx_m], phi_n[idx_n],
                     sub_n.weights(mass_n), dm[idx_m], dn[idx_n],
                     chunk_for(idx_m.shape[0], idx_n.shape[0], None), lambda p: idx_m[p])
    _, maps = steps(C, jnp.arange(first_full, len(sizes)), phi_m, phi_n, mass_n, dm, dn, chunk,
                    lambda p: p)
    return maps[n_full - n_keep:]


@functools.partial(jax.jit, static_argnames=("sizes", "n_keep", "weight", "dims", "n_energies",
                                             "chunk"))
def _refine_jit(p2p, spec_m, spec_n, samples, *, sizes, n_keep, weight, dims, n_energies, chunk):
    return refine_core(p2p, spec_m, spec_n, sizes=sizes, n_keep=n_keep, weight=weight,
                       dims=dims, n_energies=n_energies, chunk=chunk, samples=samples)


def start_point_map(pair_p2p, C, spec_m: Spectrum, spec_n: Spectrum, chunk: int):
    """The input point map, or the nearest-neighbour point map of ``C`` when there is none."""
    if pair_p2p is not None:
        return jnp.asarray(pair_p2p)
    kn, km = C.shape[-2:]
    return _to_p2p(jnp.asarray(C, spec_m.evecs.dtype), spec_m.evecs[:, :km],
                   spec_n.evecs[:, :kn], chunk, False)


def check_options(*, k_start, k_max, step, n_keep, descriptor_weight, descriptor_dims,
                  n_energies) -> None:
    """Raise [`BSFError`][bsfjax.BSFError] for an out-of-range option (names as given)."""
    check_int(k_start, "k_start", 1)
    if k_max is not None:
        check_int(k_max, "k_max", 1)
    check_int(step, "step", 1)
    check_int(n_keep, "n_vote", 1)
    check_int(descriptor_dims, "descriptor_dims", 1)
    check_int(n_energies, "n_energies", 2)
    if check_real(descriptor_weight, "descriptor_weight") < 0:
        raise BSFError(f"descriptor_weight must be ≥ 0, got {descriptor_weight!r}")
    if descriptor_dims > n_energies:
        raise BSFError(f"descriptor_dims ({descriptor_dims}) must be at most n_energies "
                       f"({n_energies})")


def sizes_for(k_source: int, k_target: int, k_start: int, k_max: int | None, step: int):
    """The size schedule for spectra of ``k_source`` and ``k_target`` eigenpairs."""
    avail = min(k_source, k_target)
    if k_max is not None and k_max > avail:
        raise BSFError(f"k_max={k_max} exceeds the eigenpairs of the spectra ({k_source} source, "
                       f"{k_target} target)")
    return refinement_sizes(k_start, avail if k_max is None else k_max, step)


def refine_point_maps(source: Spectrum, target: Spectrum, p2p, *, k_start: int = 60,
                      k_max: int | None = None, step: int = 20, n_keep: int = 3,
                      descriptor_weight: float = 0.5, descriptor_dims: int = 8,
                      n_energies: int = 100, samples=None) -> jax.Array:
    """The last ``n_keep`` point maps of the descriptor-guided continuation of ``p2p``.

    **Arguments:**

    - ``source``, ``target``: spectra; ``k_max`` (default: the smaller size) eigenpairs used.
    - `p2p`: ``(n_N,)`` point map target vertex → source vertex to start from.
    - ``k_start``, ``step``: the first basis size (clipped to ``k_max``) and the growth per
      iteration.
    - `n_keep`: how many of the last point maps to return (at most one per size).
    - `descriptor_weight`: ``w`` above (0: plain ZoomOut from the point map).
    - ``descriptor_dims``, ``n_energies``: principal WKS dimensions kept, WKS energies.
    - `samples`: ``None`` (every step on every vertex) or ``(source, target)``
      [`Subsample`][bsfjax.Subsample] s ([`bsfjax.subsample`][bsfjax.subsample], as [`bsfjax.zoomout`][bsfjax.zoomout]): the
      steps whose maps are not returned then run on the samples, the last ``n_keep`` on every
      vertex.

    Returns ``(min(n_keep, number of sizes), n_N)`` int32 point maps, the last one the most
    refined.
    """
    check_options(k_start=k_start, k_max=k_max, step=step, n_keep=n_keep,
                  descriptor_weight=descriptor_weight, descriptor_dims=descriptor_dims,
                  n_energies=n_energies)
    for name, s in (("source", source), ("target", target)):
        if not isinstance(s, Spectrum):
            raise BSFError(f"{name} must be a bsfjax.Spectrum, got {type(s).__name__}")
    p = _as_index_array(p2p, target.n_vertices, source.n_vertices, "p2p")
    sizes = sizes_for(source.k, target.k, k_start, k_max, step)
    if samples is not None:
        samples = check_samples(samples, source.n_vertices, target.n_vertices)
    # the two shapes at one area near 1, on the host in float64 before the float32 cast
    source, _, target, _ = unit_area_pair(source, target)
    return _refine_jit(jnp.asarray(p), source, target, samples, sizes=sizes,
                       n_keep=min(n_keep, len(sizes)), weight=float(descriptor_weight),
                       dims=int(descriptor_dims), n_energies=int(n_energies),
                       chunk=chunk_for(source.n_vertices, target.n_vertices, None))
