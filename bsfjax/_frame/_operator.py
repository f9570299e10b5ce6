r"""A frame is a linear operator: the abstract interface every coder is written against.

Owner of: [`AbstractFrame`][bsfjax.AbstractFrame], `TAU_CONVENTIONS`, `DENSE_BUDGET_BYTES`.

A Binary Sparse Frame on a shape with ``n`` vertices is the binary matrix ``B`` ``(n, q)``, one
atom per column, together with where the atoms came from (the kernel coefficients ``coeffs``,
``taus``, ``centers``, ``gammas``) and the vertex areas ``mass``.  The coders
(``_lstsq.py``, ``_omp.py``, ``_lasso.py``) only ever touch ``B`` through this interface, with
``W = diag(w)`` the weights of the coding norm ``‖u‖²_W = Σ_v w_v u_v²`` (``w = None``: ``W = I``)
and functions stored as rows (the library's ``(..., n)`` convention):

==========================  ===============================================================
``apply(α)``                rows of ``B α``: ``(m, q) -> (m, n)``
``apply_transpose(Y, w)``   rows of ``Bᵀ W y``: ``(m, n) -> (m, q)``
``column_norms2(w)``        ``(q,)`` ``‖b_j‖²_W``
``gram(w)``                 the full ``BᵀWB`` ``(q, q)`` (when it fits)
``gram_rows(ks, w)``        rows ``(BᵀWB)[ks, :]`` ``(len(ks), q)``
``host_gram_source(w, r)``  a host source of Gram rows if it beats the device for ``r`` rows
``transfer(C, Φ_N, …)``     the frame carried to another shape through a functional map
``todense()``               ``B`` as an ``(n, q)`` array
==========================  ===============================================================

The two implementations are [`bsfjax.Frame`][bsfjax.Frame] (``_dense_frame.py``: the ``(n, q)``
matrix) and [`bsfjax.SparseFrame`][bsfjax.SparseFrame] (``_sparse_frame.py``: per-vertex atom lists).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
from jaxtyping import Array, Float, Int

from ._binarize import effective_taus as _effective_taus

__all__ = ["AbstractFrame", "TAU_CONVENTIONS", "DENSE_BUDGET_BYTES"]

#: ``sparse=None`` builds a [`SparseFrame`][bsfjax.SparseFrame] when the dense atoms (``n · q`` entries
#: of the float dtype) would take more than this many bytes; a sparse frame forms its dense
#: ``q × q`` Gram matrix (least squares, lasso) only within it.
DENSE_BUDGET_BYTES = 2**31

#: ``"unit_area"``: τ acts on the eigenvalues of the shape rescaled to unit area (λ · area);
#: ``"raw"``: τ acts on the eigenvalues as they are (the paper's formula).
TAU_CONVENTIONS = ("unit_area", "raw")


class AbstractFrame(eqx.Module):
    """A Binary Sparse Frame as a linear operator ``B`` ``(n, q)`` (see the module docstring).

    Fields every frame has (column order scale-major: column ``s * n_centers + c`` is the atom
    of scale ``taus[s]`` centred at ``centers[c]``):

    - `coeffs`: ``(k, q)`` spectral coefficients ``ĝ ⊙ Φ[x, :]`` of each atom's kernel (what a
      functional map transports, paper Eq. 11).
    - `taus`: ``(q,)`` diffusion scale of each column, in ``tau_convention``.
    - `centers`: ``(q,)`` vertex index of each column's centre (after a transfer: still the
      source shape's vertices).
    - `mass`: ``(n,)`` vertex areas (the ``weights="area"`` of the coders), or ``None`` for a
      plain atom array wrapped as a frame.
    - `gammas`: ``(q,)`` thresholds γ (reused by a transfer), or ``None``.
    - `tau_convention`: ``"unit_area"`` or ``"raw"`` (static).
    - `columns`: ``(q,)`` index of each column in the frame as built, after pruning; ``None``
      when never pruned.
    """

    # The fields above are declared by each implementation (an ``eqx.AbstractVar`` here would
    # fix their order before the implementation's own first field, ``atoms``/``atom_lists``).

    # ---------------------------------------------------------------- sizes

    @property
    @abc.abstractmethod
    def n_vertices(self) -> int:
        """``n``, the number of vertices (rows of ``B``)."""

    @property
    @abc.abstractmethod
    def n_atoms(self) -> int:
        """``q``, the number of atoms (columns of ``B``)."""

    @property
    @abc.abstractmethod
    def dtype(self):
        """The float dtype the frame computes in (before promotion with the functions)."""

    @property
    def effective_taus(self) -> Float[Array, " q"]:
        """``(q,)`` the τ multiplying the raw eigenvalues: ``taus · Σ mass`` for
        ``"unit_area"``, ``taus`` for ``"raw"``.  (After a transfer, Σ mass is the target's.)"""
        return _effective_taus(self.taus, self.mass, self.tau_convention)

    # ---------------------------------------------------------------- products (traceable)

    @abc.abstractmethod
    def apply(self, alpha: Float[Array, "m q"]) -> Float[Array, "m n"]:
        """Rows of ``B α``: the functions ``f = Bα`` of the codes ``α`` (rows)."""

    @abc.abstractmethod
    def apply_transpose(self, y: Float[Array, "m n"],
                        w: Float[Array, " n"] | None = None) -> Float[Array, "m q"]:
        """Rows of ``Bᵀ W y`` (``w = None``: ``Bᵀ y``), the correlations of ``y`` with the
        atoms in the ``W`` inner product."""

    @abc.abstractmethod
    def column_norms2(self, w: Float[Array, " n"] | None = None) -> Float[Array, " q"]:
        """``(q,)`` squared atom norms ``‖b_j‖²_W = Σ_v w_v B_vj²``."""

    @abc.abstractmethod
    def gram(self, w: Float[Array, " n"] | None = None) -> Float[Array, "q q"]:
        """The Gram matrix ``BᵀWB`` ``(q, q)`` in the frame's dtype."""

    @abc.abstractmethod
    def gram_rows(self, ks: Int[Array, " b"],
                  w: Float[Array, " n"] | None = None) -> Float[Array, "b q"]:
        """Rows ``(BᵀWB)[ks, :]``, computed on the device (``O(n q)`` per row or less)."""

    def host_gram_source(self, w, n_rows: int):
        """A host source of Gram rows (an object with ``rows(ks)`` giving float64
        ``(len(ks), q)`` rows of ``BᵀWB``) when ``n_rows`` such rows are cheaper there than
        on the device, else ``None``.  Only called with concrete frames and weights."""
        return None

    # ---------------------------------------------------------------- structure

    @abc.abstractmethod
    def todense(self, dtype=None) -> Float[Array, "n q"]:
        """``B`` as an ``(n, q)`` array (only for frames that fit in memory)."""

    @abc.abstractmethod
    def atom_columns(self, js) -> "jax.Array":
        """Dense 0/1 columns ``B[:, js]`` ``(n, len(js))`` (host)."""

    @abc.abstractmethod
    def supports_equal(self, a, b) -> "jax.Array":
        """``(len(a),)`` bool (host): ``supp b_{a_i} = supp b_{b_i}``, exactly."""

    @abc.abstractmethod
    def support_hashes(self, r: Int[Array, "h n"]) -> Int[Array, "h q"]:
        """``Σ_v [B_vj ≠ 0] r_hv mod 2³²`` per column and hash row (uint32), and nothing else
        about the values: equal supports hash equally (`unique_atoms`)."""

    @abc.abstractmethod
    def nonempty(self) -> "jax.Array":
        """``(q,)`` bool: the atoms with a non-empty support."""

    @abc.abstractmethod
    def select_columns(self, cols, columns=None) -> "AbstractFrame":
        """The frame of columns ``cols`` (a concrete increasing int array), with
        ``columns`` as its record of built columns."""

    @abc.abstractmethod
    def pull_back(self, p2p, coeffs, mass) -> "AbstractFrame":
        """The frame whose atoms are ``B[p2p]`` (target vertex ``v`` takes the atoms of source
        vertex ``p2p[v]``), with new ``coeffs`` and ``mass`` and the same column data."""

    @abc.abstractmethod
    def rebinarized(self, evecs, coeffs, mass) -> "AbstractFrame":
        """A frame of the same kind on another shape: atoms ``[|Φ a| ≥ γ max |Φ a|]`` of
        ``Φ = evecs`` ``(n_N, k_N)`` and ``a = coeffs`` ``(k_N, q)``, thresholds ``gammas``;
        the other column data are this frame's."""
