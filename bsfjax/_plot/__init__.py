"""Matplotlib figures of functions, segmentations and atoms on meshes, and of the 1-D study.

Public as `bsfjax.plot`.
"""

from ._figures import (
    label_colour, plot_1d_approximation, plot_1d_atoms, plot_atoms, plot_error, plot_function,
    plot_segmentation,
)
from ._scene import Scene, VIEWS

__all__ = [
    "Scene", "VIEWS", "label_colour", "plot_1d_approximation", "plot_1d_atoms", "plot_atoms",
    "plot_error", "plot_function", "plot_segmentation",
]
