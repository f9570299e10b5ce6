"""Size buckets: the few padded sizes a jitted stage compiles for, instead of one per size.

Owner of :data:`BUCKET_FACTORS` and :func:`size_bucket`, used by the per-target kernel of
:func:`bsfjax.transfer_collection` (vertex and face counts) and by the jitted farthest point
sampling (point counts).
"""

from __future__ import annotations

__all__ = ["BUCKET_FACTORS", "size_bucket"]

#: Bucket sizes are ``c · 2^j`` for ``c`` in these factors: neighbouring sizes differ by at
#: most 1.5×, so padding adds at most 50 % (about 20 % on average) and a collection of
#: 3.4K–6.9K-vertex targets compiles the kernel for 2 or 3 sizes.
BUCKET_FACTORS = (4, 6)


def size_bucket(n: int) -> int:
    """The smallest ``c · 2^j ≥ n`` with ``c`` in :data:`BUCKET_FACTORS` (``n ≥ 1``)."""
    j = max(0, int(n).bit_length() - 4)
    while True:
        for c in BUCKET_FACTORS:
            if c << j >= n:
                return c << j
        j += 1
