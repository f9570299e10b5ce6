"""Size buckets: the few padded sizes a jitted stage compiles for, instead of one per size.

Owner of `BUCKET_FACTORS` and `size_bucket`, used by the per-target kernel of
[`bsfjax.transfer_collection`][bsfjax.transfer_collection] (vertex and face counts) and by the jitted farthest point
sampling (point counts).
"""

from __future__ import annotations

__all__ = ["BUCKET_FACTORS", "MERGE_PADDING", "merge_buckets", "size_bucket"]

#: Bucket sizes are ``c · 2^j`` for ``c`` in these factors: neighbouring sizes differ by at
#: most 1.5×, so padding adds at most 50 % (about 20 % on average) and a collection of
#: 3.4K–6.9K-vertex targets compiles the kernel for 2 or 3 sizes.
BUCKET_FACTORS = (4, 6)


def size_bucket(n: int) -> int:
    """The smallest ``c · 2^j ≥ n`` with ``c`` in `BUCKET_FACTORS` (``n ≥ 1``)."""
    j = max(0, int(n).bit_length() - 4)
    while True:
        for c in BUCKET_FACTORS:
            if c << j >= n:
                return c << j
        j += 1


#: Padded vertices worth one compilation: a bucket's targets are moved up to the next larger
#: bucket in use when that adds at most this many padded vertices over all of them.  Measured
#: on the 2-core CPU (``transfer_collection``, FAUST-like targets): one bucket's compilation
#: takes 4–6 s, a padded vertex ~1.5e-4 s of the per-target stages (≈ 30 000 vertices).
MERGE_PADDING = 20_000


def merge_buckets(sizes, max_padding: int = MERGE_PADDING) -> dict[int, int]:
    """For the bucket sizes of a collection's targets (one entry per target), the bucket each
    size is computed in: walking up from the smallest, a bucket's targets join the next larger
    bucket in use when the padding they gain, ``Σ (next − own)``, is at most ``max_padding``
    (so a small collection spread over several buckets compiles once, a large one keeps
    every bucket).  Padding never changes a result, only the time it takes."""
    count: dict[int, int] = {}
    for b in sizes:
        count[b] = count.get(b, 0) + 1
    order = sorted(count)
    into = {b: b for b in order}
    for lo, hi in zip(order, order[1:]):
        if count[lo] * (hi - lo) <= max_padding:  # lo's targets (with those merged into it)
            count[hi] += count[lo]
            for b, dest in into.items():
                if dest == lo:
                    into[b] = hi
    return into
