"""The Binary Sparse Frame (paper Sec. 4, Algorithm 1).

Owner of: ``Frame``, ``build_frame``, ``transfer_frame``.
"""

from __future__ import annotations

import equinox as eqx
import jax

__all__ = ["Frame"]


class Frame(eqx.Module):
    """A Binary Sparse Frame on one shape: ``q`` binary atoms and where they came from.

    Column order: scale-major — column ``s * n_centers + c`` is the atom of scale ``taus[s]``
    centred at ``centers[c]``; ``Frame.taus`` and ``Frame.centers`` give both per column.

    Attributes:
        atoms: ``(n, q)`` binary matrix B (0/1 in the float dtype), one atom per column.
        coeffs: ``(k, q)`` spectral coefficients ĝ ⊙ Φ[x, :] of the Gaussian behind each atom
            (the quantity a functional map transports, paper Eq. 11).
        taus: ``(q,)`` diffusion scale τ of each column (as given by the caller).
        centers: ``(q,)`` int vertex index of each column's centre.
        mass: ``(n,)`` vertex areas of the shape (for area-weighted coding and metrics).
    """

    atoms: jax.Array
    coeffs: jax.Array
    taus: jax.Array
    centers: jax.Array
    mass: jax.Array

    @property
    def n_vertices(self) -> int:
        return int(self.atoms.shape[-2])

    @property
    def n_atoms(self) -> int:
        return int(self.atoms.shape[-1])
