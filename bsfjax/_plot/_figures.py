"""Figures: functions, segmentations, errors and atoms on meshes; the paper's 1D figures.

Every function returns a `matplotlib.figure.Figure` and, given ``path=``, also writes it
(format from the suffix, PNG by default) atomically.  Figures are built with
``matplotlib.figure.Figure`` on an Agg canvas, never through ``pyplot``: this module never
changes matplotlib's global backend, so it works headless and leaves a notebook's inline backend
alone.  In a notebook the returned figure displays itself (it has a ``_repr_png_``).

Meshes are drawn by a small software renderer: vertices are projected orthographically onto the
view plane, triangles facing away from the camera are dropped (on a closed, consistently
oriented mesh; otherwise all are drawn, lit on both sides), the rest are painted back to front
(painter's algorithm) as one ``PolyCollection``, each with its colour times a Lambert shading
factor ``ambient + (1 − ambient)·max(0, n·l)`` of its face normal ``n`` and a fixed light ``l``.
This draws a 7K-vertex mesh in a fraction of a second per view, much faster than mplot3d.

Views: ``"front"``, ``"back"``, ``"left"`` (the mesh's ``+x`` side; alias ``"side"``),
``"right"``, ``"top"``, ``"bottom"``, ``"iso"``, or an ``(azimuth, elevation)`` pair in degrees.
``up`` names the world axis that points up on screen: ``"y"`` (default; FAUST, SMPL and
[`bsfjax.example_pair`][bsfjax.example_pair] meshes), ``"z"`` (TOSCA), ``"x"`` or a negated axis (``"-y"``).
``"front"`` looks at the ``+z`` side of a ``y``-up mesh and at the ``−y`` side of a ``z``-up mesh.

Import it as a submodule (``from bsfjax import plot``); ``import bsfjax`` alone does not import
matplotlib.
"""

from __future__ import annotations

import io
import os
from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.collections import PolyCollection
from matplotlib.colors import (BoundaryNorm, Colormap, LinearSegmentedColormap, ListedColormap,
                               Normalize)
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from .._util import atomic_path
from .._util import BSFError
from .._mesh import Mesh

__all__ = [
    "VIEWS",
    "plot_function",
    "plot_segmentation",
    "plot_error",
    "plot_atoms",
    "plot_1d_atoms",
    "plot_1d_approximation",
]

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
_GREY = np.array([0.72, 0.72, 0.72])
_PANEL_INCHES = 3.0


class _Figure(Figure):
    """A Figure on an Agg canvas that notebooks display without pyplot."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        FigureCanvasAgg(self)

    def _repr_png_(self) -> bytes:
        buf = io.BytesIO()
        self.savefig(buf, format="png")
        return buf.getvalue()


# --------------------------------------------------------------------------------------------
# validation helpers


def _check_mesh(mesh) -> Mesh:
    if not isinstance(mesh, Mesh):
        raise BSFError(f"mesh must be a bsfjax.Mesh, got {type(mesh).__name__}")
    return mesh


def _per_vertex(name: str, values, mesh: Mesh, *, allow_faces: bool = False,
                allow_2d: bool = False) -> np.ndarray:
    a = np.asarray(values)
    n, m = mesh.n_vertices, mesh.n_faces
    ok_len = (n, m) if allow_faces else (n,)
    if a.ndim == 0 or a.ndim > (2 if allow_2d else 1) or a.shape[0] not in ok_len:
        want = f"n_vertices={n}" + (f" (or n_faces={m})" if allow_faces else "")
        raise BSFError(f"{name} must have length {want}"
                       f"{' and 1 or 2 dimensions' if allow_2d else ' and be 1-D'}, "
                       f"got shape {a.shape}")
    if not (np.issubdtype(a.dtype, np.number) or a.dtype == bool):
        raise BSFError(f"{name} must be numeric, got dtype {a.dtype}")
    return a


def _float_array(name: str, values) -> np.ndarray:
    try:
        return np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        raise BSFError(f"{name} must be a numeric array, got {type(values).__name__}") from None


def _check_1d(name: str, values, n: int | None = None) -> np.ndarray:
    a = _float_array(name, values)
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"shape ({n},)" if n is not None else "1 dimension"
        raise BSFError(f"{name} must have {want}, got {a.shape}")
    return a


def _check_2d(name: str, values, n: int) -> np.ndarray:
    a = _float_array(name, values)
    if a.ndim == 1 and a.shape[0] == n:
        a = a[:, None]
    if a.ndim != 2 or a.shape[0] != n or a.shape[1] == 0:
        raise BSFError(f"{name} must have shape ({n}, k) with k >= 1, got {np.shape(values)}")
    return a


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


def _cmap(cmap) -> Colormap:
    if isinstance(cmap, Colormap):
        return cmap
    try:
        return colormaps[cmap]
    except KeyError:
        raise BSFError(f"cmap: unknown colormap {cmap!r}") from None


# --------------------------------------------------------------------------------------------
# the renderer


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


def _face_values(values: np.ndarray, faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Per-face value: the face's own value, or the mean of its vertices' (NaN-propagating)."""
    if values.shape[0] == faces.shape[0] and values.shape[0] != n_vertices:
        return values.astype(np.float64)
    return values.astype(np.float64)[faces].mean(axis=1)


def _face_labels(labels: np.ndarray, faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """Per-face label: the majority label of its three vertices (the first when all differ)."""
    if labels.shape[0] == faces.shape[0] and labels.shape[0] != n_vertices:
        return labels
    a, b, c = labels[faces].T
    return np.where((a == b) | (a == c), a, np.where(b == c, b, a))


def _new_figure(n_panels: int, figsize, dpi: float, extra_width: float = 0.0) -> Figure:
    if figsize is None:
        figsize = (_PANEL_INCHES * n_panels + extra_width, _PANEL_INCHES * 1.25)
    try:
        w, h = (float(x) for x in figsize)
    except (TypeError, ValueError):
        raise BSFError(f"figsize must be (width, height) in inches, got {figsize!r}") from None
    if not (w > 0 and h > 0 and np.isfinite(w) and np.isfinite(h)):
        raise BSFError(f"figsize must be positive, got {figsize!r}")
    if not (np.isfinite(dpi) and dpi > 0):
        raise BSFError(f"dpi must be positive, got {dpi!r}")
    return _Figure(figsize=(w, h), dpi=dpi, layout="constrained")


def _finish(fig: Figure, path) -> Figure:
    if path is not None:
        fmt = os.path.splitext(os.fspath(path))[1].lstrip(".").lower() or "png"
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=fmt, dpi=fig.dpi)
    return fig


def _value_range(vals: np.ndarray, vmin, vmax) -> tuple[float, float]:
    """The colour range: the given limits, else the finite data range (a constant is centred)."""
    finite = vals[np.isfinite(vals)]
    lo = float(vmin) if vmin is not None else (float(finite.min()) if finite.size else 0.0)
    hi = float(vmax) if vmax is not None else (float(finite.max()) if finite.size else 1.0)
    if not (np.isfinite(lo) and np.isfinite(hi)) or hi < lo:
        raise BSFError(f"vmin and vmax must be finite with vmin <= vmax, got vmin={lo}, vmax={hi}")
    if hi == lo:
        lo, hi = lo - 0.5, hi + 0.5
    return lo, hi


def _mesh_panels(mesh: Mesh, face_vals, *, views, up, cmap, norm, title, colorbar, cbar_label,
                 figsize, dpi, path, legend=None):
    """One panel per view of the mesh coloured by per-face values, plus colour bar / legend."""
    scene = Scene(mesh, views, up)
    nv = len(scene.views)
    fig = _new_figure(nv, figsize, dpi, extra_width=0.9 if (colorbar or legend) else 0.0)
    axes = fig.subplots(1, nv, squeeze=False)[0]
    rgb = _colours(face_vals, cmap, norm)
    for k, ax in enumerate(axes):
        scene.draw(ax, k, rgb, scene.views[k][0] if nv > 1 else None)
    if title:
        fig.suptitle(title)
    if colorbar:
        sm = ScalarMappable(norm=norm, cmap=cmap)
        fig.colorbar(sm, ax=list(axes), shrink=0.75, label=cbar_label)
    if legend:
        fig.legend(handles=legend, loc="outside right upper", fontsize=8, frameon=False)
    return _finish(fig, path)


def _colours(face_vals: np.ndarray, cmap: Colormap, norm) -> np.ndarray:
    rgb = np.asarray(cmap(norm(np.where(np.isfinite(face_vals), face_vals, 0.0))))[:, :3]
    rgb[~np.isfinite(face_vals)] = _GREY  # NaN: no value
    return rgb


# --------------------------------------------------------------------------------------------
# mesh figures


def plot_function(mesh: Mesh, values, views=("front", "side"), *, cmap="viridis",
                  vmin: float | None = None, vmax: float | None = None, title: str | None = None,
                  colorbar: bool = True, label: str | None = None, up: str = "y",
                  figsize=None, dpi: float = 100, path=None) -> Figure:
    """A scalar function on a mesh, flat-shaded, seen from several views.

    Args:
        mesh: the surface.
        values: ``(n_vertices,)`` per-vertex values (a face shows the mean of its vertices) or
            ``(n_faces,)`` per-face values.  NaN shows grey.
        views: view names or ``(azimuth, elevation)`` pairs, one panel each.
        cmap, vmin, vmax: colour map and its range (default: the data's finite range).
        title, colorbar, label: figure title, whether to draw a colour bar, its label.
        up: the world axis pointing up on screen (``"y"``, ``"z"``, ``"x"``, ``"-y"``, ...).
        figsize, dpi: figure size in inches (default 3 × 3.75 per panel) and resolution; a saved
            PNG is ``figsize · dpi`` pixels.
        path: if given, the figure is also written there (atomically).
    """
    mesh = _check_mesh(mesh)
    vals = _per_vertex("values", values, mesh, allow_faces=True).astype(np.float64)
    fv = _face_values(vals, mesh.faces, mesh.n_vertices)
    lo, hi = _value_range(vals, vmin, vmax)
    return _mesh_panels(mesh, fv, views=views, up=up, cmap=_cmap(cmap), norm=Normalize(lo, hi),
                        title=title, colorbar=colorbar, cbar_label=label, figsize=figsize,
                        dpi=dpi, path=path)


def label_colour(label: np.ndarray) -> np.ndarray:
    """A fixed colour per label value (so the same part has one colour in every figure)."""
    pal = np.asarray(colormaps["tab10"].colors + colormaps["tab20b"].colors[::2]
                     + colormaps["tab20c"].colors[::2])[:, :3]
    out = pal[np.mod(label, len(pal))]
    out[label < 0] = _GREY
    return out


def plot_segmentation(mesh: Mesh, labels, views=("front", "side"), *,
                      label_names: Sequence[str] | Mapping[int, str] | None = None,
                      title: str | None = None, legend: bool = True, up: str = "y",
                      figsize=None, dpi: float = 100, path=None) -> Figure:
    """A segmentation (integer part label per vertex or per face) in categorical colours.

    Label ``l >= 0`` always gets the same colour (tab10 first), so a ground-truth and a
    transferred segmentation plotted separately are comparable; ``−1`` (unassigned) is grey.
    A face takes the majority label of its vertices.  The legend names each label present,
    from ``label_names`` (a sequence indexed by label, or a mapping) when given.
    """
    mesh = _check_mesh(mesh)
    lab = _per_vertex("labels", labels, mesh, allow_faces=True)
    if lab.dtype == bool:
        lab = lab.astype(np.int64)
    if not np.issubdtype(lab.dtype, np.integer):
        if not np.all(np.isfinite(lab)) or not np.all(np.mod(lab, 1) == 0):
            raise BSFError(f"labels must be integers (−1 for unassigned), got dtype {lab.dtype}")
        lab = lab.astype(np.int64)
    if np.any(lab < -1):
        raise BSFError(f"labels must be >= −1 (−1 = unassigned), found {int(lab.min())}")
    fl = _face_labels(lab.astype(np.int64), mesh.faces, mesh.n_vertices)
    present = np.unique(lab)
    handles = None
    if legend:
        handles = []
        for l in present:
            if l < 0:
                name = "unassigned"
            elif label_names is None:
                name = str(int(l))
            elif isinstance(label_names, Mapping):
                name = str(label_names.get(int(l), int(l)))
            else:
                name = str(label_names[l]) if l < len(label_names) else str(int(l))
            handles.append(Patch(color=label_colour(np.array([l]))[0], label=name))
    rgb_table = ListedColormap(label_colour(np.arange(-1, max(int(lab.max()), 0) + 1)))
    norm = BoundaryNorm(np.arange(-1.5, max(int(lab.max()), 0) + 1.5), rgb_table.N)
    return _mesh_panels(mesh, fl.astype(np.float64), views=views, up=up, cmap=rgb_table,
                        norm=norm, title=title, colorbar=False, cbar_label=None,
                        figsize=figsize, dpi=dpi, path=path, legend=handles)


def plot_error(mesh: Mesh, reference, estimate, views=("front", "side"), *, cmap="hot_r",
               vmax: float | None = None, title: str | None = None, colorbar: bool = True,
               up: str = "y", figsize=None, dpi: float = 100, path=None) -> Figure:
    """The per-vertex error between a reference and an estimate.

    ``e_i = |reference_i − estimate_i|`` for 1-D real arrays, ``‖reference_i − estimate_i‖₂``
    for ``(n, c)`` arrays, and the mismatch indicator ``[reference_i ≠ estimate_i]`` when both
    are integer arrays (labels).  The colour scale starts at 0; the default title gives the
    mean error.
    """
    mesh = _check_mesh(mesh)
    ref = _per_vertex("reference", reference, mesh, allow_faces=True, allow_2d=True)
    est = _per_vertex("estimate", estimate, mesh, allow_faces=True, allow_2d=True)
    if ref.shape != est.shape:
        raise BSFError(f"reference and estimate must have the same shape, got {ref.shape} "
                       f"and {est.shape}")
    ints = all(np.issubdtype(a.dtype, np.integer) or a.dtype == bool for a in (ref, est))
    if ints:
        err = (ref != est).astype(np.float64)
        if err.ndim == 2:
            err = err.max(axis=1)
        what = "mismatch"
    else:
        d = ref.astype(np.float64) - est.astype(np.float64)
        err = np.abs(d) if d.ndim == 1 else np.linalg.norm(d, axis=1)
        what = "|error|"
    fv = _face_values(err, mesh.faces, mesh.n_vertices)
    hi = float(np.nanmax(err)) if vmax is None else float(vmax)
    if not np.isfinite(hi) or hi <= 0:
        hi = 1.0
    if title is None:
        title = f"mean {what} = {np.nanmean(err):.4g}"
    return _mesh_panels(mesh, fv, views=views, up=up, cmap=_cmap(cmap), norm=Normalize(0.0, hi),
                        title=title, colorbar=colorbar, cbar_label=what, figsize=figsize,
                        dpi=dpi, path=path)


_ATOM_CMAP = LinearSegmentedColormap.from_list("bsf_atom", [(0.82, 0.82, 0.82), (0.80, 0.12, 0.15)])


def plot_atoms(mesh: Mesh, atoms, taus, view="front", *, center: int | None = None,
               title: str | None = None, up: str = "y", figsize=None, dpi: float = 100,
               path=None) -> Figure:
    """The atoms of one centre at each scale: one panel per scale ``taus[s]``.

    Args:
        atoms: ``(n_vertices, s)`` atoms (binary: the atom's support is red, the rest grey;
            real values are shaded from grey at 0 to red at their maximum).
        taus: ``(s,)`` the scale of each column, shown in the panel titles.
        view: one view for every panel.
        center: the centre vertex, marked with a black dot where it faces the camera.
    """
    mesh = _check_mesh(mesh)
    B = _check_2d("atoms", atoms, mesh.n_vertices)
    t = _check_1d("taus", taus, B.shape[1])
    vw = _views(view)
    if len(vw) != 1:
        raise BSFError(f"view must be a single view, got {view!r}")
    if center is not None and not (isinstance(center, (int, np.integer))
                                   and 0 <= center < mesh.n_vertices):
        raise BSFError(f"center must be a vertex index in [0, {mesh.n_vertices}), got {center!r}")
    s = B.shape[1]
    scene = Scene(mesh, [vw[0][1]], up)
    fig = _new_figure(s, figsize, dpi)
    axes = fig.subplots(1, s, squeeze=False)[0]
    hi = float(np.nanmax(B)) if np.nanmax(B) > 0 else 1.0
    norm = Normalize(0.0, hi)
    for j, ax in enumerate(axes):
        rgb = _colours(_face_values(B[:, j], mesh.faces, mesh.n_vertices), _ATOM_CMAP, norm)
        p = scene.draw(ax, 0, rgb, f"τ = {t[j]:.3g}")
        if center is not None and scene.visible(0, int(center)):
            ax.plot(p[center, 0], p[center, 1], "o", ms=5, mfc="k", mec="w", mew=0.8)
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


# --------------------------------------------------------------------------------------------
# 1D figures (paper Fig. 1 and Fig. 5)


def plot_1d_atoms(x, fourier_basis, bsf_atoms, *, stacked: bool = True,
                  titles=("Fourier basis (Laplacian eigenfunctions)", "BSF binary atoms"),
                  title: str | None = None, figsize=None, dpi: float = 100, path=None) -> Figure:
    """Laplacian eigenfunctions next to binary atoms on an interval (paper Fig. 1).

    Args:
        x: ``(n,)`` sample positions.
        fourier_basis: ``(n, k)`` eigenfunctions, one curve each.
        bsf_atoms: ``(n, q)`` atoms, drawn as steps.
        stacked: draw each curve on its own baseline (offset upwards) instead of overlapping.
    """
    xs = _check_1d("x", x)
    n = xs.shape[0]
    Phi = _check_2d("fourier_basis", fourier_basis, n)
    B = _check_2d("bsf_atoms", bsf_atoms, n)
    fig = _new_figure(2, figsize if figsize is not None else (9.0, 4.0), dpi)
    axes = fig.subplots(1, 2, squeeze=False)[0]
    for ax, M, steps, name in zip(axes, (Phi, B), (False, True), titles):
        span = float(np.nanmax(np.ptp(M, axis=0))) if M.size else 1.0
        gap = 1.25 * (span if span > 0 else 1.0)
        colors = colormaps["tab10"].colors
        for j in range(M.shape[1]):  # a loop over the few curves drawn, not over data
            off = j * gap if stacked else 0.0
            ax.plot(xs, M[:, j] + off, color=colors[j % 10], lw=1.4,
                    drawstyle="steps-mid" if steps else "default")
            if stacked:
                ax.axhline(off, color="0.85", lw=0.6, zorder=0)
        ax.set_title(name, fontsize=10)
        ax.set_xlabel("x")
        if stacked:
            ax.set_yticks([])
    if title:
        fig.suptitle(title)
    return _finish(fig, path)


def plot_1d_approximation(x, f, approximations: Mapping[str, np.ndarray],
                          errors: Mapping[str, float] | None = None, *,
                          title: str | None = None, figsize=None, dpi: float = 100,
                          path=None) -> Figure:
    """A step function and its approximations on an interval (paper Fig. 5).

    Args:
        x: ``(n,)`` sample positions.
        f: ``(n,)`` the function (drawn as a thick black step line).
        approximations: name -> ``(n,)`` approximation, e.g. ``{"Fourier k=10": ..., "BSF": ...}``.
        errors: optional name -> error, appended to the legend entries.
    """
    xs = _check_1d("x", x)
    n = xs.shape[0]
    fv = _check_1d("f", f, n)
    if not isinstance(approximations, Mapping) or not approximations:
        raise BSFError("approximations must be a non-empty mapping name -> (n,) array, "
                       f"got {type(approximations).__name__}")
    approx = {str(k): _check_1d(f"approximations[{k!r}]", v, n) for k, v in approximations.items()}
    if errors is not None:
        if not isinstance(errors, Mapping):
            raise BSFError("errors must be a mapping name -> float or None, "
                           f"got {type(errors).__name__}")
        unknown = set(map(str, errors)) - set(approx)
        if unknown:
            raise BSFError(f"errors has names not in approximations: {sorted(unknown)}")
    fig = _new_figure(1, figsize if figsize is not None else (7.0, 3.5), dpi)
    ax = fig.subplots()
    ax.plot(xs, fv, color="k", lw=2.6, drawstyle="steps-mid", label="f", zorder=1)
    colors = colormaps["tab10"].colors
    for j, (name, a) in enumerate(approx.items()):
        lab = name
        if errors is not None and name in {str(k) for k in errors}:
            err = {str(k): v for k, v in errors.items()}[name]
            lab = f"{name} (error {float(err):.3g})"
        ax.plot(xs, a, color=colors[j % 10], lw=1.5, label=lab, zorder=2 + j)
    ax.set_xlabel("x")
    ax.legend(fontsize=8, frameon=False)
    if title:
        ax.set_title(title)
    return _finish(fig, path)
