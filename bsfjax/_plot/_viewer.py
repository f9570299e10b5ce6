"""The polyscope viewer and its headless renders: [`view`][bsfjax.plot.view] opens a window with
a source and its targets side by side (or one at a time), their part labels in the same
categorical colours, the wrong-label areas against a truth, and per-part IoU in the side panel;
[`render`][bsfjax.plot.render] draws the same scene to PNGs (EGL, no display).

**Colours.** A part ``l ≥ 0`` has the colour `label_colour` gives it on every shape (the
matplotlib figures' palette); ``−1`` (unassigned) is grey.  A triangle takes the majority label
of its three vertices and one flat colour, so colours never blend across a part border; a point
cloud's points take their own label.  With a truth, each target gets a second panel,
``<target> errors``: red where the label is wrong, grey where unassigned, the part colour faded
to 30 % where right.

**Scores.** Per target with a truth: accuracy ``Σ_i a_i [ŷ_i = y_i] / Σ_i a_i`` and per-part
``IoU_l = Σ a_i [ŷ_i = l ∧ y_i = l] / Σ a_i [ŷ_i = l ∨ y_i = l]`` over the parts of the truth,
``a_i`` the barycentric vertex areas (triangle areas for labels per triangle; 1 per point on a
point cloud).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple, Sequence

import numpy as np

from .._util import BSFError
from .._mesh import Mesh, as_mesh, vertex_areas
from ._figures import label_colour
from ._panels import _GREY, _face_labels
from ._polyscope import backend_in_use, polyscope, register
from ._scene import _up_frame

__all__ = ["ViewScene", "render", "view", "VIEW_ANGLES"]

#: The named cameras of `render`: the turn of every shape about its up axis, in degrees.
VIEW_ANGLES = {"front": 0.0, "back": 180.0, "side": 90.0, "left": 90.0, "right": -90.0}
_WRONG = np.array([0.86, 0.08, 0.08])
_FADE = 0.3  # the share of a part's colour kept on right areas of an errors panel


class ViewScene(NamedTuple):
    """What [`view`][bsfjax.plot.view] and [`render`][bsfjax.plot.render] put in polyscope.

    **Attributes:**

    - `structures`: the polyscope structure names, left to right.
    - `kinds`: ``"surface"`` or ``"points"`` per structure.
    - `colours`: per structure, the ``"parts"`` colours given to polyscope (one row per
      triangle of a surface, per point of a cloud), or ``None`` without labels.
    - `scores`: per target with a truth, ``{"accuracy", "unassigned", "iou": {part: IoU}}``
      (parts by name where names are given, else by label).
    - `paths`: the PNG files written (``render``; empty for ``view``).
    """

    structures: tuple[str, ...]
    kinds: tuple[str, ...]
    colours: tuple[np.ndarray | None, ...]
    scores: dict
    paths: tuple[Path, ...] = ()


class _Shape(NamedTuple):
    name: str
    mesh: Mesh
    labels: np.ndarray | None
    colours: np.ndarray | None
    function: np.ndarray | None


def _is_single(x) -> bool:
    return not isinstance(x, (list, tuple)) or (
        len(x) == 2 and all(np.ndim(a) == 2 for a in x))  # a (vertices, faces) pair


def _labels_on(mesh: Mesh, lab, what: str) -> np.ndarray:
    a = np.asarray(lab)
    sizes = (mesh.n_vertices,) if mesh.is_point_cloud else (mesh.n_vertices, mesh.n_faces)
    if a.ndim != 1 or a.shape[0] not in sizes:
        raise BSFError(f"{what}: expected one label per vertex ({mesh.n_vertices})"
                       + ("" if mesh.is_point_cloud else f" or per triangle ({mesh.n_faces})")
                       + f", got shape {a.shape}")
    if a.dtype == bool or not np.issubdtype(a.dtype, np.number) or not (
            np.all(np.isfinite(a)) and np.all(np.mod(a, 1) == 0)):
        raise BSFError(f"{what}: labels must be integers (−1 for unassigned), got {a.dtype}")
    a = a.astype(np.int64)
    if a.size and a.min() < -1:
        raise BSFError(f"{what}: labels must be >= −1 (−1 = unassigned), found {int(a.min())}")
    return a


def _on_elements(mesh: Mesh, lab: np.ndarray) -> np.ndarray:
    """Labels per triangle (a surface) or per point (a cloud)."""
    return lab if mesh.is_point_cloud else _face_labels(lab, mesh.faces, mesh.n_vertices)


def part_colours(mesh: Mesh, labels) -> np.ndarray:
    """The ``"parts"`` colours of a shape: ``(m, 3)`` per triangle (majority label) of a
    surface, ``(n, 3)`` per point of a point cloud; grey for ``−1``."""
    return label_colour(_on_elements(mesh, _labels_on(mesh, labels, "labels")))


def _error_colours(mesh: Mesh, result: np.ndarray, truth: np.ndarray) -> np.ndarray:
    state = np.where(result < 0, 2, (result != truth).astype(np.int64))  # 0 right, 1 wrong
    state, lab = _on_elements(mesh, state), _on_elements(mesh, result)
    out = _FADE * label_colour(lab) + (1 - _FADE)
    out[state == 1] = _WRONG
    out[state == 2] = _GREY
    return out


def scores(mesh: Mesh, result, truth, label_names: Sequence[str] | None = None) -> dict:
    """Accuracy, unassigned share and per-part IoU of ``result`` against ``truth`` on ``mesh``
    (module doc: area-weighted).

    **Arguments:**

    - `mesh`: the target (a `Mesh`, a point cloud, or what [`as_mesh`][bsfjax.as_mesh] takes).
    - `result`, `truth`: ``(n,)`` labels per vertex (or ``(m,)`` per triangle), ``−1``
      unassigned.
    - `label_names`: ``label_names[l]`` names part ``l`` in the ``"iou"`` keys.

    **Returns:**

    ``{"accuracy": float, "unassigned": float, "iou": {part: float}}`` over the truth's parts.
    """
    mesh = as_mesh(mesh)
    r, t = _labels_on(mesh, result, "result"), _labels_on(mesh, truth, "truth")
    if r.shape != t.shape:
        raise BSFError(f"result and truth must have the same shape, got {r.shape} and {t.shape}")
    if mesh.is_point_cloud:
        a = np.ones(r.shape[0])
    else:
        a = vertex_areas(mesh) if r.shape[0] == mesh.n_vertices else mesh.face_areas()
    total = a.sum()
    iou = {}
    for part in np.unique(t[t >= 0]):
        inter = a[(r == part) & (t == part)].sum()
        union = a[(r == part) | (t == part)].sum()
        key = label_names[part] if label_names is not None and part < len(label_names) \
            else int(part)
        iou[key] = float(inter / union)
    return {"accuracy": float(a[r == t].sum() / total), "unassigned": float(a[r < 0].sum() / total),
            "iou": iou}


def _per_target(x, n: int, what: str) -> list:
    if x is None:
        return [None] * n
    items = [x] if n == 1 and not isinstance(x, list) else x
    if not isinstance(items, (list, tuple)) or len(items) != n:
        raise BSFError(f"{what}: give one per target ({n}) as a list, got "
                       f"{len(items) if isinstance(items, (list, tuple)) else type(x).__name__}")
    return list(items)


def _shapes(source, targets, labels, results, truth, function, names, label_names):
    targets = [] if targets is None else [targets] if _is_single(targets) else list(targets)
    meshes = [as_mesh(source, "source")] + [as_mesh(t, f"target {i}") for i, t in
                                            enumerate(targets)]
    n = len(targets)
    results, truths = _per_target(results, n, "results"), _per_target(truth, n, "truth")
    fn = [None] * (n + 1)
    if function is not None:
        fn = list(function) if isinstance(function, list) else [function]
        if len(fn) > n + 1:
            raise BSFError(f"function: at most one per shape ({n + 1}), got {len(fn)}")
        fn += [None] * (n + 1 - len(fn))
    for i, (m, f) in enumerate(zip(meshes, fn)):
        if f is not None and np.shape(f) != (m.n_vertices,):
            raise BSFError(f"function {i}: expected one value per vertex ({m.n_vertices}), got "
                           f"shape {np.shape(f)}")
    if names is None:
        names = ["source"] + [f"target {i + 1}" for i in range(n)] if n > 1 else \
            ["source", "target"][:n + 1]
    if len(names) != n + 1 or len(set(names)) != n + 1:
        raise BSFError(f"names: give {n + 1} distinct names (source, then targets), got {names}")
    shapes, score = [], {}
    src = None if labels is None else _labels_on(meshes[0], labels, "labels")
    shapes.append(_Shape(names[0], meshes[0], src,
                         None if src is None else label_colour(_on_elements(meshes[0], src)),
                         fn[0]))
    for i in range(n):
        m, name = meshes[i + 1], names[i + 1]
        r = None if results[i] is None else _labels_on(m, results[i], f"result of {name}")
        shapes.append(_Shape(name, m, r, None if r is None else
                             label_colour(_on_elements(m, r)), fn[i + 1]))
        if truths[i] is not None:
            if r is None:
                raise BSFError(f"truth of {name}: needs its result to compare with")
            t = _labels_on(m, truths[i], f"truth of {name}")
            if t.shape != r.shape:
                raise BSFError(f"truth of {name}: {t.shape[0]} labels, its result has "
                               f"{r.shape[0]}")
            score[name] = scores(m, r, t, label_names)
            shapes.append(_Shape(f"{name} errors", m, r, _error_colours(m, r, t), None))
    return shapes, score


def _positions(shapes, up: str, angle: float, layout: str) -> list[np.ndarray]:
    """Each shape in polyscope's frame (z up, camera at −y): turned by ``angle`` about its own
    up axis through its centre, and placed left to right (``"side"``) or at the origin."""
    t = np.deg2rad(angle)
    rot = np.array([[np.cos(t), -np.sin(t), 0], [np.sin(t), np.cos(t), 0], [0, 0, 1]])
    out, x = [], 0.0
    for s in shapes:
        p = s.mesh.vertices @ _up_frame(s.mesh.vertices, up).T
        lo, hi = p.min(0), p.max(0)
        p = (p - (lo + hi) / 2) @ rot.T
        if layout == "side":
            half = 0.5 * np.linalg.norm((hi - lo)[:2])  # any turn fits in this footprint
            gap = 0.08 * (hi - lo)[2]
            p[:, 0] += x + half
            x += 2 * half + gap
        out.append(p)
    return out


def _scene(shapes, score=None, paths=()) -> ViewScene:
    return ViewScene(tuple(s.name for s in shapes),
                     tuple("points" if s.mesh.is_point_cloud else "surface" for s in shapes),
                     tuple(s.colours for s in shapes), score or {}, tuple(paths))


def _frame_camera(ps, positions: list[np.ndarray], aspect: float, margin: float = 1.08) -> None:
    """A distant camera at −y (nearly orthographic: every shape seen straight on) looking at
    the shapes' bounding box, its field of view fitted to it."""
    pts = np.concatenate(positions)
    lo, hi = pts.min(0), pts.max(0)
    centre = (lo + hi) / 2
    half = margin * max((hi - lo)[2], (hi - lo)[0] / aspect) / 2  # half the visible height
    dist = 8.0 * half + (hi - lo)[1]
    fov = 2 * np.degrees(np.arctan(half / (dist - (hi - lo)[1] / 2)))
    ps.set_vertical_fov_degrees(float(fov))
    ps.look_at(tuple(centre - [0, dist, 0]), tuple(centre))


def _build(ps, shapes, up: str, layout: str, angle: float = 0.0) -> list[np.ndarray]:
    positions = _positions(shapes, up, angle, layout)
    for i, (s, p) in enumerate(zip(shapes, positions)):
        cloud = s.mesh.is_point_cloud
        register(ps, s.name, p, None if cloud else s.mesh.faces,
                 face_colours=None if cloud else s.colours,
                 point_colours=s.colours if cloud else None,
                 labels=s.labels, function=s.function, enabled=layout == "side" or i == 0)
    ps.set_up_dir("z_up")
    ps.set_front_dir("neg_y_front")
    ps.set_ground_plane_mode("shadow_only")
    return positions


def _checks(layout, up):
    if layout not in ("side", "one"):
        raise BSFError(f"layout must be 'side' (side by side) or 'one' (one at a time), got "
                       f"{layout!r}")
    _up_frame(np.zeros((1, 3)), up)  # a clear error for a wrong up


def _side_panel(ps, shapes, score, layout):
    from polyscope import imgui as psim

    state = {"shown": 0}
    palette = {}
    for s in shapes:
        if s.labels is not None:
            for lab in np.unique(s.labels[s.labels >= 0]):
                palette[int(lab)] = label_colour(np.array([lab]))[0]

    def callback():
        if layout == "one":
            changed, state["shown"] = psim.Combo("shape", state["shown"],
                                                 [s.name for s in shapes])
            if changed:
                for i, s in enumerate(shapes):
                    get = ps.get_point_cloud if s.mesh.is_point_cloud else ps.get_surface_mesh
                    get(s.name).set_enabled(i == state["shown"])
        for name, sc in score.items():
            if psim.CollapsingHeader(f"{name}: {sc['accuracy']:.1%} right"):
                psim.TextUnformatted(f"unassigned {sc['unassigned']:.1%} of the area")
                for i, (part, iou) in enumerate(sc["iou"].items()):
                    lab = i if not isinstance(part, int) else part
                    rgb = palette.get(lab, _GREY)
                    psim.TextColored((*map(float, rgb), 1.0), f"{part}")
                    psim.SameLine()
                    psim.TextUnformatted(f"IoU {iou:.1%}")

    return callback


def view(source, targets=None, *, labels=None, results=None, truth=None, function=None,
         names: Sequence[str] | None = None, label_names: Sequence[str] | None = None,
         layout: str = "side", up: str = "y", backend: str = "auto",
         show: bool = True) -> ViewScene:
    """Open polyscope with ``source`` and each target, side by side or one at a time.

    Every shape may be a [`Mesh`][bsfjax.Mesh], a [`PointCloud`][bsfjax.PointCloud] (drawn as
    points), a file path, a ``(vertices, faces)`` pair, a trimesh / pyFM / open3d object
    ([`as_mesh`][bsfjax.as_mesh]).  Colours, errors panels and scores: module doc.

    **Arguments:**

    - `source`: the source shape.
    - `targets`: one target, or a list of them (``None``: the source alone).
    - `labels`: ``(n,)`` part labels of the source (per vertex, or per triangle), ``−1``
      unassigned.
    - `results`: the labels on each target (one array, or a list, one per target).
    - `truth`: the true labels of each target (as `results`): adds an errors panel per target
      and its scores (side panel: accuracy, per-part IoU).
    - `function`: ``(n,)`` values on the source, or a list of them, one per shape (source first;
      ``None`` skips one), shown as a ``"function"`` scalar (viridis).
    - `names`: the structure names, source then targets (default ``source``, ``target``).
    - `label_names`: ``label_names[l]`` names part ``l`` in the side panel.
    - `layout`: ``"side"`` (left to right) or ``"one"`` (one shape at a time; a menu chooses).
    - `up`: the up axis of the shapes (``"y"``, ``"z"``, ``"-y"``, ...).
    - `backend`: ``"auto"`` (a window; a one-line error without a display), ``"window"`` or
      ``"mock"`` (polyscope's test backend: no window, three frames).
    - `show`: open the window (blocks until it is closed); ``False`` only builds the scene, for
      more polyscope calls before ``polyscope.show()``.

    **Returns:**

    The [`ViewScene`][bsfjax.plot.ViewScene].
    """
    _checks(layout, up)
    shapes, score = _shapes(source, targets, labels, results, truth, function, names,
                            label_names)
    ps = polyscope(backend, window=True)
    _build(ps, shapes, up, layout)
    ps.set_user_callback(_side_panel(ps, shapes, score, layout))
    ps.reset_camera_to_home_view()
    if show:
        ps.show(3 if backend_in_use() == "mock" else None)
    return _scene(shapes, score)


def render(source, targets=None, out_dir=".", *, labels=None, results=None, truth=None,
           function=None, names: Sequence[str] | None = None,
           label_names: Sequence[str] | None = None, views: Sequence[str] = ("front",),
           size: tuple[int, int] = (1200, 600), layout: str = "side", up: str = "y",
           prefix: str = "view", backend: str = "auto") -> ViewScene:
    """Render the scene of [`view`][bsfjax.plot.view] headless to PNG files, one per view
    (``layout="side"``: ``{prefix}_{view}.png``) or per shape and view (``"one"``:
    ``{prefix}_{shape}_{view}.png``, spaces as ``_``).

    **Arguments:**

    - `source`, `targets`, `labels`, `results`, `truth`, `function`, `names`, `label_names`,
      `layout`, `up`: as [`view`][bsfjax.plot.view].
    - `out_dir`: the folder of the PNGs (made if missing).
    - `views`: camera names, each a turn of every shape about its up axis: ``"front"``,
      ``"back"``, ``"side"`` (= ``"left"``), ``"right"``; or angles in degrees.
    - `size`: ``(width, height)`` of each PNG in pixels.
    - `prefix`: the start of each file name.
    - `backend`: ``"auto"`` (EGL without a display, else a window), ``"egl"``, ``"window"`` or
      ``"mock"`` (tests: blank images).

    **Returns:**

    The [`ViewScene`][bsfjax.plot.ViewScene], its `paths` the PNGs written.
    """
    _checks(layout, up)
    angles = []
    for v in views:
        if isinstance(v, str) and v in VIEW_ANGLES:
            angles.append((v, VIEW_ANGLES[v]))
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            angles.append((f"{v:g}", float(v)))
        else:
            raise BSFError(f"views: unknown view {v!r}; use {sorted(VIEW_ANGLES)} or degrees")
    try:
        w, h = (int(x) for x in size)
    except (TypeError, ValueError):
        raise BSFError(f"size must be (width, height) in pixels, got {size!r}") from None
    if not (16 <= w <= 8192 and 16 <= h <= 8192):
        raise BSFError(f"size must be 16 to 8192 pixels each way, got {w}x{h}")
    shapes, score = _shapes(source, targets, labels, results, truth, function, names,
                            label_names)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    ps = polyscope(backend)
    ps.set_window_size(w, h)
    ps.set_build_default_gui_panels(False)
    paths = []
    groups = [shapes] if layout == "side" else [[s] for s in shapes]
    for group in groups:
        for view_name, angle in angles:
            ps.remove_all_structures()
            _frame_camera(ps, _build(ps, group, up, "side", angle), w / h)
            stem = prefix if layout == "side" else f"{prefix}_{group[0].name}"
            path = out / f"{stem}_{view_name}.png".replace(" ", "_")
            ps.screenshot(str(path), transparent_bg=False)
            paths.append(path)
    ps.set_build_default_gui_panels(True)  # (the last view's structures stay registered)
    return _scene(shapes, score, paths)
