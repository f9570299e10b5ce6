r"""Coders are small objects: the base class, the diagnostics and the shared option checks.

Owner of: [`AbstractCoder`][bsfjax.AbstractCoder], [`CodingInfo`][bsfjax.CodingInfo].  Each algorithm lives in its own
module with its coder class — [`LeastSquares`][bsfjax.LeastSquares] (``_lstsq.py``),
[`OMP`][bsfjax.OMP] and [`ErrorOMP`][bsfjax.ErrorOMP] (``_omp.py``), [`Lasso`][bsfjax.Lasso]
(``_lasso.py``) — and [`bsfjax.encode`][bsfjax.encode] (``_encode.py``) validates the inputs and runs
one jitted kernel that calls the coder's ``_solve`` with the frame as an operator
([`AbstractFrame`][bsfjax.AbstractFrame]): a coder never knows which kind of frame it codes in.

A coder is an ``eqx.Module``; its options are fields with their defaults stated once, checked
when it is made ([`BSFError`][bsfjax.BSFError] on a bad value).  Every coder has ``weights``:

- ``"area"`` (default): the codes minimise ``‖f − Bα‖_A`` with the frame's vertex areas
  ``A = frame.mass`` — the norm of the paper's metrics.  A plain ``(n, q)`` atom array has no
  areas, so there ``"area"`` means unit weights (the Euclidean norm).
- `None`: the Euclidean norm ``‖f − Bα‖₂`` (as SPAMS and scikit-learn).
- an ``(n,)`` array ``w ≥ 0``: ``‖f − Bα‖²_W = Σ_v w_v (f − Bα)_v²``.
"""

from __future__ import annotations

import abc
import math
import numbers
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax
import numpy as np

from .._util import BSFError
from .._util import is_traced

__all__ = ["AbstractCoder", "CodingInfo"]


class CodingInfo(NamedTuple):
    """Per-function diagnostics of [`encode`][bsfjax.encode] (``return_info=True``); a pytree.

    **Attributes:**

    - `n_atoms`: ``(...,)`` int32 number of nonzero coefficients (atoms used).
    - `residual`: ``(...,)`` residual norm ``‖f − Bα‖_W`` in the coder's ``weights``.
    - `converged`: ``(...,)`` bool.  ``OMP``: ``S`` atoms were selected, or the residual
      became orthogonal to every atom (nothing left to fit); false when OMP stopped
      early because the next atom was linearly dependent on the selected ones.
      ``ErrorOMP``: the bound ``‖f − Bα‖² ≤ ε`` was met.  ``Lasso``: the last
      FISTA step met ``tol`` within ``maxiter`` iterations.  ``LeastSquares``: always
      true.
    """

    n_atoms: jax.Array
    residual: jax.Array
    converged: jax.Array



def check_positive(name, value, allow_zero=False):
    ok = isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))
    if not ok or not math.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        rel = ">= 0" if allow_zero else "> 0"
        raise BSFError(f"{name} must be a finite number {rel}, got {value!r}")
    return float(value)


def check_steps(coder, name: str, q: int) -> int:
    """The step count option ``name`` against ``q`` atoms: the field's default is capped at
    ``q`` (tiny frames), an explicit larger value is an error."""
    value = getattr(coder, name)
    if value > q:
        if value == type(coder).__dataclass_fields__[name].default:
            return q
        raise BSFError(f"{name} must be in [1, q={q}], got {value}")
    return value


def check_precompute(value):
    if not (isinstance(value, str) and value == "auto") and value is not True \
            and value is not False:
        raise BSFError(f"precompute must be 'auto', True or False, got {value!r}")


class AbstractCoder(eqx.Module):
    """A sparse (or least-squares) coder: ``α`` with ``f ≈ Bα`` for a frame ``B``.

    Subclasses hold their options as fields and implement ``_options`` (the per-call split of
    the options into static values, replicated arrays and per-function arrays) and ``_solve``
    (traced, written against [`AbstractFrame`][bsfjax.AbstractFrame] only).

    **Arguments:**

    - `weights`: ``"area"`` (default), ``None`` or an ``(n,)`` array — see the module doc.
    """

    weights: Any = "area"

    #: The name of this coder in `CODERS`.
    name: ClassVar[str] = ""

    def __check_init__(self):
        w = self.weights
        if w is None:
            return
        if isinstance(w, str):
            if w != "area":
                raise BSFError(f"weights must be None, 'area' or an (n,) array, got {w!r}")
            return
        if not hasattr(w, "shape"):
            raise BSFError(f"weights must be None, 'area' or an (n,) array, got {w!r}")
        if np.ndim(w) != 1:
            raise BSFError(f"weights must be None, 'area' or an (n,) array, got shape "
                           f"{tuple(np.shape(w))}")
        if not is_traced(w):
            a = np.asarray(w)
            if not np.issubdtype(a.dtype, np.number) or not np.all(np.isfinite(a)) \
                    or np.any(a < 0) or not np.any(a > 0):
                raise BSFError("weights must be finite, >= 0 and not all zero")

    def _options(self, frame, w, lead: tuple, m: int, dtype, host: bool = False):
        """``(static, replicated, per_function)``: hashable static options, arrays shared by
        all functions, arrays with a leading ``(m,)`` function axis.  Checks the options that
        depend on the frame (``q``) or the batch shape ``lead``."""
        return {}, {}, {}

    def _host_source(self, frame, w, m: int):
        """A host source of Gram rows to register for this call (OMP), or ``None``."""
        return None

    @classmethod
    @abc.abstractmethod
    def _solve(cls, frame, F, w, C, fnorm2, static: dict, dyn: dict):
        """Traced: ``(alpha, converged)`` for the ``(m, n)`` functions ``F`` with correlations
        ``C = Bᵀ W F`` ``(m, q)`` and ``fnorm2 = ‖f‖²_W``; ``converged`` is an ``(m,)`` bool
        array or a function of the squared residuals ``(m,) -> (m,)``."""
