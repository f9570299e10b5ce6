"""polyscope, imported lazily: its backend (a window, EGL headless, or the mock backend of the
tests), and the structures of the viewer (`bsfjax._plot._viewer`).

polyscope (Sharp et al.) is an optional dependency (``pip install bsfjax[view]``); nothing
else in bsfjax imports it.  polyscope is one global scene per process: it is initialised once,
with the first backend asked for, and every `view` / `render` call clears its structures.
"""

from __future__ import annotations

import os
import sys

import numpy as np

from .._util import BSFError

__all__ = ["BACKENDS", "polyscope", "register"]

#: ``backend`` names -> polyscope's backend strings.  ``"auto"``: a window where there is a
#: display, else EGL (screenshots only).
BACKENDS = {"window": "openGL3_glfw", "egl": "openGL3_egl", "mock": "openGL_mock"}
_STATE: dict = {"backend": None}


def _has_display() -> bool:
    if sys.platform in ("darwin", "win32"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def polyscope(backend: str = "auto", *, window: bool = False):
    """The ``polyscope`` module, initialised with ``backend`` (``"auto"``, ``"window"``,
    ``"egl"`` or ``"mock"``) and emptied of structures.  ``window``: the caller needs a window
    (the interactive viewer); with ``"auto"`` and no display that is a one-line error."""
    if backend not in ("auto", *BACKENDS):
        raise BSFError(f"backend must be 'auto' or one of {sorted(BACKENDS)}, got {backend!r}")
    try:
        import polyscope as ps
    except ImportError:
        raise BSFError("the viewer needs polyscope: pip install 'bsfjax[view]' (or pip install "
                       "polyscope)") from None
    if backend == "auto":
        if _STATE["backend"] is not None:
            backend = _STATE["backend"]
        elif _has_display():
            backend = "window"
        elif window:
            raise BSFError("no display (DISPLAY / WAYLAND_DISPLAY unset): the interactive viewer "
                           "needs one; render PNGs headless instead (bsfjax view --screenshot DIR"
                           ", bsfjax.plot.render)")
        else:
            backend = "egl"
    if _STATE["backend"] is None:
        ps.set_allow_headless_backends(True)
        ps.set_program_name("bsfjax")
        ps.set_print_prefix("[bsfjax view] ")
        ps.set_errors_throw_exceptions(True)
        ps.set_verbosity(0)
        ps.set_use_prefs_file(False)
        try:
            ps.init(BACKENDS[backend])
        except Exception as exc:  # polyscope raises RuntimeError (or its own) on a failed init
            why = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            hint = (" (EGL: apt-get install libegl1 libgl1-mesa-dri libegl-mesa0, or a GPU "
                    "driver's EGL)" if backend == "egl" else "")
            raise BSFError(f"polyscope could not start its {backend} backend: {why}{hint}") \
                from None
        _STATE["backend"] = backend
    elif _STATE["backend"] != backend:
        raise BSFError(f"polyscope already runs the {_STATE['backend']} backend in this process; "
                       f"it cannot switch to {backend} (polyscope is one scene per process)")
    if window and _STATE["backend"] == "egl":
        raise BSFError("the EGL backend renders headless and has no window: use render / "
                       "--screenshot, or a display")
    ps.remove_all_structures()
    ps.set_user_callback(None)
    return ps


def backend_in_use() -> str | None:
    """The backend polyscope was initialised with in this process, or ``None``."""
    return _STATE["backend"]


def register(ps, name: str, positions: np.ndarray, faces: np.ndarray | None, *,
             face_colours: np.ndarray | None = None, point_colours: np.ndarray | None = None,
             labels: np.ndarray | None = None, function: np.ndarray | None = None,
             enabled: bool = True):
    """One structure: a surface mesh (``faces``) or a point cloud (``faces`` ``None``), with
    its colours as a ``"parts"`` colour quantity (per triangle, or per point), its integer
    ``labels`` as a categorical ``"label"`` scalar (for picking), and a ``"function"`` scalar."""
    if faces is None:
        s = ps.register_point_cloud(name, positions, enabled=enabled, radius=0.0035)
        s.set_point_render_mode("sphere")
        where = {}
    else:
        s = ps.register_surface_mesh(name, positions, faces, enabled=enabled, smooth_shade=True)
        where = {"defined_on": "vertices"}
    colour = face_colours if faces is not None else point_colours
    if colour is not None:
        kw = {"defined_on": "faces"} if faces is not None else {}
        s.add_color_quantity("parts", np.asarray(colour, np.float64), enabled=True, **kw)
    if labels is not None and labels.shape[0] == positions.shape[0]:
        s.add_scalar_quantity("label", labels.astype(np.float64), datatype="categorical",
                              **where)
    if function is not None:
        s.add_scalar_quantity("function", np.asarray(function, np.float64), cmap="viridis",
                              enabled=colour is None, **where)
    return s
