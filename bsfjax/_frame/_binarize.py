r"""The binarization of band-limited heat kernels: the one rule both frame kinds use.

Owner of: the kernel coefficients ``a = ĝ_τ ⊙ Φ[x, :]``, the effective τ of a convention, and
the rule

    B_vj = [ |g_vj| ≥ γ_j · max_u |g_uj| ],      g = Φ a,

in one jitted block (`kernel_mask`) and in column blocks that never form the ``(n, q)``
kernel matrix (`binarize`).  The dense frame (``_dense_frame.py``) writes the mask into a
0/1 matrix; the sparse frame (``_sparse_frame.py``) turns its blocks into per-vertex lists.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

__all__ = ["kernel_mask", "binarize", "kernel_coeffs", "effective_taus", "build_core",
           "transfer_coeffs"]

#: Kernel values per column block of `binarize` (4 MiB in float32): the product, the
#: column maxima and the threshold of a block then stay in cache.
BINARIZE_BLOCK_ELEMS = 2**20


def effective_taus(taus: Float[Array, "*b q"], mass: Float[Array, "*b n"],
                   tau_convention: str) -> Float[Array, "*b q"]:
    """The τ multiplying the raw eigenvalues of a frame's columns.

    ``taus · Σ mass`` for ``"unit_area"``, ``taus`` for ``"raw"``.

    **Arguments:**

    - `taus`: ``(q,)`` per-column scales in the frame's convention.
    - `mass`: ``(n,)`` vertex areas of the shape.
    - `tau_convention`: ``"unit_area"`` or ``"raw"``.
    """
    if tau_convention == "raw":
        return taus
    return taus * jnp.sum(mass, axis=-1, keepdims=True)


def kernel_coeffs(evals, evecs, mass, centers, taus, unit_area: bool):
    """``(k, S·C)`` coefficients ``ĝ_s ⊙ Φ[x_c, :]``, scale-major (column ``s · C + c``)."""
    k = evals.shape[0]
    taus_eff = taus * jnp.sum(mass) if unit_area else taus
    ghat = jnp.exp(-taus_eff[:, None] * (evals - evals[0])[None, :])  # (S, k)
    rows = evecs[centers]  # (C, k): Φ[x, :] of every centre
    return (ghat[:, None, :] * rows[None, :, :]).reshape(-1, k).T  # (k, S·C)


kernel_coeffs_jit = jax.jit(kernel_coeffs, static_argnames="unit_area")


def kernel_mask(evecs: Float[Array, "n k"], coeffs: Float[Array, "k c"],
                gammas: Float[Array, " c"]) -> Bool[Array, "n c"]:
    """The binarization rule: ``|g| ≥ γ · max_v |g|`` per column of ``g = evecs @ coeffs``.

    ``max |g|`` is taken as ``max(max g, −min g)`` and the test is division-free (equal to
    ``|g|/max|g| ≥ γ`` up to one rounding at the threshold); a column with ``max |g| = 0`` (a
    kernel that vanished, e.g. mapped to zero by C) gives an empty atom rather than 0/0 = NaN.

    **Arguments:**

    - `evecs`: ``(n, k)`` eigenvectors Φ.
    - `coeffs`: ``(k, c)`` spectral coefficients of the kernels.
    - `gammas`: ``(c,)`` thresholds in ``(0, 1)``.
    """
    # "highest": full float32 products on GPU/TPU too (TF32/bf16 would move atoms at γ)
    g = jnp.matmul(evecs, coeffs, precision=jax.lax.Precision.HIGHEST)
    m = jnp.maximum(jnp.max(g, axis=0), -jnp.min(g, axis=0))
    return (jnp.abs(g) >= gammas * m) & (m > 0)


mask_block = jax.jit(kernel_mask)  # one block of whole columns (the sparse build)


def binarize(evecs: Float[Array, "n k"], coeffs: Float[Array, "k q"],
             gammas: Float[Array, " q"]) -> Float[Array, "n q"]:
    """``(n, q)`` atoms of `kernel_mask` in the float dtype, in column blocks.

    Computed in blocks of ``w`` whole columns written into the result, so the ``(n, q)`` kernel
    matrix ``g`` never exists: one ``(n, w)`` block is multiplied, reduced and thresholded
    while in cache, and the only ``(n, q)`` traffic is writing the atoms (on FAUST, 6890 × 1032,
    ~1.5× faster inside the pipeline than the product → max → compare passes over a fresh
    ``g``).  The last block is shifted left to end at column ``q`` (recomputing a few columns
    with the same values) instead of padding, so no copy is needed to cut the result.
    """
    n, q = evecs.shape[0], coeffs.shape[1]
    w = int(max(1, min(q, BINARIZE_BLOCK_ELEMS // max(n, 1))))
    n_blocks = -(-q // w)

    dtype = jnp.result_type(evecs, coeffs)
    if n_blocks == 1:
        return kernel_mask(evecs, coeffs, gammas).astype(dtype)

    def body(i, out):
        start = jnp.minimum(i * w, q - w)
        cb = jax.lax.dynamic_slice_in_dim(coeffs, start, w, axis=1)
        gb = jax.lax.dynamic_slice_in_dim(gammas, start, w, axis=0)
        atoms = kernel_mask(evecs, cb, gb).astype(dtype)
        return jax.lax.dynamic_update_slice_in_dim(out, atoms, start, axis=1)

    return jax.lax.fori_loop(0, n_blocks, body, jnp.zeros((n, q), dtype))


def transfer_coeffs(C, coeffs):
    """``C · coeffs[:k_M]``: a frame's kernel coefficients carried through a map (Eq. 11)."""
    return jnp.matmul(C, coeffs[:C.shape[1]], precision=jax.lax.Precision.HIGHEST)


transfer_coeffs_jit = jax.jit(transfer_coeffs)


@jax.jit
def carry_dense(C, coeffs, evecs, gammas):
    """Paper Eq. 11–12 in one call: ``a_N = C a`` and the atoms of ``Φ_N[:, :k_N] a_N``."""
    a = transfer_coeffs(C, coeffs)
    return a, binarize(evecs[:, :a.shape[0]], a, gammas)




def build_core(evals, evecs, mass, centers, taus, gammas, unit_area: bool):
    """Algorithm 1 for ``S`` scales × ``C`` centres at once.

    Shapes: evals ``(k,)``, evecs ``(n, k)``, mass ``(n,)``, centers ``(C,)``, taus ``(S,)``,
    gammas ``(S,)``.  Returns atoms ``(n, S·C)`` and coeffs ``(k, S·C)``, scale-major.
    """
    coeffs = kernel_coeffs(evals, evecs, mass, centers, taus, unit_area)
    gcols = jnp.repeat(gammas, centers.shape[0])  # (S·C,)
    return binarize(evecs, coeffs, gcols), coeffs


build_core_jit = jax.jit(build_core, static_argnames="unit_area")
