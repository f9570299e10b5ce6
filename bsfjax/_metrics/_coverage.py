"""Which source labels (parts) have no counterpart on a target: a partial target's report.

Owner of [`missing_labels`][bsfjax.missing_labels] and its rule, `MISSING_RATIO`.
"""

from __future__ import annotations

import numpy as np

from .._util import BSFError

__all__ = ["MISSING_RATIO", "missing_labels"]

#: A source label is missing on the target when its share of the target's area is below this
#: fraction of its share of the source's area.
MISSING_RATIO = 0.25


def missing_labels(source_labels, source_area, target_labels, target_area,
                   ratio: float = MISSING_RATIO) -> np.ndarray:
    """The source labels that have (almost) no counterpart on the target.

    With ``a_M(l) = Σ_{i: l_i = l} A_M,i / Σ_i A_M,i`` the share of the source's area labelled
    ``l`` and ``a_N(l)`` the same on the target (its transferred labels), label ``l`` is
    missing when ``a_N(l) < ratio · a_M(l)``: the transfer found no place for most of that part
    (a limb cut off, a part inside a hole).  Shares are of each mesh's own area, so a target
    that lost some parts gives every kept part a larger share, never a smaller one.

    **Arguments:**

    - `source_labels`: ``(n_M,)`` int labels of the source (negative: no label, ignored).
    - `source_area`: ``(n_M,)`` vertex (or triangle) areas of the source.
    - `target_labels`: ``(n_N,)`` the transferred labels (−1: unassigned).
    - `target_area`: ``(n_N,)`` areas of the target's vertices (triangles).
    - `ratio`: the fraction (default ``MISSING_RATIO`` = 0.25).

    **Returns:** ``(K,)`` int64, the missing labels in increasing order.
    """
    ls, ws = np.asarray(source_labels), np.asarray(source_area, np.float64)
    lt, wt = np.asarray(target_labels), np.asarray(target_area, np.float64)
    if ls.shape != ws.shape or lt.shape != wt.shape or ls.ndim != 1 or lt.ndim != 1:
        raise BSFError(f"labels and areas must be matching 1-D arrays, got source {ls.shape} / "
                       f"{ws.shape} and target {lt.shape} / {wt.shape}")
    if not 0 < ratio <= 1:
        raise BSFError(f"ratio must be in (0, 1], got {ratio!r}")
    ids = np.unique(ls[ls >= 0])
    if ids.size == 0 or ws.sum() <= 0 or wt.sum() <= 0:
        return np.zeros(0, np.int64)
    share_m = np.array([ws[ls == i].sum() for i in ids]) / ws.sum()
    share_n = np.array([wt[lt == i].sum() for i in ids]) / wt.sum()
    return ids[share_n < ratio * share_m].astype(np.int64)
