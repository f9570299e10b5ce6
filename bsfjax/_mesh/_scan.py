"""A scan made ready for its spectrum: one sequence of cleaning steps, in one place.

Owner of [`prepare_scan`][bsfjax.prepare_scan] and [`PreparedScan`][bsfjax.PreparedScan]:
`bsfjax transfer` and [`transfer_collection`][bsfjax.transfer_collection] run it on the source
and on every target, and a user of the array-level functions runs it before
[`spectrum`][bsfjax.spectrum].  The steps, in order: the main body is split from the other
components ([`split_main_body`][bsfjax.split_main_body]: one zero eigenvalue), then smoothed
([`denoise`][bsfjax.denoise]: the same vertices, moved).  Results computed on
``PreparedScan.mesh`` go back to the mesh as read with ``PreparedScan.to_whole``.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._components import MainBody, split_main_body
from ._denoise import as_strength, auto_iterations, denoise, denoise_iterations, noise_level
from ._mesh import Mesh
from ._interop import as_mesh

__all__ = ["PreparedScan", "prepare_scan"]


class PreparedScan(NamedTuple):
    """What [`prepare_scan`][bsfjax.prepare_scan] made of a mesh.

    **Attributes:**

    - `mesh`: the geometry the spectrum, the map and the transfer use: the main body, denoised.
      Its vertices are the main body's, in order (``parts.vertices`` of the mesh as read).
    - `parts`: the split ([`MainBody`][bsfjax.MainBody]); ``parts.whole`` is the mesh as read.
    - `noise_level`: the main body's [`noise_level`][bsfjax.noise_level] when the strength was
      ``"auto"``, else ``None`` (not measured).
    - `denoise_iterations`: the Taubin iterations run (0: none).
    """

    mesh: Mesh
    parts: MainBody
    noise_level: float | None
    denoise_iterations: int

    @property
    def whole(self) -> Mesh:
        """The mesh as read."""
        return self.parts.whole

    def to_whole(self, values, fill=None, *, faces: bool = False) -> np.ndarray:
        """Values on ``mesh`` (first axis: its vertices, or triangles with ``faces``) on the mesh
        as read: see [`MainBody.to_whole`][bsfjax.MainBody.to_whole]."""
        return self.parts.to_whole(values, fill, faces=faces)

    def summary(self, role: str = "mesh") -> str:
        """One line on the smoothing, e.g. ``target noise level 0.292, 9 Taubin iterations``."""
        level = "" if self.noise_level is None else f" noise level {self.noise_level:.3f},"
        return f"{role}{level} {self.denoise_iterations} Taubin iterations"


def prepare_scan(mesh: Mesh, denoise_strength=True) -> PreparedScan:
    """Make a mesh as read (a scan, a registration, a point cloud) ready for its spectrum.

    1. [`split_main_body`][bsfjax.split_main_body]: only the largest connected component by
       area is matched; the other components take the value of the nearest main-body vertex
       afterwards (``to_whole``).
    2. [`denoise`][bsfjax.denoise] the main body: Taubin smoothing with a strength from its
       [`noise_level`][bsfjax.noise_level] (none on a clean mesh); the vertices keep their
       order, so values on the result belong to the vertices as read.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh] (or [`PointCloud`][bsfjax.PointCloud]) as read.
    - `denoise_strength`: ``True`` (default) or ``"auto"``: the strength from the noise level;
      ``False`` / ``0``: no smoothing; an integer: that many Taubin iterations.

    **Returns:** a [`PreparedScan`][bsfjax.PreparedScan].
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    parts = split_main_body(mesh)
    strength = as_strength(denoise_strength)
    level = None
    if strength == "auto":
        level = noise_level(parts.mesh)  # once: the iterations follow from it
        n_it = auto_iterations(level)
    else:
        n_it = denoise_iterations(parts.mesh, strength)
    return PreparedScan(denoise(parts.mesh, n_it), parts, level, n_it)
