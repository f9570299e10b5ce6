"""The spectrum stage: cotangent stiffness W and lumped mass A, and the Laplace–Beltrami eigenpairs (λ, Φ)."""

from ._eigensolver import has_cholmod
from ._laplacian import cotangent_stiffness, laplacian, mass_matrix
from ._spectrum import (
    Spectrum, interval_operators, interval_spectrum, map_to_unit_area, spectrum,
    spectrum_from_operators, stack_spectra, unit_area, unit_area_pair,
)

__all__ = [
    "Spectrum", "cotangent_stiffness", "has_cholmod", "interval_operators", "interval_spectrum",
    "laplacian", "map_to_unit_area", "mass_matrix", "spectrum", "spectrum_from_operators",
    "stack_spectra", "unit_area", "unit_area_pair",
]
