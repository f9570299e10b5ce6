r"""Transfer methods by name: the registry of the Binary Sparse Frame and the paper's competitors
(Melzi 2019, Sec. 6).

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

This module owns the registry (`METHODS`, `CODER_NAMES`, `method_name`, `as_method`); the
classes live in `bsfjax._transfer._bsf` (`Pair`, `AbstractMethod`, `BSF`),
`bsfjax._transfer._baselines` (the competitors) and `bsfjax._transfer._refined`
(``"refined"``).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._coding import CODERS, as_coder
from .._util import BSFError
from ._baselines import GeodesicBalls, ProductBasis, PullBack, SaturatedHeat, SpectralProjection
from ._bsf import AbstractMethod, BSF, Pair
from ._refined import RefinedPullBack

__all__ = ["METHODS", "CODER_NAMES", "as_method", "method_name", "AbstractMethod", "Pair"]


def _normalize_taus(taus):
    return taus if isinstance(taus, str) else tuple(float(t) for t in np.atleast_1d(taus))


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
