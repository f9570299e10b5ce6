"""Matplotlib figures of functions, segmentations and atoms on meshes, and of the 1-D study;
the polyscope viewer and its headless renders (`view`, `render`; polyscope imported lazily).

Public as `bsfjax.plot`.
"""

from ._figures import (
    label_colour, plot_1d_approximation, plot_1d_atoms, plot_atoms, plot_error, plot_function,
    plot_segmentation,
)
from ._scene import Scene, VIEWS
from ._viewer import VIEW_ANGLES, ViewScene, render, view

__all__ = [
    "Scene", "VIEWS", "VIEW_ANGLES", "ViewScene", "label_colour", "plot_1d_approximation", "plot_1d_atoms", "plot_atoms",
    "plot_error", "plot_function", "plot_segmentation", "render", "view",
]
