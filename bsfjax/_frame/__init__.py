"""The Binary Sparse Frame: binarized spectral Gaussians as dense or sparse frame operators, and their transfer through a functional map."""

from ._binarize import effective_taus, kernel_mask
from ._build import build_frame, transfer_frame
from ._dense_frame import Frame
from ._frame_tools import ADAPTIVE_N_SCALES, adaptive_taus, prune_frame, unique_atoms
from ._gram_rows import HostGramRows, host_gram_rows
from ._operator import AbstractFrame, DENSE_BUDGET_BYTES
from ._packed_lists import decode_host, decode_traced, pack_lists
from ._sparse_frame import SparseFrame, ell_matmul, ell_rmatmul, sparse_atoms
from ._sparse_gram import sparse_gram

__all__ = [
    "ADAPTIVE_N_SCALES", "AbstractFrame", "DENSE_BUDGET_BYTES", "Frame", "HostGramRows",
    "SparseFrame", "adaptive_taus", "build_frame", "decode_host", "decode_traced",
    "effective_taus", "ell_matmul", "ell_rmatmul", "host_gram_rows", "kernel_mask",
    "pack_lists", "prune_frame", "sparse_atoms", "sparse_gram", "transfer_frame", "unique_atoms",
]
