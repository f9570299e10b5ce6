"""The experiments' one adapter to the transfer engine.

Every call of the experiments into the engine ([`bsfjax.transfer`][bsfjax.transfer] and its method objects,
[`bsfjax.METHODS`][bsfjax.METHODS], [`bsfjax.Pair`][bsfjax.Pair]) and into the array-level BSF functions
([`encode`][bsfjax.encode], [`decode`][bsfjax.decode], [`build_frame`][bsfjax.build_frame],
[`transfer_frame`][bsfjax.transfer_frame]) goes through this module, and no other module of
[`bsfjax.experiments`][bsfjax.experiments] imports the engine.

What the experiments see:

* method names: [`METHODS`][bsfjax.METHODS], `CODERS`, `APPROX_METHODS`,
  `TRANSFER_METHODS`, `KN_METHODS`, `PLAIN_METHODS`;
* settings: `settings` (``settings(**overrides)``: the paper's defaults, i.e. each
  method's own defaults, with ``taus``, ``gamma``, ``sparsity``, ``eps_fraction``, … applied
  to every method that has that option, on the method or on its coder) and
  `PARAMETER_SETS` (Table 5's two sets);
* one pair (or a stack of pairs): `pair_input`, `stack`;
* running one method: `run_method` → ``(approximation, transferred, codes)``;
* Table 3's timed frames: `frame_atoms` (the BSF), `heat_frame` (the
  saturated kernels of the ``heat`` baseline) and their size `n_atoms`;
* the array-level functions, re-exported: [`build_frame`][bsfjax.build_frame], [`transfer_frame`][bsfjax.transfer_frame],
  [`encode`][bsfjax.encode], [`decode`][bsfjax.decode].
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from .._coding import decode, encode
from .._frame import build_frame, transfer_frame
from .._transfer import BSF, CODER_NAMES, METHODS as _METHODS, PAPER_GAMMA, PAPER_TAUS, AbstractMethod, Pair, saturate
from .._transfer import TransferResult, stack_pairs
from .._transfer import transfer as _run_transfer

#: The paper's methods (ours and its competitors): the registry without the methods beyond the
#: paper ("refined", whose table is ``reproduce segmentation``).
METHODS = tuple(m for m in _METHODS if m != "refined")
CODERS = CODER_NAMES

__all__ = ["METHODS", "CODERS", "APPROX_METHODS", "TRANSFER_METHODS", "KN_METHODS",
           "PLAIN_METHODS", "PARAMETER_SETS", "Settings", "settings", "pair_input", "stack",
           "run_method", "frame_atoms", "n_atoms", "heat_frame", "build_frame", "transfer_frame",
           "encode", "decode"]

#: Methods with an approximation on the source (all but the point-map pull-back).
APPROX_METHODS = tuple(m for m in METHODS if m != "p2p")
#: Methods that transfer (all).
TRANSFER_METHODS = METHODS
#: fig7's methods: those whose transfer depends on k_N alone through C.
KN_METHODS = ("std",) + CODERS
#: Methods without BSF parameters (Table 5 runs them once).
PLAIN_METHODS = ("std", "std2", "p2p", "prod")


@dataclasses.dataclass(frozen=True)
class Settings:
    """Overrides of the methods' default options (an empty one: the paper's settings)."""

    overrides: tuple = ()

    @property
    def taus(self):
        return dict(self.overrides).get("taus", PAPER_TAUS)

    @property
    def gamma(self):
        return dict(self.overrides).get("gamma", PAPER_GAMMA)

    def method(self, name: str) -> AbstractMethod:
        """The method object of ``name`` with every override it (or its coder) has."""
        m = _METHODS[name]
        own = {f.name for f in dataclasses.fields(m)}
        coder = getattr(m, "coder", None)
        cfields = {f.name for f in dataclasses.fields(coder)} if coder is not None else set()
        opts = {k: v for k, v in self.overrides if k in own}
        copts = {k: v for k, v in self.overrides if k in cfields and k not in own}
        if copts:
            opts["coder"] = dataclasses.replace(coder, **copts)
        return m.with_options(**opts) if opts else m


def settings(**overrides) -> Settings:
    """The engine's settings: the paper's (τ = (0.001, 0.005, 0.01) unit-area, γ = 0.75,
    S = 10, ε = ‖f‖/10, area-weighted coding) with ``overrides`` applied.

    **Arguments:**

    - ``**overrides``: options to change, e.g. ``taus``, ``gamma``, ``sparsity`` (OMP's S),
      ``eps_fraction`` (``omp_error``'s ε / ‖f‖); each goes to every method that has it.
    """
    if "taus" in overrides and not isinstance(overrides["taus"], str):
        overrides["taus"] = tuple(float(t) for t in overrides["taus"])
    s = Settings(tuple(sorted(overrides.items())))
    for name in METHODS:  # every override is checked now, not when a method first runs
        s.method(name)
    return s


#: Table 5's two BSF parameter sets.  "paper": the paper's defaults.  "wide": larger, fewer
#: overlapping atoms (τ doubled, γ = 0.6), which should suit the coarse 10×10 estimated maps.
PARAMETER_SETS = {
    "paper": {"n_bsf": 0.05, "params": settings()},
    "wide": {"n_bsf": 0.05, "params": settings(taus=(2e-3, 1e-2, 2e-2), gamma=0.6)},
}


def pair_input(source, target=None, C=None, C2=None, p2p=None, centers=None,
               distances=None) -> Pair:
    """One source/target pair as the engine takes it.

    **Arguments:**

    - `source`, `target`: the two spectra (``target`` ``None`` for approximation only).
    - `C`: ``(k_N, k)`` functional map; C2: ``std2``'s ``(2k_N, 2k)`` map.
    - `p2p`: point map (target vertex → source vertex) of the ``p2p`` method.
    - `centers`: BSF centres on the source; distances: geodesic distances from them (``geod``).
    """
    return Pair(source=source, target=target, C=C, C2=C2, p2p=p2p, centers=centers,
                distances=distances)


def stack(items):
    """Stack equal-shaped pairs (leading pair axis) to run them under one ``vmap``."""
    return stack_pairs(items)


def run_method(method: str, pair, F, *, k: int, settings: Settings, transfer: bool = True,
               k_targets=None) -> TransferResult:
    """Approximate ``F`` on the source with ``method`` and transfer it to the target.

    **Arguments:**

    - `method`: one of [`METHODS`][bsfjax.METHODS].
    - `pair`: `pair_input` (or a `stack` of them).
    - `F`: ``(m, n_M)`` functions (``(P, m, n_M)`` for a stack).
    - `k`: source basis size.
    - `settings`: `settings`.
    - `transfer`: also transfer (else ``transferred`` is ``None``).
    - `k_targets`: target sizes: one transfer per ``C[:k_N]`` (``transferred`` a tuple).

    **Returns:**

    ``(approximation, transferred, codes)`` (``approximation`` is ``None`` for ``p2p``).
    """
    return _run_transfer(settings.method(method), pair, F, k=k, transfer=transfer,
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
    return saturate(jnp.asarray(spectrum.evecs, fr.coeffs.dtype) @ fr.coeffs, settings.gamma)
