"""Metrics and test functions.

The area-weighted relative error of the paper (Eq. 14–15, square-root form,
`relative_error`), random connected region indicators, and conversions between part labels and
indicator functions, and the source labels a partial target has no place for
(`missing_labels`).
"""

from ._indicators import indicators_to_labels, labels_to_indicators, random_indicators
from ._relative_error import relative_error
from ._coverage import MISSING_RATIO, missing_labels

__all__ = [
    "MISSING_RATIO", "indicators_to_labels", "missing_labels", "labels_to_indicators", "random_indicators", "relative_error",
]
