"""The experiments of Melzi 2019 as library functions returning tidy tables, and ``reproduce``.

Each experiment returns a list of flat ``dict`` rows (one per function × method × setting, a
"tidy" table that `write_csv` writes and `summarize` aggregates).  One module per
table or figure, each with its experiment function and its report:

* ``table1`` — approximation error (Eq. 14) vs k ∈ {10, 30, 50, 70, 90}:
  `approximation_experiment` (`.table1`);
* ``table2`` — transfer error (Eq. 15) with ground-truth maps, same k:
  `transfer_experiment` (`.table2`);
* ``fig7`` — transfer error as k_N grows, k_M ∈ {10, 30, 50}: `kn_experiment`
  (`.fig7`);
* ``table3`` — frame build time (geod, heat, ours): `frame_time_experiment`
  (`.table3`);
* ``table4`` — time to transfer one function with estimated maps:
  `transfer_time_experiment` (`.table4`);
* ``table5`` — TOSCA classes, estimated 10×10 and 30×30 maps, two parameter sets:
  `tosca_experiment` (`.table5`);
* ``fig10`` — dependence on the n_BSF share, FPS distance, γ, ε and S:
  `parameter_experiment` (`.fig10`);
* ``sparse`` (beyond the paper) — approximation and transfer error (ground-truth and estimated
  maps) against the number of non-zeros, paper scales vs ``taus="adaptive"`` vs the projection
  with as many coefficients: `sparse_experiment` (`.sparse`).

Errors are the square-root form ``‖f − f̃‖_A / ‖f‖_A`` ([`bsfjax.relative_error`][bsfjax.relative_error]).
Test functions are random connected indicators covering 5–25 % of the area
([`bsfjax.random_indicators`][bsfjax.random_indicators]), drawn on each source shape from ``seed``.  Settings are the
paper's: n_BSF = 5 % of the vertices by Euclidean farthest point sampling, τ ∈ {0.001, 0.005,
0.01} (unit-area convention), γ = 0.75, OMP S = 10, ``omp_error`` ε = ‖f‖/10.  Ground-truth
maps are ``C = Φ_Nᵀ A_N Π Φ_M`` ([`bsfjax.fmap_from_p2p`][bsfjax.fmap_from_p2p]); the ``p2p`` baseline uses the
point map recovered from the same ``k × k`` map ([`bsfjax.fmap_to_p2p`][bsfjax.fmap_to_p2p]), so every method
sees the same information.  Estimated maps (tables 4–5) minimise descriptor preservation +
Laplacian and descriptor commutativity ([`bsfjax.estimate_fmap`][bsfjax.estimate_fmap]) with WKS descriptors plus
WKS at 5 landmarks (chosen by farthest point sampling on the target, paired through the ground
truth).  All pairs of one size are stacked and every method runs on all pairs × functions in
one jitted ``vmap``; only methods, settings and groups of differently sized pairs are Python
loops.

Layout of the package:

* ``_registry.py``: `Experiment` records, `EXPERIMENTS` (name → record) and
  `reproduce` (looks the name up, runs it, writes ``NAME.csv``, ``NAME.md``,
  ``NAME.json`` and, for figures, ``NAME.png``);
* ``_engine.py``: the **only** module that calls the transfer engine (methods, settings,
  pair inputs, frames and coders); switching engines changes that file alone;
* ``_io.py``: CSV, summaries, Markdown pivots, PNG line plots, atomic writes;
* ``_shapes.py``: shapes (spectra, centres), test functions, functional maps;
* ``_datasets.py``: ``--data`` folders (`load_dataset`);
* one module per table or figure: ``table1.py`` … ``sparse.py``.

**Adding an experiment** = one new module + one registry line.  The module (say
``segmentation.py``) defines ``DESCRIPTION`` (the first paragraph of ``NAME.md``),
``DEFAULT_KS``, ``run(dataset, *, pairs, functions, ks, seed, cache_dir, progress) -> rows``
and ``report(rows, ks) -> Report`` (Markdown, optional figure panels, optional settings line),
calling the engine only through ``_engine``; then in ``_registry.py`` import it and add
``_entry("segmentation", segmentation),`` to `EXPERIMENTS` — ``reproduce`` and the
``bsfjax reproduce`` command pick it up from there.
"""

from __future__ import annotations

from ._datasets import Dataset, load_dataset
from ._engine import APPROX_METHODS, CODERS, KN_METHODS, PARAMETER_SETS, TRANSFER_METHODS
from ._io import Report, pivot_markdown, summarize, write_csv
from ._registry import EXPERIMENTS, Experiment, cli, reproduce
from ._shapes import N_LANDMARKS, ShapeData, _functions, prepare_shapes
from .fig7 import kn_experiment
from .fig10 import SWEEPS, parameter_experiment
from .sparse import SPARSE_FRAMES, SPARSITIES, sparse_experiment
from .table1 import DEFAULT_KS, approximation_experiment
from .table2 import transfer_experiment
from .table3 import frame_time_experiment
from .table4 import transfer_time_experiment
from .table5 import tosca_experiment

__all__ = [
    "EXPERIMENTS", "Experiment", "Report", "DEFAULT_KS", "APPROX_METHODS", "TRANSFER_METHODS",
    "CODERS",
    "PARAMETER_SETS", "ShapeData", "prepare_shapes", "approximation_experiment",
    "transfer_experiment", "kn_experiment", "frame_time_experiment", "transfer_time_experiment",
    "tosca_experiment", "parameter_experiment", "sparse_experiment", "SPARSITIES",
    "SPARSE_FRAMES", "summarize", "pivot_markdown", "write_csv", "reproduce", "Dataset",
    "load_dataset",
]
