"""bsfjax: Binary Sparse Frames in JAX.

Sparse representation and transfer of step functions on manifolds, after S. Melzi,
"Sparse representation of step functions on manifolds", Computers & Graphics 82 (2019).

Pipeline, one module per stage (data flows downwards only)::

    mesh.py        Mesh, load_mesh, save_mesh
    laplacian.py   laplacian -> (W, A)
    spectrum.py    Spectrum, spectrum, spectrum_from_operators, interval_spectrum
"""

from importlib.metadata import PackageNotFoundError, version as _version

from .errors import BSFError, MeshError
from .laplacian import laplacian
from .mesh import Mesh, load_mesh, save_mesh
from .spectrum import Spectrum, interval_spectrum, spectrum, spectrum_from_operators

try:
    __version__ = _version("bsfjax")
except PackageNotFoundError:  # pragma: no cover - running from a source tree
    __version__ = "0.0.0+unknown"

__all__ = [
    "BSFError",
    "Mesh",
    "MeshError",
    "Spectrum",
    "interval_spectrum",
    "laplacian",
    "load_mesh",
    "save_mesh",
    "spectrum",
    "spectrum_from_operators",
]
