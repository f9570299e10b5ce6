"""The Binary Sparse Frame.

Spectral Gaussians `g_x = Φ (ĝ ⊙ Φ[x, :])`, `ĝ_l = exp(−τ (λ_l − λ_1))`, for every centre `x`
and scale `τ`, normalized by their maximum and binarized at `γ`: the columns of `B`.  The frame
is an operator (`AbstractFrame`: products with `B` and `Bᵀ`, Gram rows), dense (`Frame`) or
as per-vertex atom lists for large meshes (`SparseFrame`), and is carried to another shape
through a functional map (`transfer_frame`).  Adaptive scales and pruning of duplicate atoms.
"""

from ._binarize import effective_taus, kernel_mask
from ._build import build_frame, transfer_frame
from ._dense_frame import Frame
from ._frame_tools import ADAPTIVE_N_SCALES, adaptive_taus, prune_frame, unique_atoms
from ._gram_rows import HostGramRows, host_gram_rows
from ._operator import AbstractFrame, DENSE_BUDGET_BYTES
from ._packed_lists import decode_host, decode_traced, pack_lists
from ._ell import ell_matmul, ell_rmatmul
from ._sparse_frame import SparseFrame, sparse_atoms, sparse_gram

__all__ = [
    "ADAPTIVE_N_SCALES", "AbstractFrame", "DENSE_BUDGET_BYTES", "Frame", "HostGramRows",
    "SparseFrame", "adaptive_taus", "build_frame", "decode_host", "decode_traced",
    "effective_taus", "ell_matmul", "ell_rmatmul", "host_gram_rows", "kernel_mask",
    "pack_lists", "prune_frame", "sparse_atoms", "sparse_gram", "transfer_frame", "unique_atoms",
]
