"""Matplotlib figures of functions, segmentations and atoms on meshes, and of the 1-D study."""

from ._plot import (VIEWS, plot_1d_approximation, plot_1d_atoms, plot_atoms, plot_error,
                    plot_function, plot_segmentation)

__all__ = ["VIEWS", "plot_function", "plot_segmentation", "plot_error", "plot_atoms",
           "plot_1d_atoms", "plot_1d_approximation"]
