"""The experiments' one adapter to the transfer engine.

Every call of the experiments into the engine (the methods of the paper's Sec. 6 and the BSF
coders: :func:`bsfjax._baselines.run_baseline`, its :class:`~bsfjax._baselines.Params` and
:class:`~bsfjax._baselines.PairInput`) and into the array-level BSF functions
(:func:`~bsfjax.encode`, :func:`~bsfjax.decode`, :func:`~bsfjax.build_frame`,
:func:`~bsfjax.transfer_frame`) goes through this module, and no other module of
:mod:`bsfjax.experiments` imports the engine.  Switching the engine changes this file only.

What the experiments see:

* method names: :data:`METHODS`, :data:`CODERS`, :data:`APPROX_METHODS`,
  :data:`TRANSFER_METHODS`, :data:`KN_METHODS`, :data:`PLAIN_METHODS`;
* settings: :func:`settings` (``settings(**overrides)``, the paper's defaults otherwise;
  overrides ``taus``, ``gamma``, ``sparsity``, ``eps_fraction``, ...) and
  :data:`PARAMETER_SETS` (Table 5's two sets);
* one pair (or a stack of pairs): :func:`pair_input`, :func:`stack`;
* running one method: :func:`run_method` → ``(approximation, transferred)``;
* Table 3's timed frames: :func:`frame_atoms` (the BSF), :func:`heat_frame` (the
  saturated kernels of the ``heat`` baseline) and their size :func:`n_atoms`;
* the array-level functions, re-exported: :func:`build_frame`, :func:`transfer_frame`,
  :func:`encode`, :func:`decode`.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .._baselines import CODERS, METHODS, BaselineResult, PairInput, Params, run_baseline
from .._baselines import _saturate
from .._coding import decode, encode
from .._frame import build_frame, transfer_frame

__all__ = ["METHODS", "CODERS", "APPROX_METHODS", "TRANSFER_METHODS", "KN_METHODS",
           "PLAIN_METHODS", "PARAMETER_SETS", "Settings", "settings", "pair_input", "stack",
           "run_method", "frame_atoms", "n_atoms", "heat_frame", "build_frame", "transfer_frame",
           "encode", "decode"]

#: The settings object of the engine (frames and coders).
Settings = Params
#: Methods with an approximation on the source (all but the point-map pull-back).
APPROX_METHODS = tuple(m for m in METHODS if m != "p2p")
#: Methods that transfer (all).
TRANSFER_METHODS = METHODS
#: fig7's methods: those whose transfer depends on k_N alone through C.
KN_METHODS = ("std",) + CODERS
#: Methods without BSF parameters (Table 5 runs them once).
PLAIN_METHODS = ("std", "std2", "p2p", "prod")


def settings(**overrides) -> Settings:
    """The engine's settings: the paper's (n_BSF aside: τ = (0.001, 0.005, 0.01) unit-area,
    γ = 0.75, S = 10, ε = ‖f‖/10, area-weighted coding) with ``overrides`` applied.

    Arguments:
        **overrides: settings to change, e.g. ``taus``, ``gamma``, ``sparsity``
            (OMP's S), ``eps_fraction`` (``omp_error``'s ε / ‖f‖).
    """
    return Params(**overrides)


#: Table 5's two BSF parameter sets.  "paper": the paper's defaults.  "wide": larger, fewer
#: overlapping atoms (τ doubled, γ = 0.6), which should suit the coarse 10×10 estimated maps.
PARAMETER_SETS = {
    "paper": {"n_bsf": 0.05, "params": settings()},
    "wide": {"n_bsf": 0.05, "params": settings(taus=(2e-3, 1e-2, 2e-2), gamma=0.6)},
}


def pair_input(source, target=None, C=None, C2=None, p2p=None, centers=None,
               distances=None) -> PairInput:
    """One source/target pair as the engine takes it.

    Arguments:
        source, target: the two spectra (``target`` ``None`` for approximation only).
        C: ``(k_N, k)`` functional map; C2: ``std2``'s ``(2k_N, 2k)`` map.
        p2p: point map (target vertex → source vertex) of the ``p2p`` method.
        centers: BSF centres on the source; distances: geodesic distances from them (``geod``).
    """
    return PairInput(source=source, target=target, C=C, C2=C2, p2p=p2p, centers=centers,
                     distances=distances)


def stack(items):
    """Stack equal-shaped pairs (leading pair axis) to run them under one ``vmap``."""
    return jax.tree.map(lambda *x: np.stack([np.asarray(v) for v in x]), *items)


def run_method(method: str, pair, F, *, k: int, settings: Settings, transfer: bool = True,
               k_targets=None) -> BaselineResult:
    """Approximate ``F`` on the source with ``method`` and transfer it to the target.

    Arguments:
        method: one of :data:`METHODS`.
        pair: :func:`pair_input` (or a :func:`stack` of them).
        F: ``(m, n_M)`` functions (``(P, m, n_M)`` for a stack).
        k: source basis size.
        settings: :func:`settings`.
        transfer: also transfer (else ``transferred`` is ``None``).
        k_targets: target sizes: one transfer per ``C[:k_N]`` (``transferred`` a tuple).

    Returns:
        ``(approximation, transferred)`` (``approximation`` is ``None`` for ``p2p``).
    """
    return run_baseline(method, pair, F, k=k, params=settings, transfer=transfer,
                        k_targets=k_targets)


def frame_atoms(spectrum, centers, settings: Settings):
    """The BSF atoms (Algorithm 1) at the settings' scales and threshold (Table 3's ``ours``)."""
    return build_frame(spectrum, centers, settings.taus, settings.gamma).atoms


def n_atoms(settings: Settings, n_centers: int) -> int:
    """Number of BSF atoms for ``n_centers`` centres (one per centre and scale)."""
    return len(settings.taus) * n_centers


def heat_frame(spectrum, centers, settings: Settings):
    """The ``heat`` baseline's frame: the BSF's band-limited kernels, saturated (Table 3)."""
    fr = build_frame(spectrum, centers, settings.taus, settings.gamma)
    return _saturate(jnp.asarray(spectrum.evecs, fr.coeffs.dtype) @ fr.coeffs, settings.gamma)
