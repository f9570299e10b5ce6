"""Matplotlib figures of functions, segmentations and atoms on meshes (public as `bsfjax.plot`)."""

from ._figures import (
    Scene, VIEWS, label_colour, plot_1d_approximation, plot_1d_atoms, plot_atoms,
    plot_error, plot_function, plot_segmentation,
)

__all__ = [
    "Scene", "VIEWS", "label_colour", "plot_1d_approximation", "plot_1d_atoms", "plot_atoms",
    "plot_error", "plot_function", "plot_segmentation",
]
