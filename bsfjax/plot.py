"""Matplotlib figures of functions, segmentations and atoms on meshes, and of the 1-D study;
the polyscope viewer (`view`) and its headless PNG renders (`render`)."""

from ._plot import (VIEW_ANGLES, VIEWS, ViewScene, plot_1d_approximation, plot_1d_atoms,
                    plot_atoms, plot_error, plot_function, plot_segmentation, render, view)

__all__ = ["VIEWS", "plot_function", "plot_segmentation", "plot_error", "plot_atoms",
           "plot_1d_atoms", "plot_1d_approximation", "view", "render", "ViewScene",
           "VIEW_ANGLES"]
