"""The spectrum stage: the Laplace–Beltrami eigenpairs of a mesh.

Cotangent stiffness `W` and lumped mass `A` (`laplacian`), then the first `k` solutions of
`W φ = λ A φ` with `Φᵀ A Φ = I` (`spectrum`): dense LAPACK for small meshes, a block Lanczos
with CHOLMOD shift-invert for large ones, ARPACK otherwise, and an approximate mode.  NumPy /
SciPy in float64; everything after the eigenbasis is JAX.
"""

from ._factorize import has_cholmod
from ._laplacian import cotangent_stiffness, laplacian, mass_matrix
from ._spectrum import interval_operators, interval_spectrum, spectrum, spectrum_from_operators
from ._spectrum_type import (
    Spectrum, map_to_unit_area, stack_spectra, unit_area, unit_area_pair,
)

__all__ = [
    "Spectrum", "cotangent_stiffness", "has_cholmod", "interval_operators", "interval_spectrum",
    "laplacian", "map_to_unit_area", "mass_matrix", "spectrum", "spectrum_from_operators",
    "stack_spectra", "unit_area", "unit_area_pair",
]
