"""Shared helpers below every stage.

Errors (`BSFError`, `MeshError`), argument checks that name the bad value, atomic file writes
and output transactions, BLAS-thread and memory control, sharding over JAX devices, size
buckets, Ctrl-C handling of the command line, and the package version.  Imports nothing
else of bsfjax.
"""

# first: the `bsfjax` command handles Ctrl-C from here on, before the heavy imports below
# (a no-op when bsfjax is imported as a library; see _signals)
from ._signals import exit_now, install_sigint_handler, is_cli_process

install_sigint_handler()

from ._buckets import BUCKET_FACTORS, MERGE_PADDING, merge_buckets, size_bucket
from ._devices import map_over_devices, n_devices, pad_leading, shard_leading
from ._errors import BSFError, MeshError
from ._files import (atomic_path, check_outputs, check_path_clashes, input_problem,
                     not_regular, output_transaction, write_text_atomic)
from ._memory import available_memory, format_bytes, release_free_memory
from ._threads import eigensolve_on_one_thread, on_one_blas_thread, one_blas_thread
from ._version import VERSION
from ._validate import (
    check_finite, check_indices, check_int, check_real, check_source_mesh, compact_labels,
    homogeneous, is_traced, magnitude_limit, non_integer_entry, pow2_scale, require_triangles,
    restore_scale, unit_scale,
)

__all__ = [
    "VERSION", "available_memory", "check_path_clashes", "format_bytes",
    "BSFError", "BUCKET_FACTORS", "MERGE_PADDING", "MeshError", "atomic_path", "check_finite",
    "check_indices", "check_int", "check_outputs", "check_real", "check_source_mesh",
    "compact_labels", "eigensolve_on_one_thread", "exit_now", "homogeneous",
    "install_sigint_handler", "is_cli_process", "is_traced", "magnitude_limit",
    "map_over_devices", "merge_buckets", "n_devices", "non_integer_entry", "on_one_blas_thread",
    "one_blas_thread", "output_transaction", "pad_leading", "pow2_scale", "release_free_memory",
    "require_triangles", "restore_scale", "shard_leading", "size_bucket", "unit_scale",
    "write_text_atomic", "input_problem", "not_regular",
]
