"""A scan made ready for its spectrum: one sequence of cleaning steps, in one place.

Owner of [`prepare_scan`][bsfjax.prepare_scan] and [`PreparedScan`][bsfjax.PreparedScan]:
`bsfjax transfer` and [`transfer_collection`][bsfjax.transfer_collection] run it on the source
and on every target, and a user of the array-level functions runs it before
[`spectrum`][bsfjax.spectrum].  The steps, in order: the main body is split from the other
components ([`split_main_body`][bsfjax.split_main_body]: one zero eigenvalue), then smoothed
([`denoise`][bsfjax.denoise]: the same vertices, moved), then its holes are closed
([`fill_holes`][bsfjax.fill_holes]: new vertices and triangles after the original ones, for
the spectrum only).  Results computed on ``PreparedScan.mesh`` go back to the mesh as read with
``PreparedScan.to_whole`` (the added vertices dropped).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._components import MainBody, split_main_body
from ._denoise import as_strength, auto_iterations, denoise, denoise_iterations, noise_level
from ._holes import HoleFill, fill_holes as _fill
from ._mesh import Mesh
from ._interop import as_mesh

#: A hole whose patch would cover more than this share of the mesh's area (``π ρ²``, ``ρ`` the
#: loop's mean distance to its centroid) is left open: an open half-scan, not a hole.
FILL_MAX_SHARE = 0.2

__all__ = ["FILL_MAX_SHARE", "PreparedScan", "prepare_scan"]


class PreparedScan(NamedTuple):
    """What [`prepare_scan`][bsfjax.prepare_scan] made of a mesh.

    **Attributes:**

    - `mesh`: the geometry the spectrum, the map and the transfer use: the main body, denoised,
      its holes closed.  Its first ``body.n_vertices`` vertices (triangles) are the main
      body's, in order (``parts.vertices`` of the mesh as read); the patches' come after.
    - `parts`: the split ([`MainBody`][bsfjax.MainBody]); ``parts.whole`` is the mesh as read.
    - `noise_level`: the main body's [`noise_level`][bsfjax.noise_level] when the strength was
      ``"auto"``, else ``None`` (not measured).
    - `denoise_iterations`: the Taubin iterations run (0: none).
    - `fill`: the closed holes ([`HoleFill`][bsfjax.HoleFill]; ``fill.original`` is ``body``),
      or ``None`` when none were closed.
    """

    mesh: Mesh
    parts: MainBody
    noise_level: float | None
    denoise_iterations: int
    fill: HoleFill | None = None

    @property
    def body(self) -> Mesh:
        """The main body, denoised, without the patches: the mesh whose file rows
        (``from_file_rows``, ``file_row_index``) read inputs onto ``mesh``'s first vertices."""
        return self.mesh if self.fill is None else self.fill.original

    @property
    def n_added(self) -> int:
        """Vertices the hole patches added to ``mesh`` (0: none)."""
        return 0 if self.fill is None else self.fill.n_added

    def extend(self, values, *, faces: bool = False) -> np.ndarray:
        """Values on ``body`` (first axis: its vertices, or triangles with ``faces``) on
        ``mesh``: each added vertex (triangle) takes the value of the nearest original one on
        its hole's boundary."""
        return np.asarray(values) if self.fill is None else self.fill.extend(values, faces=faces)

    def restrict(self, values, *, faces: bool = False) -> np.ndarray:
        """Values on ``mesh`` on ``body``: the added vertices (triangles) dropped."""
        return np.asarray(values) if self.fill is None else self.fill.restrict(values,
                                                                               faces=faces)

    @property
    def whole(self) -> Mesh:
        """The mesh as read."""
        return self.parts.whole

    def to_whole(self, values, fill=None, *, faces: bool = False) -> np.ndarray:
        """Values on ``mesh`` (first axis: its vertices, or triangles with ``faces``; or on
        ``body``) on the mesh as read: the added vertices dropped, then
        [`MainBody.to_whole`][bsfjax.MainBody.to_whole]."""
        v = np.asarray(values)
        if self.fill is not None and v.shape[:1] == ((self.mesh.n_faces,) if faces else
                                                      (self.mesh.n_vertices,)):
            v = self.fill.restrict(v, faces=faces)
        return self.parts.to_whole(v, fill, faces=faces)

    def summary(self, role: str = "mesh") -> str:
        """One line on the smoothing, e.g. ``target noise level 0.292, 9 Taubin iterations``."""
        level = "" if self.noise_level is None else f" noise level {self.noise_level:.3f},"
        return f"{role}{level} {self.denoise_iterations} Taubin iterations"

    def fill_summary(self, role: str = "mesh") -> str:
        """One line on the closed holes, e.g. ``target: 5 holes closed for the spectrum (212
        vertices added, not labelled)``."""
        if self.fill is None:
            return f"{role}: no holes"
        return (f"{role}: {len(self.fill.loops)} holes closed for the spectrum "
                f"({self.n_added} vertices added, not labelled)")


def prepare_scan(mesh: Mesh, denoise_strength=True, fill_holes=True) -> PreparedScan:
    """Make a mesh as read (a scan, a registration, a point cloud) ready for its spectrum.

    1. [`split_main_body`][bsfjax.split_main_body]: only the largest connected component by
       area is matched; the other components take the value of the nearest main-body vertex
       afterwards (``to_whole``).
    2. [`denoise`][bsfjax.denoise] the main body: Taubin smoothing with a strength from its
       [`noise_level`][bsfjax.noise_level] (none on a clean mesh); the vertices keep their
       order, so values on the result belong to the vertices as read.
    3. [`fill_holes`][bsfjax.fill_holes]: every boundary loop (a hole, a cut limb's stump)
       is closed by a smooth patch of new vertices (after the original ones), so the spectrum
       is nearly that of the closed surface; outputs drop them (``to_whole``).  A loop whose
       patch would cover more than ``FILL_MAX_SHARE`` (20 %) of the area stays open.

    **Arguments:**

    - `mesh`: a [`Mesh`][bsfjax.Mesh] (or [`PointCloud`][bsfjax.PointCloud]) as read.
    - `denoise_strength`: ``True`` (default) or ``"auto"``: the strength from the noise level;
      ``False`` / ``0``: no smoothing; an integer: that many Taubin iterations.
    - `fill_holes`: ``True`` (default): close every hole; ``False``: leave them open.

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
    body = denoise(parts.mesh, n_it)
    fill = None
    if fill_holes and not body.is_point_cloud:
        fill = _fill(body, max_share=FILL_MAX_SHARE)
        fill = fill if fill.n_added_faces else None
    return PreparedScan(body if fill is None else fill.mesh, parts, level, n_it, fill)
