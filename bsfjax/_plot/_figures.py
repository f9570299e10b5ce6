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

This module owns the public figure functions; the renderer lives in `bsfjax._plot._scene`, the
shared checks and panel plumbing in `bsfjax._plot._panels`.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib import colormaps
from matplotlib.colors import BoundaryNorm, LinearSegmentedColormap, ListedColormap, Normalize
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from .._util import BSFError
from .._mesh import Mesh
from ._panels import (
    _GREY, _check_1d, _check_2d, _check_mesh, _cmap, _colours, _face_labels, _face_values,
    _finish, _mesh_panels, _new_figure, _per_vertex, _value_range,
)
from ._scene import Scene, _views

__all__ = [
    "plot_function",
    "plot_segmentation",
    "plot_error",
    "plot_atoms",
    "plot_1d_atoms",
    "plot_1d_approximation",
]

# --------------------------------------------------------------------------------------------
# mesh figures


def plot_function(mesh: Mesh, values, views=("front", "side"), *, cmap="viridis",
                  vmin: float | None = None, vmax: float | None = None, title: str | None = None,
                  colorbar: bool = True, label: str | None = None, up: str = "y",
                  figsize=None, dpi: float = 100, path=None) -> Figure:
    """A scalar function on a mesh, flat-shaded, seen from several views.

    **Arguments:**

    - `mesh`: the surface.
    - `values`: ``(n_vertices,)`` per-vertex values (a face shows the mean of its vertices) or
      ``(n_faces,)`` per-face values.  NaN shows grey.
    - `views`: view names or ``(azimuth, elevation)`` pairs, one panel each.
    - `cmap`, `vmin`, `vmax`: colour map and its range (default: the data's finite range).
    - `title`, `colorbar`, `label`: figure title, whether to draw a colour bar, its label.
    - `up`: the world axis pointing up on screen (``"y"``, ``"z"``, ``"x"``, ``"-y"``, ...).
    - `figsize`, `dpi`: figure size in inches (default 3 × 3.75 per panel) and resolution; a saved
      PNG is ``figsize · dpi`` pixels.
    - `path`: if given, the figure is also written there (atomically).
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

    **Arguments:**

    - `atoms`: ``(n_vertices, s)`` atoms (binary: the atom's support is red, the rest grey;
      real values are shaded from grey at 0 to red at their maximum).
    - `taus`: ``(s,)`` the scale of each column, shown in the panel titles.
    - `view`: one view for every panel.
    - `center`: the centre vertex, marked with a black dot where it faces the camera.
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

    **Arguments:**

    - `x`: ``(n,)`` sample positions.
    - `fourier_basis`: ``(n, k)`` eigenfunctions, one curve each.
    - `bsf_atoms`: ``(n, q)`` atoms, drawn as steps.
    - `stacked`: draw each curve on its own baseline (offset upwards) instead of overlapping.
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

    **Arguments:**

    - `x`: ``(n,)`` sample positions.
    - `f`: ``(n,)`` the function (drawn as a thick black step line).
    - `approximations`: name -> ``(n,)`` approximation, e.g. ``{"Fourier k=10": ..., "BSF": ...}``.
    - `errors`: optional name -> error, appended to the legend entries.
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
