"""bsfjax.plot: figures are drawn correctly (hidden surfaces, views, colours), saved, validated."""

from __future__ import annotations

import subprocess
import sys
import time

import numpy as np
import pytest
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.image import imread
from scipy.spatial import ConvexHull

from bsfjax import plot
from bsfjax.internal import label_colour
from bsfjax import BSFError
from bsfjax import example_mesh, example_pair
from bsfjax import Mesh
from bsfjax import interval_spectrum


@pytest.fixture(scope="module")
def pair():
    return example_pair(levels=2)  # 2018 vertices: fast


def _sphere(n=400, centre=(0.0, 0.0, 0.0), radius=1.0) -> Mesh:
    """A closed, outward-oriented triangulated sphere (convex hull of a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * i / n)
    theta = np.pi * (1 + 5**0.5) * i
    p = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
    f = ConvexHull(p).simplices
    nrm = np.cross(p[f[:, 1]] - p[f[:, 0]], p[f[:, 2]] - p[f[:, 0]])
    flip = (nrm * p[f].mean(1)).sum(1) < 0
    f[flip] = f[flip][:, ::-1]
    return Mesh(radius * p + np.asarray(centre), f)


def _union(a: Mesh, b: Mesh) -> Mesh:
    return Mesh(np.concatenate([a.vertices, b.vertices]),
                np.concatenate([a.faces, b.faces + a.n_vertices]))


def _pixels(fig: Figure) -> np.ndarray:
    fig.canvas.draw()
    return np.asarray(fig.canvas.buffer_rgba())[..., :3].astype(float) / 255.0


def _check_png(path, size, min_colours=5):
    img = imread(path)
    assert img.shape[:2] == (size[1], size[0])  # rows = height
    rgb = img[..., :3]
    assert rgb.std() > 0.05  # not blank
    n_colours = len(np.unique((rgb * 255).astype(np.uint8).reshape(-1, 3), axis=0))
    assert n_colours >= min_colours
    assert not list(path.parent.glob(".*.tmp*"))  # the atomic write left nothing behind
    return rgb


def _chroma(rgb):
    return rgb / np.maximum(rgb.sum(-1, keepdims=True), 1e-9)


# --------------------------------------------------------------------------------------------
# renderer correctness


def test_hidden_surfaces_front_and_back(pair):
    """Front view (camera at +z for y-up meshes) shows the z > 0 half of the rest-pose body, the
    back view the z < 0 half: culling and depth order work and the views point where named."""
    mesh = example_mesh("rest", levels=2)
    z = mesh.vertices[:, 2]
    two = ListedColormap([(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)])  # z < 0 blue, z > 0 red
    fracs = {}
    for view in ("front", "back"):
        fig = plot.plot_function(mesh, np.sign(z), views=view, cmap=two, vmin=-1, vmax=1,
                                 colorbar=False, figsize=(3, 3), dpi=80)
        px = _pixels(fig)
        red = (px[..., 0] > 0.1) & (px[..., 1] < 0.05) & (px[..., 2] < 0.05)
        blue = (px[..., 2] > 0.1) & (px[..., 0] < 0.05) & (px[..., 1] < 0.05)
        assert red.sum() + blue.sum() > 1000  # the body covers many pixels
        fracs[view] = red.sum() / (red.sum() + blue.sum())
    assert fracs["front"] > 0.97 and fracs["back"] < 0.03, fracs


def test_painter_order_nearer_sphere_wins():
    """Two overlapping unit spheres, the second nearer the camera: it is fully visible and
    hides part of the first (visible areas π and π − 2.15 in disc units)."""
    far = _sphere(centre=(0.0, 0.0, 0.0))
    near = _sphere(centre=(0.5, 0.0, 2.5))
    both = _union(far, near)
    vals = np.r_[np.zeros(far.n_vertices), np.ones(near.n_vertices)]
    two = ListedColormap([(0.0, 0.0, 1.0), (1.0, 0.0, 0.0)])
    fig = plot.plot_function(both, vals, views="front", cmap=two, vmin=0, vmax=1,
                             colorbar=False, figsize=(3, 3), dpi=80)
    px = _pixels(fig)
    counts = {"red": ((px[..., 0] > 0.1) & (px[..., 1] < 0.05) & (px[..., 2] < 0.05)).sum(),
              "blue": ((px[..., 2] > 0.1) & (px[..., 0] < 0.05) & (px[..., 1] < 0.05)).sum()}
    ratio = counts["red"] / counts["blue"]
    expected = np.pi / (np.pi - 2.152)  # 3.17; drawing far over near would give ~0.3
    assert 0.8 * expected < ratio < 1.25 * expected, counts


def test_up_axis_is_a_rotation(pair):
    """A y-up mesh drawn with up='y' looks the same as its copy rotated to z-up with up='z'."""
    v = pair.target.vertices
    rotated = Mesh(np.stack([v[:, 0], -v[:, 2], v[:, 1]], 1), pair.target.faces)
    kw = dict(views=("front", "left", "iso"), colorbar=False, figsize=(6, 3), dpi=60)
    a = _pixels(plot.plot_function(pair.target, v[:, 1], up="y", **kw))
    b = _pixels(plot.plot_function(rotated, v[:, 1], up="z", **kw))
    assert np.mean(np.any(np.abs(a - b) > 0.02, axis=-1)) < 0.002
    c = _pixels(plot.plot_function(pair.target, v[:, 1], up="z", **kw))  # wrong up: differs
    assert np.mean(np.any(np.abs(a - c) > 0.02, axis=-1)) > 0.02


def test_open_mesh_draws_both_sides():
    """A mesh with a hole is drawn without culling, so its inside shows through the hole."""
    s = _sphere(600)
    keep = s.vertices[s.faces].mean(1)[:, 2] < 0.6  # cut the cap facing the camera
    m = Mesh(s.vertices, s.faces[keep])
    fig = plot.plot_function(m, np.ones(m.n_vertices), views="front", cmap="Reds", vmin=0,
                             vmax=1, colorbar=False, figsize=(3, 3), dpi=80)
    px = _pixels(fig)
    h, w, _ = px.shape
    centre = px[h // 2 - 3:h // 2 + 3, w // 2 - 3:w // 2 + 3]
    assert np.all(centre.sum(-1) < 2.9)  # not white background: the inner wall is drawn


# --------------------------------------------------------------------------------------------
# each public function: returns a Figure, saves a PNG of the requested size, not blank


def test_plot_function_saves(pair, tmp_path):
    path = tmp_path / "f.png"
    fig = plot.plot_function(pair.source, pair.source.vertices[:, 1], views=("front", "side"),
                             title="height", figsize=(5, 3), dpi=60, path=path)
    assert isinstance(fig, Figure)
    assert fig._suptitle.get_text() == "height"
    assert len(fig.axes) == 3  # two views + colour bar
    _check_png(path, (300, 180), min_colours=50)
    assert fig._repr_png_()[:8] == b"\x89PNG\r\n\x1a\n"  # notebooks display it
    # per-face values are accepted too
    plot.plot_function(pair.source, np.arange(pair.source.n_faces), views="iso")


def test_plot_function_speed():
    mesh = example_pair().source  # 8066 vertices, 16128 faces
    t0 = time.perf_counter()
    plot.plot_function(mesh, mesh.vertices[:, 0], views=("front", "side"))._repr_png_()
    assert time.perf_counter() - t0 < 4.0  # measured ~0.4 s


def test_nan_values_are_grey(pair):
    vals = pair.source.vertices[:, 0].copy()
    vals[:] = np.nan
    fig = plot.plot_function(pair.source, vals, views="front", cmap="Reds", colorbar=False,
                             figsize=(3, 3), dpi=60)
    px = _pixels(fig)
    body = px.sum(-1) < 2.9
    assert body.sum() > 300
    assert np.all(np.ptp(px[body], axis=-1) < 0.02)  # every drawn pixel is a grey


def test_plot_segmentation_colours(pair, tmp_path):
    path = tmp_path / "seg.png"
    lab = pair.labels.copy()
    lab[: pair.source.n_vertices // 20] = -1  # some unassigned vertices
    fig = plot.plot_segmentation(pair.source, lab, views=("front", "back"), legend=False,
                                 figsize=(4, 3), dpi=80, path=path)
    assert isinstance(fig, Figure)
    rgb = _check_png(path, (320, 240))
    # flat shading scales a colour, so every label's chromaticity must appear in the image
    chroma = _chroma(rgb).reshape(-1, 3)
    for l in range(6):
        c = label_colour(np.array([l]))[0]
        assert np.min(np.abs(chroma - _chroma(c)).max(-1)) < 0.01, l
    # unassigned: shaded grey pixels (equal channels, darker than the white background)
    flat = rgb.reshape(-1, 3)
    grey = (np.ptp(flat, axis=-1) < 0.01) & (flat.mean(-1) < 0.7) & (flat.mean(-1) > 0.1)
    assert grey.sum() > 50


def test_plot_segmentation_legend_names(pair):
    fig = plot.plot_segmentation(pair.source, pair.labels, label_names=pair.label_names)
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts == list(pair.label_names)
    fig = plot.plot_segmentation(pair.source, np.where(pair.labels == 2, -1, pair.labels),
                                 label_names={0: "body"})
    texts = [t.get_text() for t in fig.legends[0].get_texts()]
    assert texts == ["unassigned", "body", "1", "3", "4", "5"]


def test_plot_error_values(pair, tmp_path):
    path = tmp_path / "err.png"
    ref = pair.source.vertices[:, 1]
    est = ref + np.linspace(0, 1, ref.size)
    fig = plot.plot_error(pair.source, ref, est, figsize=(4, 3), dpi=50, path=path)
    assert fig._suptitle.get_text() == f"mean |error| = {np.mean(np.abs(est - ref)):.4g}"
    _check_png(path, (200, 150))
    # integer labels: the mismatch fraction
    wrong = pair.labels.copy()
    wrong[wrong == 2] = 3
    fig = plot.plot_error(pair.source, pair.labels, wrong)
    assert fig._suptitle.get_text() == f"mean mismatch = {np.mean(pair.labels == 2):.4g}"
    # (n, c) arrays: the Euclidean norm per vertex
    fig = plot.plot_error(pair.source, pair.source.vertices, pair.target.vertices)
    d = np.linalg.norm(pair.source.vertices - pair.target.vertices, axis=1).mean()
    assert fig._suptitle.get_text() == f"mean |error| = {d:.4g}"


def test_plot_atoms(pair, tmp_path):
    path = tmp_path / "atoms.png"
    v = pair.source.vertices
    c = int(np.argmax(v[:, 2]))
    d = np.linalg.norm(v - v[c], axis=1)
    taus = np.array([0.1, 0.5, 2.0])
    atoms = (d[:, None] < np.array([0.3, 0.6, 1.2])).astype(np.float32)
    fig = plot.plot_atoms(pair.source, atoms, taus, center=c, figsize=(6, 2.5), dpi=60, path=path)
    assert isinstance(fig, Figure) and len(fig.axes) == 3
    assert [ax.get_title() for ax in fig.axes] == ["τ = 0.1", "τ = 0.5", "τ = 2"]
    rgb = _check_png(path, (360, 150))
    # the support is red, growing with the scale
    red = [((p[..., 0] > p[..., 1] + 0.2) & (p[..., 0] > p[..., 2] + 0.2)).sum()
           for p in np.array_split(rgb, 3, axis=1)]
    assert 0 < red[0] < red[1] < red[2], red


def test_plot_1d_atoms(tmp_path):
    n = 200
    x = np.linspace(0, 1, n)
    phi = interval_spectrum(n, 5).evecs
    B = np.stack([(np.abs(x - c) < w).astype(float) for c, w in ((0.3, 0.05), (0.6, 0.15))], 1)
    path = tmp_path / "a1d.png"
    fig = plot.plot_1d_atoms(x, phi, B, figsize=(6, 3), dpi=50, path=path)
    assert isinstance(fig, Figure)
    left, right = fig.axes
    curves = [l for l in left.lines if len(l.get_xdata()) == n]
    steps = [l for l in right.lines if len(l.get_xdata()) == n]
    assert len(curves) == 5 and len(steps) == 2
    assert all(l.get_drawstyle() == "steps-mid" for l in steps)
    # stacked: each curve is the data shifted up by a constant
    for j, l in enumerate(curves):
        shift = l.get_ydata() - phi[:, j]
        np.testing.assert_allclose(shift, shift[0], atol=1e-12)
    assert np.all(np.diff([l.get_ydata()[0] - phi[0, j] for j, l in enumerate(curves)]) > 0)
    _check_png(path, (300, 150))
    fig = plot.plot_1d_atoms(x, phi, B[:, 0], stacked=False)  # a single atom as a 1-D array
    assert len(fig.axes[1].lines) == 1


def test_plot_1d_approximation(tmp_path):
    x = np.linspace(0, 1, 300)
    f = (x > 0.4).astype(float)
    approx = {"Fourier k=10": f + 0.1 * np.sin(40 * x), "BSF": f}
    path = tmp_path / "app.png"
    fig = plot.plot_1d_approximation(x, f, approx, errors={"Fourier k=10": 0.1234},
                                     title="step", figsize=(5, 3), dpi=60, path=path)
    texts = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert texts == ["f", "Fourier k=10 (error 0.123)", "BSF"]
    _check_png(path, (300, 180))


# --------------------------------------------------------------------------------------------
# validation


def test_bad_inputs(pair):
    m = pair.source
    n = m.n_vertices
    with pytest.raises(BSFError, match=r"values must have length n_vertices=2018"):
        plot.plot_function(m, np.zeros(n + 1))
    with pytest.raises(BSFError, match="values"):
        plot.plot_function(m, np.zeros((n, 2)))
    with pytest.raises(BSFError, match="labels must have length"):
        plot.plot_segmentation(m, np.zeros(5, dtype=int))
    with pytest.raises(BSFError, match="labels must be integers"):
        plot.plot_segmentation(m, np.full(n, 0.5))
    with pytest.raises(BSFError, match="labels must be >= "):
        plot.plot_segmentation(m, np.full(n, -2))
    with pytest.raises(BSFError, match="estimate must have length"):
        plot.plot_error(m, np.zeros(n), np.zeros(n - 1))
    with pytest.raises(BSFError, match="same shape"):
        plot.plot_error(m, np.zeros(n), np.zeros((n, 2)))
    with pytest.raises(BSFError, match=r"taus must have shape \(2,\)"):
        plot.plot_atoms(m, np.zeros((n, 2)), [1.0, 2.0, 3.0])
    with pytest.raises(BSFError, match="atoms must have shape"):
        plot.plot_atoms(m, np.zeros((n - 1, 2)), [1.0, 2.0])
    with pytest.raises(BSFError, match="center"):
        plot.plot_atoms(m, np.zeros((n, 1)), [1.0], center=n)
    with pytest.raises(BSFError, match="unknown view 'sideways'"):
        plot.plot_function(m, np.zeros(n), views=("front", "sideways"))
    with pytest.raises(BSFError, match="up must be"):
        plot.plot_function(m, np.zeros(n), up="w")
    with pytest.raises(BSFError, match="cmap"):
        plot.plot_function(m, np.zeros(n), cmap="no-such-map")
    with pytest.raises(BSFError, match="mesh must be a bsfjax.Mesh"):
        plot.plot_function(m.vertices, np.zeros(n))
    with pytest.raises(BSFError, match="figsize"):
        plot.plot_function(m, np.zeros(n), figsize=(0, 3))
    x = np.linspace(0, 1, 10)
    with pytest.raises(BSFError, match=r"f must have shape \(10,\)"):
        plot.plot_1d_approximation(x, np.zeros(9), {"a": np.zeros(10)})
    with pytest.raises(BSFError, match=r"approximations\['a'\] must have shape \(10,\)"):
        plot.plot_1d_approximation(x, np.zeros(10), {"a": np.zeros(11)})
    with pytest.raises(BSFError, match="errors has names not in approximations"):
        plot.plot_1d_approximation(x, np.zeros(10), {"a": np.zeros(10)}, errors={"b": 1.0})
    with pytest.raises(BSFError, match=r"fourier_basis must have shape \(10, k\)"):
        plot.plot_1d_atoms(x, np.zeros((9, 3)), np.zeros((10, 2)))
    # all raised as ValueError too
    with pytest.raises(ValueError):
        plot.plot_function(m, np.zeros(3))


def test_no_pyplot_no_backend_change():
    """import bsfjax does not import matplotlib; plotting never imports pyplot or sets a backend."""
    code = (
        "import sys, bsfjax\n"
        "assert 'matplotlib' not in sys.modules, 'import bsfjax imported matplotlib'\n"
        "import matplotlib\n"
        "matplotlib.use('svg')\n"
        "from bsfjax import plot\n"
        "m = bsfjax.example_mesh(levels=1)\n"
        "plot.plot_function(m, m.vertices[:, 0])._repr_png_()\n"
        "assert 'matplotlib.pyplot' not in sys.modules\n"
        "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
