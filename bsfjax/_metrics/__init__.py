"""Metrics and test functions.

The area-weighted relative error of the paper (Eq. 14–15, square-root form,
`relative_error`), random connected region indicators, and conversions between part labels and
indicator functions.
"""

from ._indicators import indicators_to_labels, labels_to_indicators, random_indicators
from ._relative_error import relative_error

__all__ = [
    "indicators_to_labels", "labels_to_indicators", "random_indicators", "relative_error",
]
