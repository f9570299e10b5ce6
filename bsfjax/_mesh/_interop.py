"""Meshes from the libraries users hold: [`as_mesh`][bsfjax.as_mesh] turns a
``trimesh.Trimesh`` / ``trimesh.PointCloud``, a pyFM ``TriMesh``, an open3d
``TriangleMesh`` / ``PointCloud`` or a ``(vertices, faces)`` pair into a
[`Mesh`][bsfjax.Mesh] (or [`PointCloud`][bsfjax.PointCloud]).

Duck-typed: none of those libraries is imported here, and none is a dependency.  The
coordinates and triangles are taken as they are (``float64`` / ``int64`` copies, nothing
cleaned, merged or reordered), so vertex ``i`` of the object is vertex ``i`` of the mesh and a
mesh read from the same file by [`load_mesh`][bsfjax.load_mesh] (a file without unreferenced
vertices or zero-area triangles) has bit-identical arrays, spectra and labels.
"""

from __future__ import annotations

import numpy as np

from .._util import MeshError
from ._mesh import Mesh, PointCloud

__all__ = ["as_mesh", "is_mesh_like"]


def _array(x, what: str, where: str) -> np.ndarray:
    try:  # open3d's Vector3dVector / Vector3iVector and trimesh's TrackedArray convert
        return np.asarray(x)
    except (TypeError, ValueError) as exc:
        raise MeshError(f"{where}{what} cannot be read as an array ({exc})") from None


def is_mesh_like(obj) -> bool:
    """Whether [`as_mesh`][bsfjax.as_mesh] takes ``obj`` for a mesh (not for bare points)."""
    return isinstance(obj, Mesh) or _is_pair(obj) or (
        not isinstance(obj, np.ndarray) and (hasattr(obj, "vertices") or hasattr(obj, "points")))


def _is_pair(obj) -> bool:
    return (isinstance(obj, (tuple, list)) and len(obj) == 2
            and all(np.ndim(x) == 2 for x in obj if not isinstance(x, (str, bytes))))


def as_mesh(obj, what: str = "mesh") -> Mesh:
    """A [`Mesh`][bsfjax.Mesh] (or [`PointCloud`][bsfjax.PointCloud]) from what a user holds.

    Accepted, in this order: a `Mesh` (returned as it is); a ``(vertices, faces)`` pair of
    ``(n, 3)`` and ``(m, 3)`` arrays (``faces`` empty or ``None``: a point cloud); an object with
    ``vertices`` and ``faces`` (``trimesh.Trimesh``, pyFM ``TriMesh``); with ``vertices`` and
    ``triangles`` (open3d ``TriangleMesh``); with ``vertices`` only (``trimesh.PointCloud``) or
    ``points`` only (open3d ``PointCloud``): a point cloud.  For the objects, vertex ``i`` is
    row ``i`` of ``vertices`` (no cleaning, so the numbering is the object's).

    **Arguments:**

    - `obj`: the mesh, in one of the forms above.
    - `what`: the argument's name in error messages.

    **Returns:**

    A `Mesh`; a `PointCloud` for points without triangles.  Raises
    [`MeshError`][bsfjax.MeshError] naming `what` for anything else.
    """
    if isinstance(obj, Mesh):
        return obj
    where = f"{what}: "
    name = None
    if _is_pair(obj) or (isinstance(obj, (tuple, list)) and len(obj) == 2 and obj[1] is None):
        v, f = obj
    elif hasattr(obj, "vertices") and hasattr(obj, "faces"):  # trimesh, pyFM
        v, f = obj.vertices, obj.faces  # (before triangles: trimesh's are corner coordinates)
    elif hasattr(obj, "vertices") and hasattr(obj, "triangles"):  # open3d TriangleMesh
        v, f = obj.vertices, obj.triangles
    elif hasattr(obj, "vertices"):  # trimesh.PointCloud
        v, f = obj.vertices, None
    elif hasattr(obj, "points") and not isinstance(obj, np.ndarray):  # open3d PointCloud
        v, f = obj.points, None
    else:
        raise MeshError(f"{what} must be a bsfjax.Mesh, got {type(obj).__name__} (or a trimesh / "
                        "pyFM / open3d mesh or point cloud, or a (vertices, faces) pair)")
    if not isinstance(obj, (tuple, list)):
        name = type(obj).__name__
    v = _array(v, "vertices", where)
    f = None if f is None else _array(f, "faces", where)
    if f is None or f.size == 0:
        return PointCloud(v, name=name)
    return Mesh(v, f, name=name)
