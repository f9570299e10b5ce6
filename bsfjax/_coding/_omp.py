r"""Orthogonal matching pursuit in a frame (paper Eqs. 8, 9): [`OMP`][bsfjax.OMP], [`ErrorOMP`][bsfjax.ErrorOMP].

Batch-OMP of Rubinstein, Zibulevsky & Elad (2008) on the ℓ2-normalised atoms ``D = B/‖b_j‖_W``
(what SPAMS, used by the paper, and scikit-learn's ``orthogonal_mp`` assume); the
coefficients are mapped back, ``α_j = β_j / ‖b_j‖_W``.  Gram matrix rows, a progressive
Cholesky factor (kept as its inverse, so every update is a small batched matrix product), a
fixed maximum number of masked steps.  Empty atoms are never selected, no atom is selected
twice, and a function stops early when its best correlation satisfies ``c² ≤ eps·‖f‖²``
(nothing left to fit at this precision) or when the best atom is linearly dependent on the
selected ones.  Large batches are processed in chunks of about 1M buffered numbers
(``chunk · steps · q``), which bounds memory and keeps the per-step work in cache.

The Gram rows ``(BᵀWB)[k, :]`` of the selected atoms come from one of three places, chosen
per call (``precompute``): the full ``BᵀWB`` (one ``n q²`` GEMM), the frame's device rows
(``O(n q)`` each), or a host source the frame offers (``frame.host_gram_source``: a CSR copy
of a sparse enough dense frame, or a sparse frame's lists), cached per call
(``_gram_rows.py``).
"""

from __future__ import annotations

import abc
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._coders import AbstractCoder, check_positive, check_precompute, check_steps
from .._util import BSFError
from .._frame import host_gram_rows
from .._util import check_int, is_traced

__all__ = ["OMP", "ErrorOMP"]

#: Functions are coded in chunks whose OMP buffers (``chunk × steps × q`` Gram rows) hold about
#: this many numbers, so that they stay in cache and memory stays bounded for any batch size
#: (and a chunk whose functions all stopped ends its loop early).  Measured on FAUST, q = 1032,
#: 256 steps, 100 functions: 2²⁰ is 2–3× faster than 2²² in float32 and float64.
_OMP_CHUNK_ELEMS = 2**20


class _AbstractOMP(AbstractCoder):
    """The options and the solve shared by both OMP coders."""

    precompute: Any = eqx.field(static=True, default="auto")

    def __check_init__(self):
        check_precompute(self.precompute)

    @abc.abstractmethod
    def _n_steps(self, q: int) -> int:
        """Largest number of atoms a code may select in a frame of ``q`` atoms."""

    def _mode(self, frame, w, m, q, n_steps, host: bool) -> str:
        if host:
            return "host"
        if self.precompute != "auto":
            return "full" if self.precompute else "rows"
        # Gram: one n·q² GEMM; rows: n·q·m per step.  Measured crossover (FAUST, q ≈ 1000,
        # 2 cores) near m·steps ≈ q/2, the GEMM being the more efficient of the two.
        return "full" if 2 * m * n_steps >= q else "rows"

    def _host_source(self, frame, w, m):
        if self.precompute != "auto" or m == 0:
            return None
        if any(is_traced(x) for x in jax.tree.leaves(frame)) or (w is not None and is_traced(w)):
            return None
        return frame.host_gram_source(w, m * self._n_steps(frame.n_atoms))

    def _static(self, frame, w, m, host: bool) -> dict:
        q = frame.n_atoms
        n_steps = self._n_steps(q)
        return {"n_steps": n_steps, "mode": self._mode(frame, w, m, q, n_steps, host),
                "chunk": max(1, min(m, _OMP_CHUNK_ELEMS // (n_steps * q)))}

    @classmethod
    @abc.abstractmethod
    def _bound(cls, static, dyn, fnorm2):
        """Traced: the squared-residual bound at which a code stops (``None``: none)."""

    @classmethod
    def _solve(cls, frame, F, w, C, fnorm2, static, dyn):
        dtype = C.dtype
        norms2 = frame.column_norms2(w).astype(dtype)
        valid = norms2 > 0
        inv_norm = jnp.where(valid, 1.0 / jnp.sqrt(jnp.where(valid, norms2, 1.0)), 0.0)
        mode = static["mode"]
        if mode == "host":
            raw = host_gram_rows(dyn["gram_token"], frame.n_atoms, dtype)
        elif mode == "full":
            G = frame.gram(w).astype(dtype)
            raw = lambda k: G[k]  # noqa: E731
        else:
            raw = lambda k: frame.gram_rows(k, w).astype(dtype)  # noqa: E731

        def gram_rows(k):  # (b,) -> (b, q) rows of DᵀD
            return raw(k) * inv_norm[k][:, None] * inv_norm[None, :]

        eps = cls._bound(static, dyn, fnorm2)
        alpha, n_sel, exhausted = omp_loop(gram_rows, inv_norm, valid, C, fnorm2, eps,
                                           static["n_steps"], static["chunk"])
        return alpha, cls._converged(static, n_sel, exhausted, eps)


class OMP(_AbstractOMP):
    """Sparsity-constrained OMP: ``min ‖f − Bα‖_W  s.t. ‖α‖₀ ≤ S`` (paper Eq. 9).

    **Arguments:**

    - `sparsity`: ``S ≥ 1``, at most that many atoms (default 10; the default is capped at
      ``q`` on smaller frames, an explicit ``S > q`` is an error).
    - `precompute`: ``"auto"`` (default), ``True`` (form the full ``q × q`` Gram matrix,
      ``O(n q²)`` once) or ``False`` (only the Gram rows of the selected atoms, ``O(n q)`` per
      step and function).  ``"auto"`` forms it when ``2 · batch · S ≥ q`` — except that a
      concrete frame offering cheaper host rows (a sparse enough dense frame, or any
      [`SparseFrame`][bsfjax.SparseFrame]) gets them from the host.
    - `weights`: the coding norm (see [`AbstractCoder`][bsfjax.AbstractCoder]).
    """

    sparsity: int = eqx.field(static=True, default=10)
    name = "omp"

    def __check_init__(self):
        check_int(self.sparsity, "sparsity", 1)

    def _n_steps(self, q):
        return check_steps(self, "sparsity", q)

    def _options(self, frame, w, lead, m, dtype, host=False):
        return self._static(frame, w, m, host), {}, {}

    @classmethod
    def _bound(cls, static, dyn, fnorm2):
        return jnp.full(fnorm2.shape, -jnp.inf, fnorm2.dtype)  # never reached: S steps run

    @classmethod
    def _converged(cls, static, n_sel, exhausted, eps):
        return (n_sel == static["n_steps"]) | exhausted


class ErrorOMP(_AbstractOMP):
    """Error-constrained OMP: ``min ‖α‖₀  s.t. ‖f − Bα‖²_W ≤ ε`` (paper Eq. 8), atoms capped.

    **Arguments:**

    - `eps_fraction`: the default bound ``ε = (eps_fraction · ‖f‖_W)²`` per function
      (default 0.1: the paper's "``ε = ‖f‖/10``" read as a bound on the residual *norm* — a
      10 % relative error, invariant to the scale of ``f``, to the mesh resolution and to the
      weights).
    - `eps`: instead, an explicit bound on the **squared** residual (SPAMS' convention): a
      number ``≥ 0`` or an array broadcasting to the batch shape ``...`` of ``f``; or
      ``"spams"``: ``ε = eps_fraction · ‖f‖`` on the squared residual, as a literal SPAMS
      call ``mexOMP(…, eps=‖f‖/10)`` would (not scale invariant).  Default ``None``.
    - `max_atoms`: cap on the atom count (default 64, capped at ``q``), since the bound is
      often unreachable (``info.converged`` says which functions met it).
    - `precompute`: as for [`OMP`][bsfjax.OMP].
    - `weights`: the coding norm (see [`AbstractCoder`][bsfjax.AbstractCoder]).

    At least one atom is selected unless ``‖f‖² ≤ ε``.
    """

    eps_fraction: float = eqx.field(static=True, default=0.1)
    eps: Any = None
    max_atoms: int = eqx.field(static=True, default=64)
    name = "omp_error"

    def __check_init__(self):
        check_positive("eps_fraction", self.eps_fraction, allow_zero=True)
        check_int(self.max_atoms, "max_atoms", 1)
        eps = self.eps
        if eps is None or (isinstance(eps, str) and eps == "spams"):
            return
        if isinstance(eps, str):
            raise BSFError(f"eps must be None, 'spams', a number >= 0 or an array, got {eps!r}")
        if not is_traced(eps):
            arr = np.asarray(eps)
            if not np.issubdtype(arr.dtype, np.number) or arr.dtype == np.bool_:
                raise BSFError(f"eps must be numeric, got {eps!r}")
            if not np.all(np.isfinite(arr)) or np.any(arr < 0):
                bad = int(np.sum(~np.isfinite(arr) | (arr < 0)))
                got = repr(eps) if arr.ndim == 0 else f"an array with {bad} such entries"
                raise BSFError(f"eps must be finite and >= 0, got {got}")

    def _n_steps(self, q):
        return check_steps(self, "max_atoms", q)

    def _options(self, frame, w, lead, m, dtype, host=False):
        static = self._static(frame, w, m, host)
        eps = self.eps
        if eps is None or isinstance(eps, str):
            static["eps_mode"] = "relative" if eps is None else "spams"
            static["eps_fraction"] = float(self.eps_fraction)
            return static, {}, {}
        try:
            np.broadcast_shapes(np.shape(eps), lead)
        except ValueError:
            raise BSFError(f"eps of shape {np.shape(eps)} does not broadcast to the "
                           f"functions' batch shape {lead}") from None
        static["eps_mode"] = "absolute"
        per = {"eps": jnp.reshape(jnp.broadcast_to(jnp.asarray(eps, dtype), lead), (m,))}
        return static, {}, per

    @classmethod
    def _bound(cls, static, dyn, fnorm2):
        if static["eps_mode"] == "relative":
            return (static["eps_fraction"] ** 2) * fnorm2
        if static["eps_mode"] == "spams":
            return static["eps_fraction"] * jnp.sqrt(fnorm2)
        return dyn["eps"]

    @classmethod
    def _converged(cls, static, n_sel, exhausted, eps):
        return lambda res2: res2 <= eps


def omp_loop(gram_rows, inv_norm, valid, C, fnorm2, eps, n_steps: int, chunk: int):
    """Batch-OMP on the normalised atoms; returns ``(alpha, n_selected, exhausted)``.

    ``gram_rows(k)`` ``(b,) -> (b, q)``: rows of the normalised Gram matrix ``DᵀD``;
    ``inv_norm`` ``(q,)``: inverse atom norms (0 for empty atoms); C = BᵀWf ``(m, q)``, fnorm2 ``(m,)``, eps ``(m,)`` bound on the squared residual
    (``-inf``: none); ``chunk`` functions at a time (``lax.map``).  Per function and step
    ``t`` (``I`` the selected atoms, ``D = B/‖b‖``)::

        k   = argmax |c| over atoms not selected and not empty      c = Dᵀr, the correlations
        w   = L⁻¹ G_{I,k};  d² = 1 − ‖w‖²                            L Lᵀ = G_II (Cholesky)
        L⁻¹ ← [[L⁻¹, 0], [−wᵀL⁻¹/d, 1/d]];  y ← [y, (c0_k − wᵀy)/d]   y = L⁻¹ (Dᵀf)_I
        β   = L⁻ᵀ y;  c = c0 − G_{:,I} β;  ‖r‖² = ‖f‖² − ‖y‖²

    A function stops (and stays stopped) when no atom is left, ``c_k² ≤ eps·‖f‖²``,
    ``‖r‖² ≤ ε``, or ``d² ≤ 100·eps`` (atom ``k`` dependent on ``I``); so a function still
    running at step ``t`` has exactly ``t`` atoms, and every update writes slot ``t``.
    """
    dtype = C.dtype
    m, q = C.shape
    T = n_steps
    tiny = jnp.finfo(dtype).eps
    tol_dep = 100 * jnp.finfo(dtype).eps
    slots = jnp.arange(T)

    def run(args):  # one chunk of b functions
        c0, fnorm2, eps = args
        b = c0.shape[0]
        rows = jnp.arange(b)

        def cond(state):
            t, *_, done, _res2 = state
            return (t < T) & ~jnp.all(done)

        def body(state):
            t, idx, Linv, y, gsel, c, avail, n_sel, exhausted, done, res2 = state
            score = jnp.where(avail, jnp.abs(c), -1.0)
            k = jnp.argmax(score, axis=1).astype(jnp.int32)
            ck = c[rows, k]
            none_left = score[rows, k] < 0
            fitted = ck * ck <= tiny * fnorm2  # residual orthogonal to all atoms (or f = 0)
            stop = done | none_left | fitted | (res2 <= eps)
            g = gram_rows(k)  # (b, q)
            gI = jnp.where(slots < t, jnp.take_along_axis(g, idx, axis=1), 0.0)
            w = jnp.einsum("bij,bj->bi", Linv, gI)  # L⁻¹ G_{I,k}
            d2 = g[rows, k] - jnp.sum(w * w, axis=1)  # squared distance of atom k to span(D_I)
            act = ~stop & (d2 > tol_dep)
            d = jnp.sqrt(jnp.where(act, d2, 1.0))
            new_row = -jnp.einsum("bi,bij->bj", w, Linv) / d[:, None]
            new_row = jnp.where(slots == t, 1.0 / d[:, None], new_row)
            y_new = (c0[rows, k] - jnp.sum(w * y, axis=1)) / d

            def put(buf, new):  # write slot t of the running functions (in place)
                old = jax.lax.dynamic_index_in_dim(buf, t, axis=1, keepdims=False)
                sel = jnp.where(act.reshape((b,) + (1,) * (new.ndim - 1)), new, old)
                return jax.lax.dynamic_update_index_in_dim(buf, sel, t, axis=1)

            Linv, y, gsel, idx = put(Linv, new_row), put(y, y_new), put(gsel, g), put(idx, k)
            avail = avail.at[rows, k].set(avail[rows, k] & ~act)
            beta = jnp.einsum("bji,bj->bi", Linv, y)  # β = L⁻ᵀ y = G_II⁻¹ (Dᵀf)_I
            c = c0 - jnp.einsum("bi,biq->bq", beta, gsel)  # Dᵀ r
            res2 = jnp.where(act, res2 - y_new * y_new, res2)
            exhausted = exhausted | (~done & (fitted | none_left))
            return (t + 1, idx, Linv, y, gsel, c, avail, n_sel + act, exhausted, done | ~act,
                    res2)

        state = (
            jnp.asarray(0),
            jnp.zeros((b, T), jnp.int32),
            jnp.broadcast_to(jnp.eye(T, dtype=dtype), (b, T, T)),
            jnp.zeros((b, T), dtype),
            jnp.zeros((b, T, q), dtype),
            c0,
            jnp.broadcast_to(valid, (b, q)),
            jnp.zeros(b, jnp.int32),
            jnp.zeros(b, bool),
            jnp.zeros(b, bool),
            fnorm2,
        )
        _, idx, Linv, y, _, _, _, n_sel, exhausted, _, _ = jax.lax.while_loop(cond, body, state)
        beta = jnp.einsum("bji,bj->bi", Linv, y)
        coef = jnp.where(slots < n_sel[:, None], beta * inv_norm[idx], 0.0)
        alpha = jnp.zeros((b, q), dtype).at[rows[:, None], idx].add(coef)
        return alpha, n_sel, exhausted

    args = (C * inv_norm, fnorm2, eps)  # c0 = Dᵀf
    if chunk >= m:
        return run(args)
    pad = -m % chunk  # zero functions: they stop at once
    args = jax.tree.map(lambda x: jnp.pad(x, [(0, pad)] + [(0, 0)] * (x.ndim - 1)), args)
    out = jax.lax.map(run, jax.tree.map(lambda x: x.reshape((-1, chunk) + x.shape[1:]), args))
    return jax.tree.map(lambda x: x.reshape((-1,) + x.shape[2:])[:m], out)
