"""The transfer-method interface and the Binary Sparse Frame method. Owner of `Pair` (the inputs of
one pair), `AbstractMethod`, the input checks the methods share, the frame options of the
methods built on the BSF's centres and scales (`_FrameSettings`, `PAPER_TAUS`, `PAPER_GAMMA`)
and [`BSF`][bsfjax.BSF] itself (paper Algorithm 1 and Eq. 11–13); the baselines
(`bsfjax._transfer._baselines`), the refined pull-back (`bsfjax._transfer._refined`) and the
registry of names (`bsfjax._transfer._methods`) build on this module.
"""

from __future__ import annotations

import abc
import dataclasses
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float, Int

from .._coding import AbstractCoder
from .._coding import decode, encode
from .._util import BSFError
from .._frame import build_frame, transfer_frame
from .._frame import ADAPTIVE_N_SCALES, prune_frame, unique_atoms
from .._frame import SparseFrame
from .._coding import OMP
from .._spectral import Spectrum

__all__ = ["AbstractMethod", "BSF", "Pair", "PAPER_TAUS", "PAPER_GAMMA"]

#: The paper's diffusion scales (unit-area convention) and threshold.
PAPER_TAUS = (1e-3, 5e-3, 1e-2)
PAPER_GAMMA = 0.75
#: How the BSF reaches the target ([`BSF.frame_transfer`][bsfjax.BSF.frame_transfer]).
FRAME_TRANSFERS = ("binary", "p2p")


class Pair(eqx.Module):
    """Everything a method may need about one source/target pair (or a stack of pairs).

    A stack of ``P`` pairs has a leading ``P`` axis on every array (equal shapes).

    **Arguments:**

    - `source`: spectrum of ``M`` (``≥ k`` eigenpairs; ``≥ 2k`` for ``"std2"``).
    - `target`: spectrum of ``N``; ``None`` for approximation only.
    - `C`: ``(k_N, k)`` functional map ``M → N`` on coefficients.
    - `C2`: ``(2k_N, 2k)`` map of ``"std2"``.
    - `p2p`: ``(n_N,)`` int point map, target vertex → source vertex.
    - `centers`: ``(n_c,)`` int BSF centres on ``M`` (``BSF``, ``"geod"``, ``"heat"``).
    - `distances`: ``(n_c, n_M)`` geodesic distances from the centres (``"geod"``).
    - `samples`: ``(source, target)`` [`Subsample`][bsfjax.Subsample] s (``"refined"``: its
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
    """A transfer method (see the module docstring of `bsfjax._transfer._methods`).  Subclasses
    set `name`."""

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


class BSF(_FrameSettings):
    """Ours: the Binary Sparse Frame coded with ``coder`` (paper Algorithm 1 and Eq. 11–13).

    **Arguments:**

    - `coder`: an [`OMP`][bsfjax.OMP] (default, ``S = 10``), ``ErrorOMP``, ``LeastSquares``
      or ``Lasso``; area-weighted by default (the codes minimise ``‖f − Bα‖_A``).
    - ``taus``, ``gamma``, ``tau_convention``: the frame's scales (``"adaptive"`` for
      [`bsfjax.adaptive_taus`][bsfjax.adaptive_taus]), threshold and τ convention ([`bsfjax.build_frame`][bsfjax.build_frame]).
    - `prune`: code in the distinct non-empty atoms only (`unique_atoms`).
    - `frame_transfer`: ``"binary"`` (re-binarize ``Φ_N C a``, paper Eq. 11–12) or ``"p2p"``
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
