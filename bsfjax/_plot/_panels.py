"""Plumbing shared by the public figures of `bsfjax._plot._figures`. Owner of the argument checks
(mesh, per-vertex values, 1-D/2-D arrays, colour maps and ranges), per-face values and labels,
the Agg-backed `_Figure` that needs no pyplot, a row of mesh panels in several views with colour
bar or legend (`_mesh_panels`, drawn by `bsfjax._plot._scene.Scene`), and the atomic save.
"""

from __future__ import annotations

import io
import os

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.cm import ScalarMappable
from matplotlib.colors import Colormap
from matplotlib.figure import Figure

from .._util import atomic_path
from .._util import BSFError
from .._mesh import Mesh, as_mesh
from ._scene import Scene

__all__: list[str] = []

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
    return as_mesh(mesh)  # a Mesh, or trimesh, pyFM, open3d, (V, F); else a one-line error


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


def _cmap(cmap) -> Colormap:
    if isinstance(cmap, Colormap):
        return cmap
    try:
        return colormaps[cmap]
    except KeyError:
        raise BSFError(f"cmap: unknown colormap {cmap!r}") from None


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
