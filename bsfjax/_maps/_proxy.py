r"""The landmark-free map of a large mesh, chosen on a decimated proxy and carried back.

Without landmarks [`MapEstimator`][bsfjax.MapEstimator] runs 15 starts, compares them by
geodesic distortion and orientation, estimates again with landmarks read off the kept map and
checks it for a front-to-back turn: Dijkstra runs, candidate point maps and orientation bases
on every shape it is given.  On a mesh of more than ``proxy_above`` vertices all of that runs
on a quadric-decimated proxy of about ``proxy_vertices`` vertices
([`bsfjax.decimate`][bsfjax.decimate]) instead, where it costs seconds, and the kept proxy map
``T_p`` is carried back to the given meshes:

1. the composed point map ``T₀(y) = ι_M(T_p(π_N(y)))``, with ``π_N`` the nearest proxy vertex of
   a target vertex and ``ι_M`` the nearest source vertex of a proxy source vertex (the
   identity on a mesh below the threshold);
2. its ``k × k`` functional map on the given spectra, ``C₀ = Φ_Nᵀ A_N Π₀ Φ_M``, and ZoomOut from
   it to ``refine_to`` eigenpairs on the given spectra (the proxy's error of a few edge lengths
   is what ZoomOut removes: the low frequencies agree, the point map is read off the fine ones);
3. the point map over every target vertex, and the ``k × k`` map of it, as for any estimate.

The quality fields of the result (start, distortion, orientation, turn) are those measured on
the proxy; ``landmarks`` (when the derived estimate was kept) are carried to the given meshes'
vertices the same way.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._estimate import MapEstimate, check_pair_samples, to_given
from ._fmap import fmap_from_p2p, fmap_to_p2p, zoomout
from .._mesh import decimate
from .._sampling import subsample
from .._spectral import Spectrum, spectrum, unit_area_pair

__all__ = ["needs_proxy", "proxy_estimate"]


def needs_proxy(estimator, source_mesh, target_mesh) -> bool:
    """Whether the landmark-free choice runs on proxies: a mesh above ``proxy_above``."""
    return estimator.proxy_above is not None and max(
        source_mesh.n_vertices, target_mesh.n_vertices) > estimator.proxy_above


def proxy_estimate(estimator, source: Spectrum, target: Spectrum, source_mesh, target_mesh,
                   refine_to: int, samples, source_symmetry) -> MapEstimate:
    """The landmark-free estimate through proxies (the module's steps).

    **Arguments:**

    - `estimator`: the [`MapEstimator`][bsfjax.MapEstimator] (its ``proxy_above``,
      ``proxy_vertices``, ``k`` and ``zoomout_step``; the rest runs on the proxies as given).
    - `source`, `target`: the spectra, at least ``refine_to`` eigenpairs.
    - `source_mesh`, `target_mesh`: the meshes of the spectra.
    - `refine_to`: ZoomOut's final size.
    - `samples`: ZoomOut's ``(source, target)`` subsamples of the given meshes, or ``None``
      (then ``zoomout_samples`` new ones, or every vertex when that is ``None``).
    - `source_symmetry`: the source's mirror symmetry, used when the source is its own proxy.

    **Returns:** a [`MapEstimate`][bsfjax.MapEstimate] in the given bases, with ``proxy``
    the two proxies' vertex counts.
    """
    proxies = [decimate(m, estimator.proxy_vertices) if m.n_vertices > estimator.proxy_above
               else None for m in (source_mesh, target_mesh)]
    meshes = [m if d is None else d.mesh for m, d in zip((source_mesh, target_mesh), proxies)]
    spectra = [s.truncate(refine_to) if d is None else spectrum(d.mesh, refine_to)
               for s, d in zip((source, target), proxies)]
    inner = dataclasses.replace(estimator, refine_to=refine_to, proxy_above=None)
    est = inner(*spectra, source_mesh=meshes[0], target_mesh=meshes[1],
                source_symmetry=source_symmetry if proxies[0] is None else None)
    to_n = (np.arange(target.n_vertices) if proxies[1] is None else proxies[1].to_proxy)
    from_m, from_n = (np.arange(m.n_vertices) if d is None else d.from_proxy
                      for m, d in zip(meshes, proxies))
    p2p0 = from_m[np.asarray(est.p2p)[to_n]]  # T₀ = ι_M ∘ T_p ∘ π_N
    # the rest on the unit-area spectra, as every estimate (the maps back in the given bases)
    source, am, target, an = unit_area_pair(source, target)
    if samples is not None:
        samples = check_pair_samples(samples, source.n_vertices, target.n_vertices)
    elif estimator.zoomout_samples is not None:
        samples = (subsample(source_mesh, estimator.zoomout_samples),
                   subsample(target_mesh, estimator.zoomout_samples))
    k = estimator.k
    C0 = fmap_from_p2p(source.truncate(k), target.truncate(k), p2p0)
    C_ref = C0
    if refine_to > k:
        C_ref = zoomout(C0, source, target, refine_to, step=estimator.zoomout_step,
                        samples=samples)
    p2p = np.asarray(fmap_to_p2p(C_ref, source, target))
    C = np.asarray(fmap_from_p2p(source.truncate(k), target.truncate(k), p2p))
    landmarks = None if est.landmarks is None else (from_m[est.landmarks[0]],
                                                    from_n[est.landmarks[1]])
    return MapEstimate(C=to_given(C, am, an), p2p=p2p, C_initial=to_given(C0, am, an),
                       samples=samples, distortion=est.distortion, orientation=est.orientation,
                       start=est.start, landmarks=landmarks, swapped=est.swapped,
                       turn_doubtful=est.turn_doubtful,
                       proxy=tuple(m.n_vertices for m in meshes))
