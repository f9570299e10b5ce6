"""The software renderer of the mesh figures. Owner of the named `VIEWS` and their validation
(`_views`), the up-axis frame and orthographic cameras, and `Scene`, which projects one mesh
into several views once and paints each as back-to-front, Lambert-shaded triangles (back faces
culled on a closed, consistently oriented mesh); the method is described in
`bsfjax._plot._figures`.
"""

from __future__ import annotations

import numpy as np
from matplotlib.collections import PolyCollection

from .._util import BSFError
from .._mesh import Mesh

__all__ = ["Scene", "VIEWS"]

#: Named views: (azimuth, elevation) in degrees about the up axis.
VIEWS: dict[str, tuple[float, float]] = {
    "front": (0.0, 0.0),
    "back": (180.0, 0.0),
    "left": (90.0, 0.0),
    "side": (90.0, 0.0),
    "right": (-90.0, 0.0),
    "top": (0.0, 90.0),
    "bottom": (0.0, -90.0),
    "iso": (35.0, 20.0),
}

# up axis -> (up vector, direction the "front" camera sits in)
_UP = {
    "z": ((0, 0, 1), (0, -1, 0)), "-z": ((0, 0, -1), (0, -1, 0)),
    "y": ((0, 1, 0), (0, 0, 1)), "-y": ((0, -1, 0), (0, 0, 1)),
    "x": ((1, 0, 0), (0, -1, 0)), "-x": ((-1, 0, 0), (0, -1, 0)),
}
_LIGHT = np.array([-0.35, 0.5, 1.0]) / np.linalg.norm([-0.35, 0.5, 1.0])  # camera coordinates
_AMBIENT = 0.3


def _views(views) -> list[tuple[str, tuple[float, float]]]:
    if isinstance(views, str) or (isinstance(views, tuple) and len(views) == 2
                                  and all(isinstance(v, (int, float)) for v in views)):
        views = [views]
    out = []
    for v in views:
        if isinstance(v, str):
            if v not in VIEWS:
                raise BSFError(f"views: unknown view {v!r}; use one of {sorted(VIEWS)} or an "
                               "(azimuth, elevation) pair in degrees")
            out.append((v, VIEWS[v]))
        else:
            try:
                az, el = (float(x) for x in v)
            except (TypeError, ValueError):
                raise BSFError("views: each view must be a name or (azimuth, elevation), "
                               f"got {v!r}") from None
            out.append((f"az {az:g}°, el {el:g}°", (az, el)))
    if not out:
        raise BSFError("views must name at least one view")
    return out


def _up_frame(vertices: np.ndarray, up: str) -> np.ndarray:
    """Rows: world -> canonical frame in which +z is up and the front camera sits at −y."""
    if not isinstance(up, str) or up not in _UP:
        raise BSFError(f"up must be one of {sorted(_UP)}, got {up!r}")
    ez, front = (np.asarray(a, dtype=np.float64) for a in _UP[up])
    ey = -front
    ex = np.cross(ey, ez)
    return np.stack([ex, ey, ez])


def _camera(az: float, el: float) -> np.ndarray:
    """Rows (right, up, towards the viewer) of a camera at azimuth/elevation, canonical frame."""
    t, p = np.deg2rad(az), np.deg2rad(el)
    d = np.array([np.sin(t) * np.cos(p), -np.cos(t) * np.cos(p), np.sin(p)])
    r = np.array([np.cos(t), np.sin(t), 0.0])
    return np.stack([r, np.cross(d, r), d])


def _orientation(faces: np.ndarray) -> tuple[bool, bool]:
    """(oriented, closed): every directed edge occurs once; and every edge has its twin."""
    he = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = int(faces.max()) + 1
    key = he[:, 0] * n + he[:, 1]
    rev = he[:, 1] * n + he[:, 0]
    if np.unique(key).size != key.size:
        return False, False
    return True, bool(np.isin(rev, key).all())


class Scene:
    """Projection of one mesh into several views (computed once per figure)."""

    def __init__(self, mesh: Mesh, views, up: str):
        v = mesh.vertices
        self.faces = mesh.faces
        self.frame = _up_frame(v, up)
        self.canon = (v - v.mean(axis=0)) @ self.frame.T
        self.views = _views(views)
        oriented, closed = _orientation(mesh.faces)
        self.cull = oriented and closed
        f = mesh.faces
        e1 = self.canon[f[:, 1]] - self.canon[f[:, 0]]
        e2 = self.canon[f[:, 2]] - self.canon[f[:, 0]]
        nrm = np.cross(e1, e2)
        if self.cull:
            # outward orientation: positive signed volume; flip the normals of inside-out meshes
            c = self.canon[f]
            vol = np.einsum("ij,ij->i", c[:, 0], np.cross(c[:, 1], c[:, 2])).sum()
            if vol < 0:
                nrm = -nrm
        self.normals = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        # shading normal: the mean of the face's area-weighted vertex normals, which hides the
        # faceting of fine meshes (a face still has one colour)
        vn = np.stack([np.bincount(f.ravel(), np.repeat(nrm[:, c], 3), minlength=len(v))
                       for c in range(3)], axis=1)
        vn /= np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-300)
        sn = vn[f].sum(axis=1)
        self.shading = sn / np.maximum(np.linalg.norm(sn, axis=1, keepdims=True), 1e-300)
        if not oriented:  # neighbours' normals may point opposite ways: keep the face normals
            self.shading = self.normals
        self.proj = [self.canon @ _camera(*ve).T for _, ve in self.views]
        lo = np.min([p[:, :2].min(axis=0) for p in self.proj], axis=0)
        hi = np.max([p[:, :2].max(axis=0) for p in self.proj], axis=0)
        self.half = 0.52 * np.max(hi - lo)  # a common scale for every panel

    def draw(self, ax, k: int, face_rgb: np.ndarray, title: str | None = None):
        _, (az, el) = self.views[k]
        cam = _camera(az, el)
        p = self.proj[k]
        facing = self.normals @ cam[2]  # towards the viewer
        keep = facing > 0 if self.cull else np.ones(len(facing), dtype=bool)
        lam = (self.shading[keep] @ cam.T) @ _LIGHT
        lam = np.maximum(lam, 0.0) if self.cull else np.abs(lam)  # two-sided if not culled
        shade = _AMBIENT + (1.0 - _AMBIENT) * lam
        f = self.faces[keep]
        depth = p[f, 2].mean(axis=1)
        order = np.argsort(depth, kind="stable")  # far to near
        rgb = np.clip(face_rgb[keep][order] * shade[order, None], 0.0, 1.0)
        tris = p[f[order]][:, :, :2]
        # no antialiasing: triangles a pixel or two wide would blend into moire patterns and
        # leave hairline seams; aliased fills tile the plane exactly
        coll = PolyCollection(tris, facecolors=rgb, edgecolors="none", linewidths=0.0,
                              antialiaseds=False)
        ax.add_collection(coll)
        cx, cy = 0.5 * (p[:, 0].min() + p[:, 0].max()), 0.5 * (p[:, 1].min() + p[:, 1].max())
        ax.set_xlim(cx - self.half, cx + self.half)
        ax.set_ylim(cy - self.half, cy + self.half)
        ax.set_aspect("equal")
        ax.set_axis_off()
        if title:
            ax.set_title(title, fontsize=9)
        return p

    def visible(self, k: int, vertex: int) -> bool:
        """Whether some face at ``vertex`` faces the camera of view ``k``."""
        cam = _camera(*self.views[k][1])
        at = np.any(self.faces == vertex, axis=1)
        return bool(np.any(self.normals[at] @ cam[2] > 0)) or not self.cull
