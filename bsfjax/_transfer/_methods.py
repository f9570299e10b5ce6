r"""Transfer methods: the Binary Sparse Frame and the paper's competitors (Melzi 2019, Sec. 6).

A method maps functions ``F`` ``(m, n_M)`` on a source shape ``M`` to an approximation on ``M``
and, through a functional map, a transfer to the target ``N``.  Each is a small
`equinox.Module` whose options are its fields (defaults stated once, here); strings are
shorthands for the registry [`METHODS`][bsfjax.METHODS] (``"omp"`` is ``BSF(coder=OMP())``).  Notation:
Φ ``(n_M, k)`` and Ψ ``(n_N, k_N)`` the eigenbases, ``A`` the vertex areas, ``C`` ``(k_N, k)``.

=============  ====================================================================================
``BSF``        ours (``"omp"``, ``"omp_error"``, ``"lstsq"``, ``"lasso"``): the Binary Sparse
               Frame ([`bsfjax.build_frame`][bsfjax.build_frame]), ``α = encode(B_M, f)``, ``f̃ = B_M α``,
               transfer ``B_N α`` with ``B_N = transfer_frame(B_M, C, N)`` (paper Eq. 11–13).
``"std"``      spectral projection (Eq. 5): ``a = Φᵀ A f``, ``f̃ = Φ a``, transfer ``Ψ C a``.
``"std2"``     the same with ``2k`` eigenfunctions and its own ``(2k_N, 2k)`` map ``C2``.
``"p2p"``      pull-back through a point map ``T`` (target vertex → source vertex): ``f ∘ T``;
               no approximation (it would be ``f`` itself).
``"prod"``     Nogneng et al. 2018: ``f ≈ Σ_{i≤j} c_ij φ_i φ_j`` (area-weighted truncated least
               squares), transferred by the extended map: with ``S`` the symmetric matrix of the
               ``c_ij``, ``f_N(x) = ψ(x)ᵀ (C S Cᵀ) ψ(x)``.
``"geod"``     geodesic-ball indicators around the BSF centres, one radius per BSF scale
               (``r_s = √(ā_s / π)``, ``ā_s`` the mean area of that scale's BSF atoms); their
               coefficients ``Φᵀ A χ`` go through ``C`` and are re-binarized at ``level · max``.
``"heat"``     saturated band-limited heat kernels ``min(1, |g| / (γ max|g|))`` (1 exactly on
               the BSF atom), transferred like the BSF.
=============  ====================================================================================

Adding a method: subclass [`AbstractMethod`][bsfjax.AbstractMethod], implement ``prepare`` (and ``check`` for
inputs it needs), add a registry line.  [`bsfjax.transfer`][bsfjax.transfer] runs any of them.
"""

from __future__ import annotations

import abc
import dataclasses
from collections.abc import Callable
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float, Int

from .._coding import AbstractCoder
from .._coding import CODERS, as_coder, decode, encode
from .._util import BSFError
from .._frame import build_frame, transfer_frame
from .._frame import ADAPTIVE_N_SCALES, prune_frame, unique_atoms
from .._frame import SparseFrame
from .._coding import LeastSquares
from .._coding import OMP
from .._spectral import Spectrum
from .._maps import check_samples, chunk_for
from .._maps import check_options as check_refine_options, refine_core, start_point_map
from .._maps import sizes_for as refine_sizes_for
from .._util import check_finite

__all__ = ["AbstractMethod", "BSF", "SpectralProjection", "PullBack", "ProductBasis",
           "GeodesicBalls", "SaturatedHeat", "RefinedPullBack", "METHODS", "as_method", "Pair",
           "PAPER_TAUS", "PAPER_GAMMA", "product_basis", "geodesic_ball_radii"]

#: The paper's diffusion scales (unit-area convention) and threshold.
PAPER_TAUS = (1e-3, 5e-3, 1e-2)
PAPER_GAMMA = 0.75
#: How the BSF reaches the target ([`BSF.frame_transfer`][bsfjax.BSF.frame_transfer]).
FRAME_TRANSFERS = ("binary", "p2p")


class Pair(eqx.Module):
    """Everything a method may need about one source/target pair (or a stack of pairs).

    A stack of ``P`` pairs has a leading ``P`` axis on every array (equal shapes).

    **Arguments:**

    - ``source``: spectrum of ``M`` (``≥ k`` eigenpairs; ``≥ 2k`` for ``"std2"``).
    - ``target``: spectrum of ``N``; ``None`` for approximation only.
    - ``C``: ``(k_N, k)`` functional map ``M → N`` on coefficients.
    - ``C2``: ``(2k_N, 2k)`` map of ``"std2"``.
    - ``p2p``: ``(n_N,)`` int point map, target vertex → source vertex.
    - ``centers``: ``(n_c,)`` int BSF centres on ``M`` (``BSF``, ``"geod"``, ``"heat"``).
    - ``distances``: ``(n_c, n_M)`` geodesic distances from the centres (``"geod"``).
    - ``samples``: ``(source, target)`` [`Subsample`][bsfjax.Subsample] s (``"refined"``: its
      continuation's early steps run on them; [`bsfjax.estimate_map`][bsfjax.estimate_map] returns the ones its
      ZoomOut used).
    """

    source: Spectrum
    target: Spectrum | None = None
    C: Float[ArrayLike, "*pairs k_N k"] | None = None
    C2: Float[ArrayLike, "*pairs k2_N k2"] | None = None
    p2p: Int[ArrayLike, "*pairs n_N"] | None = None
    centers: Int[ArrayLike, "*pairs n_c"] | None = None
    distances: Float[ArrayLike, "*pairs n_c n_M"] | None = None
    samples: tuple | None = None


def _shape(x):
    return None if x is None else tuple(np.shape(x))


def _check_p2p(pair: Pair, b: int, what: str) -> None:
    n_n = np.shape(pair.target.evecs)[b]
    n_m = np.shape(pair.source.evecs)[b]
    if pair.p2p is None or _shape(pair.p2p)[b:] != (n_n,):
        raise BSFError(f"{what} needs pair.p2p of shape ({n_n},) (target → source vertex), got "
                       f"{_shape(pair.p2p)}")
    p = np.asarray(pair.p2p)
    if not np.issubdtype(p.dtype, np.integer) or p.min() < 0 or p.max() >= n_m:
        raise BSFError(f"pair.p2p must hold source vertex indices in [0, {n_m})")


# A method's ``prepare`` codes the functions on the source once and returns
# ``(approximation, carry)`` where ``carry(C)`` transfers them through a map ``C`` ``(k_N, k)``,
# so several target sizes (fig. 7's growing k_N) reuse one code.  ``codes`` are the BSF codes
# (``None`` for methods without a frame).
Prepared = tuple  # (approximation | None, carry: Callable[[jax.Array], jax.Array], codes | None)


class AbstractMethod(eqx.Module):
    """A transfer method (see the module docstring).  Subclasses set `name`."""

    name: ClassVar[str] = ""
    #: The method has no approximation on the source, only a transfer.
    transfer_only: ClassVar[bool] = False
    #: ``C`` is not what carries the functions (``"std2"`` has its own, ``"p2p"`` none).
    own_map: ClassVar[bool] = False

    def source_k(self, k: int) -> int:
        """Source eigenpairs used for basis size ``k``."""
        return k

    def frame_entries(self, pair: Pair) -> int:
        """Entries ``n · q`` of the largest dense frame this method would build (0: none);
        the engine runs a method whose frame exceeds the dense budget eagerly, on
        per-vertex-list frames ([`SparseFrame`][bsfjax.SparseFrame])."""
        return 0

    def check(self, pair: Pair, k: int, transfer: bool, batch: int) -> None:
        """Raise [`BSFError`][bsfjax.BSFError] for missing or ill-shaped inputs (before tracing)."""

    @abc.abstractmethod
    def prepare(self, pair: Pair, F, k: int) -> Prepared:
        """``(approximation, carry, codes)`` of functions ``F`` ``(m, n_M)`` with basis size
        ``k`` (traceable; runs inside the engine's jit and vmap)."""

    def with_options(self, **options) -> "AbstractMethod":
        """A copy with fields replaced (unknown names are an error)."""
        fields = {f.name for f in dataclasses.fields(self)}
        bad = sorted(set(options) - fields)
        if bad:
            raise BSFError(f"method {self.name!r} has no option {', '.join(bad)}; its options: "
                           f"{', '.join(sorted(fields)) or 'none'}")
        return dataclasses.replace(self, **options)


def _evecs(spec: Spectrum, k: int):
    return jnp.asarray(spec.evecs)[:, :k]


def _check_centers(method: str, pair: Pair, batch: int) -> None:
    if pair.centers is None:
        raise BSFError(f"method {method!r} needs pair.centers (the BSF centres)")
    c = pair.centers
    if isinstance(c, jax.core.Tracer):
        return
    c = np.asarray(c)
    n_m = np.shape(pair.source.evecs)[-2]
    if c.ndim != 1 + batch or c.shape[-1] == 0 or not np.issubdtype(c.dtype, np.integer):
        raise BSFError(f"centers must be a non-empty integer array of shape (n_centers,) per "
                       f"pair, got {c.dtype} {c.shape}")
    if c.min() < 0 or c.max() >= n_m:
        raise BSFError(f"centers must index source vertices in [0, {n_m}), got "
                       f"[{c.min()}, {c.max()}]")


class _FrameSettings(AbstractMethod):
    """Frame options shared by the methods built on the BSF's centres and scales."""

    taus: tuple | str = eqx.field(static=True, default=PAPER_TAUS, kw_only=True)
    gamma: float = eqx.field(static=True, default=PAPER_GAMMA, kw_only=True)
    tau_convention: str = eqx.field(static=True, default="unit_area", kw_only=True)

    def __check_init__(self):
        if isinstance(self.taus, str):
            if self.taus != "adaptive":
                raise BSFError(f"taus must be positive numbers or 'adaptive', got {self.taus!r}")
        elif not self.taus or not all(np.isfinite(t) and t > 0 for t in self.taus):
            raise BSFError(f"taus must be positive, got {self.taus!r}")
        if not 0 < self.gamma < 1:
            raise BSFError(f"gamma must be in (0, 1), got {self.gamma!r}")

    def frame(self, pair: Pair, k: int):
        return build_frame(pair.source.truncate(k), pair.centers, self.taus, self.gamma,
                           tau_convention=self.tau_convention)

    def n_scales(self) -> int:
        return ADAPTIVE_N_SCALES if isinstance(self.taus, str) else len(self.taus)


def _normalize_taus(taus):
    return taus if isinstance(taus, str) else tuple(float(t) for t in np.atleast_1d(taus))


class BSF(_FrameSettings):
    """Ours: the Binary Sparse Frame coded with ``coder`` (paper Algorithm 1 and Eq. 11–13).

    **Arguments:**

    - ``coder``: an [`OMP`][bsfjax.OMP] (default, ``S = 10``), ``ErrorOMP``, ``LeastSquares``
      or ``Lasso``; area-weighted by default (the codes minimise ``‖f − Bα‖_A``).
    - ``taus``, ``gamma``, ``tau_convention``: the frame's scales (``"adaptive"`` for
      [`bsfjax.adaptive_taus`][bsfjax.adaptive_taus]), threshold and τ convention ([`bsfjax.build_frame`][bsfjax.build_frame]).
    - ``prune``: code in the distinct non-empty atoms only ([`bsfjax.unique_atoms`][bsfjax.unique_atoms]).
    - ``frame_transfer``: ``"binary"`` (re-binarize ``Φ_N C a``, paper Eq. 11–12) or ``"p2p"``
      (pull the atoms back through ``pair.p2p``).
    """

    coder: AbstractCoder = OMP()
    prune: bool = eqx.field(static=True, default=False, kw_only=True)
    frame_transfer: str = eqx.field(static=True, default="binary", kw_only=True)

    name: ClassVar[str] = "bsf"

    def __check_init__(self):
        if not isinstance(self.coder, AbstractCoder):
            raise BSFError(f"coder must be a coder object (bsfjax.OMP(), ...), got {self.coder!r}")
        if not isinstance(self.prune, bool):
            raise BSFError(f"prune must be a bool, got {self.prune!r}")
        if self.frame_transfer not in FRAME_TRANSFERS:
            raise BSFError(f"frame_transfer must be one of {FRAME_TRANSFERS}, got "
                           f"{self.frame_transfer!r}")

    def frame_entries(self, pair):
        q = self.n_scales() * int(np.shape(pair.centers)[-1])
        n = max(np.shape(pair.source.evecs)[-2],
                0 if pair.target is None else np.shape(pair.target.evecs)[-2])
        return n * q

    def check(self, pair, k, transfer, batch):
        _check_centers("bsf", pair, batch)
        if transfer and self.frame_transfer == "p2p":
            _check_p2p(pair, batch, "frame_transfer='p2p'")

    def prepare(self, pair, F, k):
        frame = self.frame(pair, k)
        p2p = pair.p2p if self.frame_transfer == "p2p" else None
        if self.prune and isinstance(frame, SparseFrame):
            # eager (beyond the dense budget): drop the columns, code in the rest, and give
            # the codes back in the built frame's columns
            pruned = prune_frame(frame)
            a = encode(pruned, F, self.coder)
            alpha = jnp.zeros(F.shape[:-1] + (frame.n_atoms,), a.dtype).at[
                ..., np.asarray(pruned.columns)].set(a)
            return (decode(pruned, a),
                    lambda C: decode(transfer_frame(pruned, C, pair.target, p2p=p2p), a), alpha)
        if self.prune:  # under jit: masked duplicates / empties get α = 0
            keep = unique_atoms(frame)[0].astype(frame.atoms.dtype)
            frame = eqx.tree_at(lambda fr: fr.atoms, frame, frame.atoms * keep)
        alpha = encode(frame, F, self.coder)
        return (decode(frame, alpha),
                lambda C: decode(transfer_frame(frame, C, pair.target, p2p=p2p), alpha), alpha)


class SpectralProjection(AbstractMethod):
    """``"std"`` (``factor=1``) and ``"std2"`` (``factor=2``: ``2k`` eigenfunctions and the
    pair's own map ``C2``): ``a = Φᵀ A f``, ``f̃ = Φ a``, transfer ``Ψ C a``."""

    factor: int = eqx.field(static=True, default=1)

    name: ClassVar[str] = "std"

    def __check_init__(self):
        if self.factor not in (1, 2):
            raise BSFError(f"factor must be 1 or 2, got {self.factor!r}")

    @property
    def own_map(self):  # type: ignore[override]
        return self.factor == 2

    def source_k(self, k):
        return self.factor * k

    def check(self, pair, k, transfer, batch):
        if transfer and self.factor == 2:
            _check_map(pair, "C2", 2 * k, batch, "std2")

    def prepare(self, pair, F, k):
        phi = _evecs(pair.source, self.factor * k)
        a = (F * pair.source.mass) @ phi  # (m, k): Φᵀ A f

        def carry(C):
            C = pair.C2 if self.factor == 2 else C
            return (a @ C.T) @ _evecs(pair.target, C.shape[0]).T

        return a @ phi.T, carry, None


class PullBack(AbstractMethod):
    """``"p2p"``: ``f ∘ T`` through the point map ``pair.p2p`` (target → source vertex)."""

    name: ClassVar[str] = "p2p"
    transfer_only: ClassVar[bool] = True
    own_map: ClassVar[bool] = True

    def check(self, pair, k, transfer, batch):
        if transfer:
            _check_p2p(pair, batch, "method 'p2p'")

    def prepare(self, pair, F, k):
        return None, lambda C: F[:, pair.p2p], None


class RefinedPullBack(AbstractMethod):
    r"""``"refined"`` (default of [`bsfjax.transfer_labels`][bsfjax.transfer_labels] and ``bsfjax transfer``): the
    pull-back through a refined map.

    The input point map ``pair.p2p`` (or, without one, the point map of ``pair.C``) is refined
    by the descriptor-guided ZoomOut continuation of `bsfjax._refine` from ``k_start`` to
    ``k_max`` eigenpairs (default: all that both spectra hold) and the functions are pulled
    back through the last ``n_vote`` point maps ``T_t``: ``f̃_N = (1/T) Σ_t f ∘ T_t`` (for
    indicators the arg-max is the majority vote of the maps, ties to the last).  With
    ``pair.samples`` the steps before those ``n_vote`` run on the samples (their searches cost
    ``s_N × s_M``); only the kept maps are computed on every vertex.  It uses the whole
    spectra it is given, not ``k``: give them ``k_max`` eigenpairs (the CLI computes 100).
    A map better than the continuation's fixed point (a registration, a ground truth) is
    better used as is: ``"p2p"``.

    Measured (docs/results.md, SMPL parts on 9 FAUST / FAUST_5k pairs, 2000 samples per
    shape): the last map alone on samples is as accurate as the vote of the last three maps on
    every vertex (94.95 against 94.81 % with the CLI's map, 93.74 against 93.54 % with a crude
    one) for one search over every vertex instead of three.

    **Arguments:** ``k_start``, ``k_max``, ``step``, ``n_vote``, ``descriptor_weight``,
    ``descriptor_dims``, ``n_energies`` as in [`bsfjax.refine_point_maps`][bsfjax.refine_point_maps] (its
    ``n_keep`` is ``n_vote``).  With ``n_vote = 1`` the scores are 0/1, so the label
    transfer's ``confidence`` is 1 and its regime never ``"unreliable"``.
    """

    k_start: int = eqx.field(static=True, default=60, kw_only=True)
    k_max: int | None = eqx.field(static=True, default=None, kw_only=True)
    step: int = eqx.field(static=True, default=20, kw_only=True)
    n_vote: int = eqx.field(static=True, default=1, kw_only=True)
    descriptor_weight: float = eqx.field(static=True, default=0.5, kw_only=True)
    descriptor_dims: int = eqx.field(static=True, default=8, kw_only=True)
    n_energies: int = eqx.field(static=True, default=100, kw_only=True)

    name: ClassVar[str] = "refined"
    transfer_only: ClassVar[bool] = True
    own_map: ClassVar[bool] = True
    #: runs on the whole spectra of the pair (the mesh-level calls do not truncate them to k)
    full_spectra: ClassVar[bool] = True

    def __check_init__(self):
        check_refine_options(k_start=self.k_start, k_max=self.k_max, step=self.step,
                             n_keep=self.n_vote, descriptor_weight=self.descriptor_weight,
                             descriptor_dims=self.descriptor_dims, n_energies=self.n_energies)

    def sizes(self, k_source: int, k_target: int) -> tuple[int, ...]:
        return refine_sizes_for(k_source, k_target, self.k_start, self.k_max, self.step)

    def check(self, pair, k, transfer, batch):
        if not transfer:
            return
        if pair.p2p is not None:
            _check_p2p(pair, batch, "method 'refined'")
        elif pair.C is None:
            raise BSFError("method 'refined' needs pair.p2p (a point map to refine) or pair.C")
        else:
            kn, km = _shape(pair.C)[batch:]
            if km > np.shape(pair.source.evecs)[-1] or kn > np.shape(pair.target.evecs)[-1]:
                raise BSFError(f"pair.C {_shape(pair.C)} is larger than the spectra")
            check_finite(pair.C, "pair.C")
        self.sizes(np.shape(pair.source.evecs)[-1], np.shape(pair.target.evecs)[-1])
        if pair.samples is not None:
            n_m, n_n = np.shape(pair.source.evecs)[-2], np.shape(pair.target.evecs)[-2]
            if batch:  # a stack: check one pair's samples (equal shapes throughout)
                check_samples(jax.tree.map(lambda x: np.asarray(x)[0], pair.samples), n_m, n_n)
            else:
                check_samples(pair.samples, n_m, n_n)

    def prepare(self, pair, F, k):
        n_m, n_n = np.shape(pair.source.evecs)[-2], np.shape(pair.target.evecs)[-2]
        chunk = chunk_for(n_m, n_n, None)
        sizes = self.sizes(np.shape(pair.source.evecs)[-1], np.shape(pair.target.evecs)[-1])
        p0 = start_point_map(pair.p2p, pair.C, pair.source, pair.target, chunk)
        maps = refine_core(p0, pair.source, pair.target, sizes=sizes,
                           n_keep=min(self.n_vote, len(sizes)),
                           weight=float(self.descriptor_weight), dims=self.descriptor_dims,
                           n_energies=self.n_energies, chunk=chunk, samples=pair.samples)
        # later (more refined) maps weigh a little more: a three-way tie goes to the last map
        w = 1.0 + 1e-3 * jnp.arange(maps.shape[0], dtype=F.dtype)
        w = w / jnp.sum(w)
        return None, lambda C: jnp.einsum("t,mtn->mn", w, F[:, maps]), None


def product_basis(evecs: jax.Array) -> jax.Array:
    """``(n, k(k+1)/2)`` products ``φ_i φ_j``, ``i ≤ j`` in ``numpy.triu_indices`` order."""
    k = evecs.shape[-1]
    iu, ju = np.triu_indices(k)
    return evecs[..., iu] * evecs[..., ju]


class ProductBasis(AbstractMethod):
    """``"prod"`` (Nogneng et al. 2018), fitted by area-weighted truncated least squares.

    ``rcond``: relative singular-value cut-off.  The product basis is badly conditioned: the
    minimum-norm fit at float32 resolution (``rcond ≈ 1e-3``) has huge cancelling coefficients
    whose images under a truncated ``C`` no longer cancel (transfer error 0.9 at k = 10 and
    1.8 at k = 30 on FAUST 000→001 with the ground-truth map).  ``3e-2`` was the best of
    {1e-3, 1e-2, 3e-2, 1e-1} on that pair (0.39 / 0.28), i.e. tuned in prod's favour.
    """

    rcond: float = eqx.field(static=True, default=3e-2)

    name: ClassVar[str] = "prod"

    def __check_init__(self):
        if not 0 <= self.rcond < 1:
            raise BSFError(f"rcond must be in [0, 1), got {self.rcond!r}")

    def prepare(self, pair, F, k):
        phi = _evecs(pair.source, k)
        P = product_basis(phi)  # (n, K)
        c = encode(P, F, LeastSquares(rcond=self.rcond, weights=pair.source.mass))
        iu, ju = np.triu_indices(k)
        half = 0.5 * c
        S = jnp.zeros((F.shape[0], k, k), F.dtype).at[:, iu, ju].add(half).at[:, ju, iu].add(half)

        def carry(C):
            T = jnp.einsum("ia,mab,jb->mij", C, S, C)  # C S Cᵀ
            psi = _evecs(pair.target, C.shape[0])
            return jnp.einsum("ni,mij,nj->mn", psi, T, psi)

        return c @ P.T, carry, None


def _with_mass(coder: AbstractCoder, mass) -> AbstractCoder:
    """``coder`` for a plain dictionary (no frame, so no areas): ``"area"`` → the source's."""
    if isinstance(coder.weights, str) and coder.weights == "area":
        return dataclasses.replace(coder, weights=mass)
    return coder


def geodesic_ball_radii(atoms: jax.Array, mass: jax.Array, n_scales: int) -> jax.Array:
    """``(n_scales,)`` radii ``√(ā_s / π)`` from the mean area ``ā_s`` of each scale's atoms
    (``atoms`` ``(n, n_scales · n_c)``, scale-major as [`bsfjax.Frame`][bsfjax.Frame])."""
    areas = (mass @ atoms).reshape(n_scales, -1)
    return jnp.sqrt(jnp.mean(areas, axis=1) / jnp.pi)


class GeodesicBalls(_FrameSettings):
    """``"geod"``: geodesic balls around the BSF centres at the BSF scales' mean radii, coded
    with ``coder``; transferred by re-binarizing ``Ψ C Φᵀ A χ`` at ``level · max``."""

    coder: AbstractCoder = OMP()
    level: float = eqx.field(static=True, default=0.5, kw_only=True)

    name: ClassVar[str] = "geod"

    def __check_init__(self):
        if not 0 < self.level < 1:
            raise BSFError(f"level must be in (0, 1), got {self.level!r}")

    def check(self, pair, k, transfer, batch):
        _check_centers("geod", pair, batch)
        if pair.distances is None:
            raise BSFError("method 'geod' needs pair.distances: (n_c, n_M) geodesic distances "
                           "from the centres (bsfjax.geodesic_distances(mesh, centers))")
        want = (np.shape(pair.centers)[batch], np.shape(pair.source.evecs)[batch])
        if _shape(pair.distances)[batch:] != want:
            raise BSFError(f"pair.distances must have shape {want}, got {_shape(pair.distances)}")

    def prepare(self, pair, F, k):
        frame = self.frame(pair, k)
        n_s = frame.n_atoms // int(np.shape(pair.centers)[-1])
        radii = geodesic_ball_radii(frame.atoms, pair.source.mass, n_s)
        D = jnp.asarray(pair.distances, F.dtype)  # (n_c, n)
        atoms = (D[None, :, :] <= radii[:, None, None]).reshape(-1, D.shape[1]).T.astype(F.dtype)
        alpha = encode(atoms, F, _with_mass(self.coder, pair.source.mass))
        coeffs = _evecs(pair.source, k).T @ (atoms * pair.source.mass[:, None])  # Φᵀ A χ

        def carry(C):
            g = _evecs(pair.target, C.shape[0]) @ (C @ coeffs)
            m = jnp.max(g, axis=0)
            return decode(((g >= self.level * m) & (m > 0)).astype(F.dtype), alpha)

        return decode(atoms, alpha), carry, None


def saturate(g, gamma):
    m = jnp.max(jnp.abs(g), axis=0)
    pos = m > 0
    return jnp.where(pos, jnp.minimum(1.0, jnp.abs(g) / (gamma * jnp.where(pos, m, 1.0))), 0.0)


class SaturatedHeat(_FrameSettings):
    """``"heat"``: the BSF's band-limited kernels saturated, ``min(1, |g| / (γ max|g|))``."""

    coder: AbstractCoder = OMP()

    name: ClassVar[str] = "heat"

    def check(self, pair, k, transfer, batch):
        _check_centers("heat", pair, batch)

    def prepare(self, pair, F, k):
        frame = self.frame(pair, k)
        atoms = saturate(_evecs(pair.source, k) @ frame.coeffs, self.gamma)
        alpha = encode(atoms, F, _with_mass(self.coder, pair.source.mass))

        def carry(C):
            g = _evecs(pair.target, C.shape[0]) @ (C @ frame.coeffs)
            return decode(saturate(g, self.gamma), alpha)

        return decode(atoms, alpha), carry, None


def _check_map(pair: Pair, name: str, cols: int, batch: int, method: str) -> None:
    C = getattr(pair, name)
    if C is None:
        raise BSFError(f"transfer with {method!r} needs pair.{name} ({cols} columns)")
    kn, km = _shape(C)[batch:]
    if km != cols:
        raise BSFError(f"pair.{name} must have k_M = {cols} columns, got shape {_shape(C)}")
    k_avail = np.shape(pair.target.evecs)[-1]
    if kn > k_avail:
        raise BSFError(f"pair.{name} has {kn} rows but the target spectrum only {k_avail} "
                       "eigenpairs")
    if not np.all(np.isfinite(np.asarray(C))):
        raise BSFError(f"pair.{name} contains NaN or inf")


#: Method names and the object each stands for.
METHODS: dict[str, AbstractMethod] = {
    **{name: BSF(coder=cls()) for name, cls in CODERS.items()},
    "std": SpectralProjection(),
    "std2": SpectralProjection(factor=2),
    "p2p": PullBack(),
    "refined": RefinedPullBack(),
    "prod": ProductBasis(),
    "geod": GeodesicBalls(),
    "heat": SaturatedHeat(),
}
#: The BSF coders' names (the methods that are ours).
CODER_NAMES = tuple(CODERS)


def method_name(method: AbstractMethod) -> str:
    """The registry name of ``method`` (``"omp"`` for ``BSF(coder=OMP(...))``)."""
    if isinstance(method, BSF):
        return {v: k for k, v in CODERS.items()}[type(method.coder)]
    if isinstance(method, SpectralProjection):
        return "std2" if method.factor == 2 else "std"
    return method.name


def as_method(method, **options) -> AbstractMethod:
    """A method object from a name of [`METHODS`][bsfjax.METHODS] (or a method object) and options.

    Options of a name are the fields of its object; for the BSF names also the fields of its
    coder (``as_method("omp", sparsity=20, taus="adaptive")`` is
    ``BSF(coder=OMP(sparsity=20), taus="adaptive")``).  Options with an object are an error.
    """
    if isinstance(method, AbstractMethod):
        if options:
            raise BSFError("options go with a method name; set the fields of a method object "
                           "directly")
        return method
    if not isinstance(method, str) or method not in METHODS:
        raise BSFError(f"method must be one of {tuple(METHODS)} or a method object, got "
                       f"{method!r}")
    base = METHODS[method]
    if "taus" in options:
        options["taus"] = _normalize_taus(options["taus"])
    if isinstance(base, BSF) and options:
        own = {f.name for f in dataclasses.fields(base)}
        coder_opts = {k: v for k, v in options.items() if k not in own}
        options = {k: v for k, v in options.items() if k in own}
        if coder_opts:
            options["coder"] = as_coder(method, **coder_opts)
    return base.with_options(**options)
