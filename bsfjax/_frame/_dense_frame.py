r"""The dense Binary Sparse Frame: the atoms as an ``(n, q)`` 0/1 matrix.

Owner of: [`Frame`][bsfjax.Frame] (one implementation of [`AbstractFrame`][bsfjax.AbstractFrame]) and the
host CSR source of its Gram rows.  Products are plain matrix products; the Gram matrix of
0/1 atoms in float64 is formed in float32 (exact integers) when that is faster.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import scipy.sparse as sp
from jaxtyping import Array, Float, Int

from ._binarize import binarize
from .._util import BSFError
from ._operator import TAU_CONVENTIONS, AbstractFrame

__all__ = ["Frame", "dense_gram"]

#: Cost of one sparse multiply-add of a host Gram row relative to one GEMM flop (measured on 2
#: cores: ~3.4 ns vs ~6 ps).  A dense frame gets its OMP Gram rows from a host CSR copy when
#: ``rows · (nnz/q) · (nnz/n) · HOST_ROW_COST < n q²`` (the Gram GEMM), e.g. FAUST binary
#: frames (2.5 % nonzeros) coding 100 functions with S = 10, but not with 256 steps.
HOST_ROW_COST = 500


class Frame(AbstractFrame):
    """A Binary Sparse Frame on one shape: ``q`` binary atoms and where they came from.

    Column order: scale-major — column ``s * n_centers + c`` is the atom of scale ``taus[s]``
    centred at ``centers[c]``; ``Frame.taus`` and ``Frame.centers`` give both per column.

    **Attributes:**

    - `atoms`: ``(n, q)`` binary matrix B (0/1 in the float dtype), one atom per column.
    - `coeffs`: ``(k, q)`` spectral coefficients ĝ ⊙ Φ[x, :] of the Gaussian behind each atom
      (the quantity a functional map transports, paper Eq. 11), with ĝ in the frame's
      ``tau_convention``.
    - `taus`: ``(q,)`` diffusion scale τ of each column (as given by the caller).
    - `centers`: ``(q,)`` int vertex index of each column's centre.  After
      [`transfer_frame`][bsfjax.transfer_frame] these still index the *source* shape's vertices.
    - `mass`: ``(n,)`` vertex areas of the shape (for area-weighted coding and metrics), or
      ``None`` (a plain atom array given to [`bsfjax.encode`][bsfjax.encode]: unit weights).
    - `gammas`: ``(q,)`` threshold γ of each column (reused by [`transfer_frame`][bsfjax.transfer_frame]), or
      ``None`` for a hand-made frame.
    - `tau_convention`: how ``taus`` enter ĝ (static): ``"unit_area"`` means
      ĝ_l = exp(−τ · area · (λ_l − λ_1)) with area = Σ mass; ``"raw"`` means
      ĝ_l = exp(−τ (λ_l − λ_1)).  `effective_taus` gives the τ applied to the raw
      eigenvalues in either case.
    - `columns`: ``(q,)`` int index of each column in the frame as [`build_frame`][bsfjax.build_frame] made
      it, after [`prune_frame`][bsfjax.prune_frame] dropped duplicate or empty atoms; ``None`` for a
      frame that was never pruned (column ``j`` is built column ``j``).
    """

    atoms: Float[Array, "n q"]
    coeffs: Float[Array, "k q"]
    taus: Float[Array, " q"]
    centers: Int[Array, " q"]
    mass: Float[Array, " n"] | None
    gammas: Float[Array, " q"] | None = None
    tau_convention: str = eqx.field(static=True, default="unit_area")
    columns: Int[Array, " q"] | None = None

    def __check_init__(self):
        if self.tau_convention not in TAU_CONVENTIONS:
            raise BSFError(f"tau_convention must be one of {TAU_CONVENTIONS}, "
                           f"got {self.tau_convention!r}")

    @property
    def n_vertices(self) -> int:
        return int(self.atoms.shape[-2])

    @property
    def n_atoms(self) -> int:
        return int(self.atoms.shape[-1])

    @property
    def dtype(self):
        return self.atoms.dtype

    # ---------------------------------------------------------------- products

    def apply(self, alpha):
        return alpha @ jnp.asarray(self.atoms).T

    def apply_transpose(self, y, w=None):
        return (y if w is None else y * w) @ self.atoms

    def column_norms2(self, w=None):
        B2 = self.atoms * self.atoms
        return jnp.sum(B2, axis=0) if w is None else w @ B2

    def gram(self, w=None):
        if w is None:
            return dense_gram(self.atoms)
        Bw = self.atoms * jnp.sqrt(w)[:, None]
        return Bw.T @ Bw

    def gram_rows(self, ks, w=None):
        cols = self.atoms[:, ks]
        return (cols if w is None else cols * w[:, None]).T @ self.atoms

    def host_gram_source(self, w, n_rows: int):
        """A CSR copy of ``diag(√w) B`` when the Gram GEMM would be chosen (``2 · rows ≥ q``)
        and ``rows`` host rows cost less than it (`HOST_ROW_COST`)."""
        Bh = np.asarray(self.atoms)
        n, q = Bh.shape
        if 2 * n_rows < q:
            return None
        # row-major: sorted by vertex, then atom (on the bool mask: ~4× faster than on floats)
        flat = np.flatnonzero(Bh != 0)
        nnz = flat.size
        if n_rows * (nnz / q) * (nnz / n) * HOST_ROW_COST >= n * q * q:
            return None
        r, c = np.divmod(flat, q)
        indptr = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(r, minlength=n), out=indptr[1:])
        Bs = sp.csr_matrix((Bh.reshape(-1)[flat].astype(np.float64), c.astype(np.int32),
                            indptr), shape=(n, q))
        if w is not None:
            Bs = sp.diags(np.sqrt(np.asarray(w, np.float64))) @ Bs
        return _CsrGramSource(Bs)

    # ---------------------------------------------------------------- structure

    def todense(self, dtype=None):
        return jnp.asarray(self.atoms, dtype)

    def atom_columns(self, js):
        return (np.asarray(self.atoms)[:, np.atleast_1d(js)] != 0).astype(np.float32)

    def supports_equal(self, a, b):
        B = np.asarray(self.atoms) != 0
        return np.all(B[:, np.asarray(a)] == B[:, np.asarray(b)], axis=0)

    def support_hashes(self, r):
        zero = jnp.zeros((), jnp.uint32)
        present = self.atoms != 0
        return jnp.stack([jnp.sum(jnp.where(present, ri[:, None], zero), axis=0,
                                  dtype=jnp.uint32) for ri in r])

    def nonempty(self):
        return jnp.any(self.atoms != 0, axis=0)

    def select_columns(self, cols, columns=None):
        return Frame(atoms=self.atoms[:, cols], coeffs=self.coeffs[:, cols],
                     taus=self.taus[cols], centers=self.centers[cols], mass=self.mass,
                     gammas=None if self.gammas is None else self.gammas[cols],
                     tau_convention=self.tau_convention, columns=columns)

    def pull_back(self, p2p, coeffs, mass):
        return Frame(atoms=jnp.asarray(self.atoms)[p2p], coeffs=coeffs, taus=self.taus,
                     centers=self.centers, mass=mass, gammas=self.gammas,
                     tau_convention=self.tau_convention, columns=self.columns)

    def rebinarized(self, evecs, coeffs, mass):
        return Frame(atoms=_binarize_jit(evecs, coeffs, self.gammas), coeffs=coeffs,
                     taus=self.taus, centers=self.centers, mass=mass, gammas=self.gammas,
                     tau_convention=self.tau_convention, columns=self.columns)


@jax.jit
def _binarize_jit(evecs, coeffs, gammas):
    """Atoms of ``Φ[:, :k_N] a`` for ``a = coeffs`` ``(k_N, q)`` (the slice inside the jit)."""
    return binarize(evecs[:, :coeffs.shape[0]], coeffs, gammas)


def dense_gram(B):
    """``G = BᵀB`` (q, q).  In float64, a 0/1 frame (unweighted binary atoms) has integer
    ``G ≤ n``, exact in float32 when ``n < 2²⁴``: that GEMM is about twice as fast, so it is
    used whenever the atoms are 0/1 (checked at run time; weighted rows are not)."""
    if B.dtype != jnp.float64 or B.shape[0] >= 2**24:
        return B.T @ B
    binary = jnp.all((B == 0) | (B == 1))
    return jax.lax.cond(binary, lambda B: _gram32(B).astype(B.dtype), lambda B: B.T @ B, B)


def _gram32(B):
    B32 = B.astype(jnp.float32)
    return B32.T @ B32


class _CsrGramSource:
    """Gram rows ``(Bs[:, k])ᵀ Bs`` of a scipy CSR ``Bs = diag(√w) B`` (host)."""

    def __init__(self, Bs):
        self.BT, self.B = Bs.T.tocsr(), Bs.tocsr()

    def rows(self, ks) -> np.ndarray:
        return (self.BT[ks] @ self.B).toarray()
