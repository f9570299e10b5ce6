"""The function forms of [`MapEstimator`][bsfjax.MapEstimator]: `estimate_map` and
`mirror_symmetry`, each a ``MapEstimator`` with the given fields and the others at their
defaults."""

from __future__ import annotations

import numpy as np

from .._mesh import as_mesh
from .._sampling import Subsample
from .._spectral import Spectrum
from ._estimate import MapEstimate
from ._estimator import MapEstimator

__all__ = ["estimate_map", "mirror_symmetry"]

_DEFAULT = MapEstimator()


def estimate_map(source: Spectrum, target: Spectrum, *, k: int = _DEFAULT.k, landmarks=None,
                 refine_to: int | None = _DEFAULT.refine_to,
                 n_energies: int = _DEFAULT.n_energies, source_mesh=None, target_mesh=None,
                 zoomout_samples: int | None = _DEFAULT.zoomout_samples,
                 zoomout_step: int = _DEFAULT.zoomout_step, starts=_DEFAULT.starts,
                 derived_landmarks: int = _DEFAULT.derived_landmarks,
                 turn_check: bool = _DEFAULT.turn_check, source_symmetry=None) -> MapEstimate:
    """Estimate a ``k × k`` functional map and a point map from descriptors (and optional
    landmarks): ``MapEstimator(k=k, ...)(source, target, landmarks, ...)``, the other fields
    at their defaults.

    **Arguments:**

    - `source`, `target`, `landmarks`, `source_mesh`, `target_mesh`, `source_symmetry`: as
      [`MapEstimator`][bsfjax.MapEstimator]'s call.
    - `k`, `refine_to`, `n_energies`, `zoomout_step`, `starts`, `derived_landmarks`,
      `turn_check`: the [`MapEstimator`][bsfjax.MapEstimator] fields.
    - `zoomout_samples`: the field, or the ``(source, target)``
      [`Subsample`][bsfjax.Subsample] s of the call's ``samples``.

    **Returns:**

    a [`MapEstimate`][bsfjax.MapEstimate].
    """
    source_mesh, target_mesh = (None if m is None else as_mesh(m, w) for m, w in
                                ((source_mesh, "source_mesh"), (target_mesh, "target_mesh")))
    given = isinstance(zoomout_samples, tuple)
    estimator = MapEstimator(
        k=k, refine_to=refine_to, n_energies=n_energies,
        zoomout_samples=_DEFAULT.zoomout_samples if given else zoomout_samples,
        zoomout_step=zoomout_step, starts=starts, derived_landmarks=derived_landmarks,
        turn_check=turn_check)
    return estimator(source, target, landmarks, source_mesh=source_mesh,
                     target_mesh=target_mesh, samples=zoomout_samples if given else None,
                     source_symmetry=source_symmetry)


def mirror_symmetry(spectrum: Spectrum, mesh, *, k: int = _DEFAULT.k,
                    refine_to: int | None = _DEFAULT.refine_to,
                    n_energies: int = _DEFAULT.n_energies,
                    samples: int | Subsample | None = _DEFAULT.zoomout_samples,
                    zoomout_step: int = _DEFAULT.zoomout_step, rows=None) -> np.ndarray:
    """The shape's intrinsic mirror symmetry ``S: M → M``, a self point map that reverses
    orientation: [`MapEstimator.mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry] of
    ``MapEstimator(k=k, ...)``, the other fields at their defaults.

    **Arguments:**

    - `spectrum`, `mesh`, `rows`: as
      [`MapEstimator.mirror_symmetry`][bsfjax.MapEstimator.mirror_symmetry].
    - `k`, `refine_to`, `n_energies`, `zoomout_step`: the
      [`MapEstimator`][bsfjax.MapEstimator] fields.
    - `samples`: ZoomOut on this many farthest-point samples (the field
      ``zoomout_samples``), on a given [`Subsample`][bsfjax.Subsample], or on every vertex
      (``None``).

    **Returns:**

    ``(n,)`` int array, ``S[i]`` the mirror image of vertex ``i`` (with ``rows``,
    ``(len(rows),)``: the image of ``rows[i]``).
    """
    mesh = as_mesh(mesh, "mesh")  # trimesh, pyFM, open3d, (V, F): bsfjax.as_mesh
    given = isinstance(samples, Subsample)
    estimator = MapEstimator(k=k, refine_to=refine_to, n_energies=n_energies,
                             zoomout_samples=None if given else samples,
                             zoomout_step=zoomout_step)
    return estimator.mirror_symmetry(spectrum, mesh, samples=samples if given else None,
                                     rows=rows)
