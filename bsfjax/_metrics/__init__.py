"""Metrics and test functions: area-weighted relative errors (paper Eq. 14–15) and region indicators."""

from ._indicators import indicators_to_labels, labels_to_indicators, random_indicators
from ._relative_error import relative_error

__all__ = [
    "indicators_to_labels", "labels_to_indicators", "random_indicators", "relative_error",
]
