r"""The paper's competitors and the BSF coders behind one interface (Melzi 2019, Sec. 6).

Every method maps functions ``F`` ``(m, n_M)`` on a source shape ``M`` to an approximation on
``M`` and (given a functional map) a transfer to the target ``N``.  Notation: Φ ``(n_M, k)`` and
Ψ ``(n_N, k_N)`` the eigenbases, ``A`` the vertex areas, ``C`` ``(k_N, k)`` the map.

``"std"``   spectral projection (paper Eq. 5): ``a = Φᵀ A f``, ``f̃ = Φ a``, transfer ``Ψ C a``.
``"std2"``  the same with ``2k`` eigenfunctions and its own ``(2k_N, 2k)`` map ``C2``.
``"p2p"``   pull-back through a point map ``T`` (target vertex → source vertex): ``f ∘ T``.
            No approximation (it would be ``f`` itself).
``"prod"``  Nogneng et al. 2018: ``f ≈ Σ_{i≤j} c_ij φ_i φ_j`` (the ``k(k+1)/2`` products,
            area-weighted truncated least squares, ``Params.prod_rcond``), transferred by
            the *extended* map ``φ_i φ_j ↦ (Cφ_i)(Cφ_j)``.  With ``S`` the symmetric
            ``k × k`` matrix of the coefficients (``S_ii = c_ii``, ``S_ij = S_ji = c_ij / 2``)
            this is
            ``f_N(x) = ψ(x)ᵀ (C S Cᵀ) ψ(x)`` — the extended map never has to be formed.
``"geod"``  a frame of geodesic-ball indicators around the BSF centres at 3 radii (one per
            BSF scale: ``r_s = √(ā_s / π)``, the radius of a flat disc with the mean area
            ``ā_s`` of the BSF atoms of scale ``τ_s``).  Coded with ``params.frame_coder``;
            transferred by carrying each ball's spectral coefficients ``Φᵀ A χ`` through ``C``
            and re-binarizing ``[g ≥ ½ max g]`` (halfway between an indicator's two values).
``"heat"``  saturated heat kernels: the BSF's band-limited kernels ``g`` (same centres and
            scales) as ``min(1, |g| / (γ max |g|))`` — equal to 1 exactly on the BSF atom and
            decaying outside; transferred like the BSF (coefficients through ``C``).
``"lstsq"``, ``"omp_error"``, ``"omp"``, ``"lasso"``
            ours: the Binary Sparse Frame (:func:`bsfjax.build_frame`) coded with that method
            of :func:`bsfjax.encode` and decoded on ``M`` and on the transferred frame.

Coding is area weighted by default (``Params.weights = "area"``): the codes minimise the same
``‖f − f̃‖_A`` the metrics report.  ``omp_error`` stops at ``‖f − Bα‖_A ≤ ε_f · ‖f‖_A``
(paper: ``ε = ‖f‖/10``).

Everything in :func:`run_baseline` after validation is one jitted function; a stacked
:class:`PairInput` (leading pair axis on every array) runs all pairs under one ``vmap``.
"""

from __future__ import annotations

import dataclasses
from functools import partial
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._encode import decode, encode
from ._errors import BSFError
from ._frame import build_frame, transfer_frame, unique_atoms
from ._spectrum import Spectrum

__all__ = ["METHODS", "CODERS", "FRAME_TRANSFERS", "TRANSFER_ONLY", "Params", "PairInput", "BaselineResult",
           "run_baseline", "geodesic_ball_radii", "product_basis"]

CODERS = ("lstsq", "omp_error", "omp", "lasso")
#: How the BSF is carried to the target (:attr:`Params.frame_transfer`).
FRAME_TRANSFERS = ("binary", "p2p")
METHODS = ("std", "std2", "p2p", "prod", "geod", "heat") + CODERS
#: Methods without an approximation on the source (only a transfer).
TRANSFER_ONLY = ("p2p",)


@dataclasses.dataclass(frozen=True)
class Params:
    """Settings of the frames and coders (static; defaults are the paper's).

    Attributes:
        taus: BSF diffusion scales (``tau_convention`` of :func:`bsfjax.build_frame`), or
            ``"adaptive"`` (:func:`bsfjax.adaptive_taus`, chosen per shape and k).
        gamma: BSF threshold γ.
        tau_convention: ``"unit_area"`` (default) or ``"raw"``.
        sparsity: OMP's ``S``.
        eps_fraction: ``omp_error`` stops at ``‖f − Bα‖ ≤ eps_fraction · ‖f‖`` (paper 1/10).
        lam: lasso's relative ``λ`` (see :func:`bsfjax.encode`).
        lasso_maxiter: lasso iteration cap.
        weights: ``"area"`` (codes minimise ``‖·‖_A``) or ``None`` (Euclidean, as SPAMS).
        frame_coder: coder of the ``geod`` and ``heat`` frames (one of :data:`CODERS`).
        geod_level: re-binarization level of transferred geodesic balls, relative to the max.
        prod_rcond: relative singular-value cut-off of ``prod``'s least-squares fit.  The
            product basis is badly conditioned: the minimum-norm fit at float32 resolution
            (``rcond ≈ 1e-3``) has huge cancelling coefficients whose images under a
            truncated ``C`` no longer cancel (transfer error 0.9 at k = 10 and 1.8 at k = 30 on
            FAUST 000→001 with the ground-truth map).  ``3e-2`` was the best of
            {1e-3, 1e-2, 3e-2, 1e-1} on that pair (0.39 / 0.28), i.e. tuned in prod's favour.
        prune: code the BSF in its distinct non-empty atoms only (duplicates and empties are
            masked, :func:`bsfjax.unique_atoms`; same span, no ties between equal columns).
        frame_transfer: how the BSF reaches the target: ``"binary"`` (paper Eq. 11–12,
            re-binarize ``Φ_N C a``) or ``"p2p"`` (pull the atoms back through
            ``pair.p2p``, :func:`bsfjax.transfer_frame`'s ``p2p``).
        lasso_target: if set, the lasso chooses λ per function for at most this many atoms
            (:func:`bsfjax.encode`'s ``target_atoms``) instead of using ``lam``.
    """

    taus: tuple = (1e-3, 5e-3, 1e-2)
    gamma: float = 0.75
    tau_convention: str = "unit_area"
    sparsity: int = 10
    eps_fraction: float = 0.1
    lam: float = 0.01
    lasso_maxiter: int = 2000
    weights: str | None = "area"
    frame_coder: str = "omp"
    geod_level: float = 0.5
    prod_rcond: float = 3e-2
    prune: bool = False
    frame_transfer: str = "binary"
    lasso_target: int | None = None

    def __post_init__(self):
        if isinstance(self.taus, str):
            if self.taus != "adaptive":
                raise BSFError(f"taus must be positive numbers or 'adaptive', got {self.taus!r}")
        else:
            taus = tuple(float(t) for t in np.atleast_1d(self.taus))
            object.__setattr__(self, "taus", taus)
            if not taus or not all(np.isfinite(t) and t > 0 for t in taus):
                raise BSFError(f"taus must be positive, got {self.taus!r}")
        if not isinstance(self.prune, bool):
            raise BSFError(f"prune must be a bool, got {self.prune!r}")
        if self.frame_transfer not in FRAME_TRANSFERS:
            raise BSFError(f"frame_transfer must be one of {FRAME_TRANSFERS}, got "
                           f"{self.frame_transfer!r}")
        if self.lasso_target is not None and (
                isinstance(self.lasso_target, bool)
                or not isinstance(self.lasso_target, (int, np.integer)) or self.lasso_target < 1):
            raise BSFError(f"lasso_target must be None or a positive int, got "
                           f"{self.lasso_target!r}")
        if not 0 < self.gamma < 1:
            raise BSFError(f"gamma must be in (0, 1), got {self.gamma!r}")
        if isinstance(self.sparsity, bool) or not isinstance(self.sparsity, (int, np.integer)) \
                or self.sparsity < 1:
            raise BSFError(f"sparsity must be a positive int, got {self.sparsity!r}")
        if not (np.isfinite(self.eps_fraction) and self.eps_fraction >= 0):
            raise BSFError(f"eps_fraction must be >= 0, got {self.eps_fraction!r}")
        if not (np.isfinite(self.lam) and self.lam > 0):
            raise BSFError(f"lam must be > 0, got {self.lam!r}")
        if self.weights not in ("area", None):
            raise BSFError(f"weights must be 'area' or None, got {self.weights!r}")
        if self.frame_coder not in CODERS:
            raise BSFError(f"frame_coder must be one of {CODERS}, got {self.frame_coder!r}")
        if not 0 < self.geod_level < 1:
            raise BSFError(f"geod_level must be in (0, 1), got {self.geod_level!r}")
        if not 0 <= self.prod_rcond < 1:
            raise BSFError(f"prod_rcond must be in [0, 1), got {self.prod_rcond!r}")


class PairInput(eqx.Module):
    """Everything a method may need about one source/target pair (or a stack of pairs).

    Attributes:
        source: spectrum of ``M`` (``≥ k`` eigenpairs; ``≥ 2k`` for ``std2``).
        target: spectrum of ``N`` (``≥ k_N``, ``≥ 2k_N`` for ``std2``); ``None`` for
            approximation only.
        C: ``(k_N, k)`` functional map ``M → N`` on coefficients.
        C2: ``(2k_N, 2k)`` map of ``std2``.
        p2p: ``(n_N,)`` int point map, target vertex → source vertex (``p2p``).
        centers: ``(n_c,)`` int BSF centres on ``M`` (ours, ``geod``, ``heat``).
        distances: ``(n_c, n_M)`` geodesic distances from the centres (``geod``).

    A stack of ``P`` pairs has a leading ``P`` axis on every array (equal shapes).
    """

    source: Spectrum
    target: Spectrum | None = None
    C: jax.Array | None = None
    C2: jax.Array | None = None
    p2p: jax.Array | None = None
    centers: jax.Array | None = None
    distances: jax.Array | None = None


class BaselineResult(NamedTuple):
    """Output of :func:`run_baseline` (leading pair axis when the input was stacked)."""

    approximation: jax.Array | None  #: ``(m, n_M)`` on the source, or ``None``
    transferred: jax.Array | None  #: ``(m, n_N)`` on the target, or ``None``


# --------------------------------------------------------------------------- helpers (traceable)


def product_basis(evecs: jax.Array) -> jax.Array:
    """``(n, k(k+1)/2)`` products ``φ_i φ_j``, ``i ≤ j`` in ``numpy.triu_indices`` order."""
    k = evecs.shape[-1]
    iu, ju = np.triu_indices(k)
    return evecs[..., iu] * evecs[..., ju]


def geodesic_ball_radii(atoms: jax.Array, mass: jax.Array, n_scales: int) -> jax.Array:
    """``(n_scales,)`` radii ``√(ā_s / π)`` from the mean area ``ā_s`` of each scale's atoms
    (``atoms`` ``(n, n_scales · n_c)``, scale-major as :class:`bsfjax.Frame`)."""
    areas = (mass @ atoms).reshape(n_scales, -1)
    return jnp.sqrt(jnp.mean(areas, axis=1) / jnp.pi)


def _coder_options(coder: str, params: Params, F, w):
    if coder == "omp":
        return {"sparsity": params.sparsity}
    if coder == "omp_error":
        fn2 = jnp.sum((F * F) * (w if w is not None else 1.0), axis=-1)
        return {"eps": params.eps_fraction ** 2 * fn2}
    if coder == "lasso":
        if params.lasso_target is not None:
            return {"target_atoms": params.lasso_target,
                    "maxiter": params.lasso_maxiter}
        return {"lam": params.lam, "maxiter": params.lasso_maxiter}
    return {}


def _code(atoms, F, coder: str, params: Params, mass):
    """α of ``F`` in ``atoms`` (a plain (n, q) array), area weighted per ``params``."""
    w = mass if params.weights == "area" else None
    opts = _coder_options(coder, params, F, w)
    for name in ("sparsity", "target_atoms"):
        if opts.get(name) is not None and opts[name] > atoms.shape[-1]:
            opts[name] = atoms.shape[-1]
    return encode(atoms, F, coder, weights=w, **opts)


def _saturate(g, gamma):
    m = jnp.max(jnp.abs(g), axis=0)
    pos = m > 0
    return jnp.where(pos, jnp.minimum(1.0, jnp.abs(g) / (gamma * jnp.where(pos, m, 1.0))), 0.0)


def _evecs(spec: Spectrum, k: int):
    return jnp.asarray(spec.evecs)[:, :k]


# --------------------------------------------------------------------------- kernels (one pair)
#
# A kernel codes the functions on the source once and returns ``(approximation, carry)``,
# where ``carry(C)`` transfers them through a map ``C`` ``(k_N, k)``; so several target sizes
# (fig. 7's growing k_N) reuse one code.


def _spectral(pair: PairInput, F, k):
    phi = _evecs(pair.source, k)
    a = (F * pair.source.mass) @ phi  # (m, k): Φᵀ A f
    return a @ phi.T, lambda C: (a @ C.T) @ _evecs(pair.target, C.shape[0]).T


def _std(pair, F, k, params):
    return _spectral(pair, F, k)


def _std2(pair, F, k, params):
    approx, carry = _spectral(pair, F, 2 * k)
    return approx, lambda C: carry(pair.C2)  # its own 2k map


def _p2p(pair, F, k, params):
    return None, lambda C: F[:, pair.p2p]


def _prod(pair, F, k, params):
    phi = _evecs(pair.source, k)
    P = product_basis(phi)  # (n, K)
    # area-weighted, truncated min-norm least squares (see Params.prod_rcond)
    c = encode(P, F, "lstsq", weights=pair.source.mass, rcond=params.prod_rcond)
    iu, ju = np.triu_indices(k)
    half = 0.5 * c
    S = jnp.zeros((F.shape[0], k, k), F.dtype).at[:, iu, ju].add(half).at[:, ju, iu].add(half)

    def carry(C):
        T = jnp.einsum("ia,mab,jb->mij", C, S, C)  # C S Cᵀ
        psi = _evecs(pair.target, C.shape[0])
        return jnp.einsum("ni,mij,nj->mn", psi, T, psi)

    return c @ P.T, carry


def _bsf(pair, k, params):
    return build_frame(pair.source.truncate(k), pair.centers, params.taus, params.gamma,
                       tau_convention=params.tau_convention)


def _ours(coder):
    def kernel(pair, F, k, params):
        frame = _bsf(pair, k, params)
        atoms = frame.atoms
        if params.prune:  # masked duplicates / empties get α = 0
            atoms = atoms * unique_atoms(atoms)[0].astype(atoms.dtype)
        alpha = _code(atoms, F, coder, params, pair.source.mass)
        p2p = pair.p2p if params.frame_transfer == "p2p" else None
        return decode(atoms, alpha), lambda C: decode(
            transfer_frame(frame, C, pair.target, p2p=p2p), alpha)

    return kernel


def _geod(pair, F, k, params):
    frame = _bsf(pair, k, params)
    n_s = frame.n_atoms // int(np.shape(pair.centers)[-1])
    radii = geodesic_ball_radii(frame.atoms, pair.source.mass, n_s)
    D = jnp.asarray(pair.distances, F.dtype)  # (n_c, n)
    atoms = (D[None, :, :] <= radii[:, None, None]).reshape(-1, D.shape[1]).T.astype(F.dtype)
    alpha = _code(atoms, F, params.frame_coder, params, pair.source.mass)
    coeffs = _evecs(pair.source, k).T @ (atoms * pair.source.mass[:, None])  # (k, q): Φᵀ A χ

    def carry(C):
        g = _evecs(pair.target, C.shape[0]) @ (C @ coeffs)
        m = jnp.max(g, axis=0)
        return decode(((g >= params.geod_level * m) & (m > 0)).astype(F.dtype), alpha)

    return decode(atoms, alpha), carry


def _heat(pair, F, k, params):
    frame = _bsf(pair, k, params)
    atoms = _saturate(_evecs(pair.source, k) @ frame.coeffs, params.gamma)
    alpha = _code(atoms, F, params.frame_coder, params, pair.source.mass)

    def carry(C):
        g = _evecs(pair.target, C.shape[0]) @ (C @ frame.coeffs)
        return decode(_saturate(g, params.gamma), alpha)

    return decode(atoms, alpha), carry


_KERNELS = {"std": _std, "std2": _std2, "p2p": _p2p, "prod": _prod, "geod": _geod,
            "heat": _heat, **{c: _ours(c) for c in CODERS}}


@partial(jax.jit, static_argnames=("method", "k", "params", "k_targets", "batched"))
def _run(pair, F, *, method, k, params, k_targets, batched):
    """``k_targets``: ``None`` (no transfer), ``()`` (transfer with all of ``pair.C``) or a
    tuple of row counts ``k_N`` (one transfer per ``C[:k_N]``)."""

    def one(p, f):
        approx, carry = _KERNELS[method](p, f, k, params)
        if k_targets is None:
            return approx, None
        if not k_targets:
            return approx, carry(p.C)
        return approx, tuple(carry(p.C[:kn]) for kn in k_targets)

    return jax.vmap(one)(pair, F) if batched else one(pair, F)


# --------------------------------------------------------------------------- validation + API


def _shape(x):
    return None if x is None else tuple(np.shape(x))


def _check_pair(method: str, pair: PairInput, k: int, transfer: bool, batched: bool,
                params: Params = Params()):
    b = 1 if batched else 0
    src = pair.source
    if not isinstance(src, Spectrum):
        raise BSFError(f"pair.source must be a bsfjax.Spectrum, got {type(src).__name__}")
    n_m, k_m = np.shape(src.evecs)[b:]
    need = 2 * k if method == "std2" else k
    if method != "p2p" and need > k_m:
        raise BSFError(f"method {method!r} with k={k} needs {need} source eigenpairs, the source "
                       f"spectrum has {k_m}")
    if method in ("geod", "heat", *CODERS):
        if pair.centers is None:
            raise BSFError(f"method {method!r} needs pair.centers (the BSF centres)")
    if method in CODERS and params.frame_transfer == "p2p" and transfer:
        n_n = np.shape(pair.target.evecs)[b] if pair.target is not None else None
        if pair.p2p is None or _shape(pair.p2p)[b:] != (n_n,):
            raise BSFError(f"frame_transfer='p2p' needs pair.p2p of shape ({n_n},) (target → "
                           f"source vertex), got {_shape(pair.p2p)}")
    if method == "geod":
        if pair.distances is None:
            raise BSFError("method 'geod' needs pair.distances: (n_c, n_M) geodesic distances "
                           "from the centres (bsfjax.geodesic_distances(mesh, centers))")
        want = (np.shape(pair.centers)[b], n_m)
        if _shape(pair.distances)[b:] != want:
            raise BSFError(f"pair.distances must have shape {want}, got {_shape(pair.distances)}")
    if not transfer:
        return
    tgt = pair.target
    if not isinstance(tgt, Spectrum):
        raise BSFError(f"transfer with {method!r} needs pair.target (a bsfjax.Spectrum)")
    n_n, k_n_avail = np.shape(tgt.evecs)[b:]
    if method == "p2p":
        if pair.p2p is None or _shape(pair.p2p)[b:] != (n_n,):
            raise BSFError(f"method 'p2p' needs pair.p2p of shape ({n_n},) (target → source "
                           f"vertex), got {_shape(pair.p2p)}")
        p = np.asarray(pair.p2p)
        if not np.issubdtype(p.dtype, np.integer) or p.min() < 0 or p.max() >= n_m:
            raise BSFError(f"pair.p2p must hold source vertex indices in [0, {n_m})")
        return
    name, C, kk = ("C2", pair.C2, 2 * k) if method == "std2" else ("C", pair.C, k)
    if C is None:
        raise BSFError(f"transfer with {method!r} needs pair.{name} ({'2k' if kk > k else 'k'}"
                       f" columns)")
    kn, km = _shape(C)[b:]
    if km != kk:
        raise BSFError(f"pair.{name} must have k_M = {kk} columns for k={k}, got shape "
                       f"{_shape(C)}")
    if kn > k_n_avail:
        raise BSFError(f"pair.{name} has {kn} rows but the target spectrum only {k_n_avail} "
                       "eigenpairs")
    if not np.all(np.isfinite(np.asarray(C))):
        raise BSFError(f"pair.{name} contains NaN or inf")


def run_baseline(method: str, pair: PairInput, f, *, k: int | None = None,
                 params: Params = Params(), transfer: bool = True,
                 k_targets=None) -> BaselineResult:
    """Approximate ``f`` on the source and transfer it to the target with one method.

    Args:
        method: one of :data:`METHODS`.
        pair: a :class:`PairInput`, or a stack of ``P`` of them (leading axis ``P``) to run
            all pairs under one ``vmap``.
        f: ``(m, n_M)`` functions on the source (``(P, m, n_M)`` for a stack).
        k: source basis size (number of source eigenfunctions; ``std2`` uses ``2k``).
            Default: the column count of ``pair.C``.
        params: frame and coder settings (:class:`Params`, the paper's by default).
        transfer: also transfer (needs ``target`` and ``C`` / ``C2`` / ``p2p``).
        k_targets: optional sequence of target sizes ``k_N ≤ C.shape[0]``: transfer once per
            ``C[:k_N]`` (the first ``k_N`` rows — exact truncation for a ground-truth map),
            reusing one code on the source; ``transferred`` is then a tuple, one array per
            ``k_N``.  Not for ``std2`` (it has its own map).

    Returns:
        :class:`BaselineResult` ``(approximation, transferred)``: ``(m, n_M)`` and
        ``(m, n_N)`` arrays (``(P, ...)`` for a stack); ``approximation`` is ``None`` for
        ``p2p``, ``transferred`` is ``None`` when ``transfer=False``.
    """
    if method not in _KERNELS:
        raise BSFError(f"method must be one of {METHODS}, got {method!r}")
    if not isinstance(pair, PairInput):
        raise BSFError(f"pair must be a bsfjax.baselines.PairInput, got {type(pair).__name__}")
    if not isinstance(params, Params):
        raise BSFError(f"params must be a bsfjax.baselines.Params, got {type(params).__name__}")
    if method in TRANSFER_ONLY and not transfer:
        raise BSFError(f"method {method!r} only transfers (its approximation would be f itself)")
    batched = np.ndim(pair.source.evals) == 2
    if k is None:
        if pair.C is None:
            raise BSFError("k must be given when pair.C is None")
        k = int(np.shape(pair.C)[-1])
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise BSFError(f"k must be a positive int, got {k!r}")
    k = int(k)
    _check_pair(method, pair, k, transfer, batched, params)
    if k_targets is not None:
        if not transfer or method in ("std2", "p2p"):
            raise BSFError("k_targets needs transfer=True and a method other than 'std2' and "
                           "'p2p' (their transfer does not use C)")
        try:
            k_targets = tuple(int(v) for v in k_targets)
        except (TypeError, ValueError):
            raise BSFError(f"k_targets must be a sequence of ints, got {k_targets!r}") from None
        rows = np.shape(pair.C)[-2]
        if not k_targets or not all(1 <= v <= rows for v in k_targets):
            raise BSFError(f"k_targets must be non-empty ints in [1, C rows = {rows}], got "
                           f"{k_targets}")
    n_m = np.shape(pair.source.evecs)[-2]
    f_shape = tuple(np.shape(f))
    want = 3 if batched else 2
    if len(f_shape) != want or f_shape[-1] != n_m or (batched and f_shape[0] !=
                                                     np.shape(pair.source.evals)[0]):
        raise BSFError(f"f must have shape {'(P, m, n_M)' if batched else '(m, n_M)'} with "
                       f"n_M = {n_m}, got {f_shape}")
    if not isinstance(f, jax.core.Tracer) and not np.all(np.isfinite(np.asarray(f))):
        raise BSFError("f contains NaN or inf")
    dtype = jax.dtypes.canonicalize_dtype(jnp.float64)
    F = jnp.asarray(f, dtype)
    pair = jax.tree.map(lambda x: jnp.asarray(x, dtype) if np.issubdtype(np.asarray(x).dtype,
                                                                          np.floating)
                        else jnp.asarray(x), pair)
    kt = None if not transfer else (() if k_targets is None else k_targets)
    approx, trans = _run(pair, F, method=method, k=k, params=params, k_targets=kt,
                         batched=batched)
    return BaselineResult(approx, trans)
