"""The ``bsfjax`` command line: ``demo``, ``example``, ``transfer``, ``reproduce``, ``spectrum``.

Bad input ends with a one-line message on stderr and exit status 2, never a traceback, and no
partial output file (every output is written atomically, after all the work is done).
"""

from __future__ import annotations

import contextlib
import sys
import warnings

from ._parser import _check_options, _join_option_values, build_parser


def main(argv: list[str] | None = None) -> int:
    """Run the `bsfjax` command with the arguments `argv` (default: `sys.argv[1:]`).

    **Returns:**

    The exit status: 0 on success, 2 for bad input, 130 after Ctrl-C.  In the `bsfjax`
    command's own process it exits with that status instead of returning.
    """
    from .._util import exit_now, install_sigint_handler

    if not install_sigint_handler():  # Ctrl-C: one line, exit 130, temporaries removed
        return _main(argv)  # (only in the command's own process, not when called from Python)
    try:
        status = _main(argv)
    except SystemExit as exc:  # argparse: --help, --version, usage errors
        if isinstance(exc.code, str):
            print(exc.code, file=sys.stderr)
        status = exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    exit_now(status)  # no interpreter finalization (see _signals)


@contextlib.contextmanager
def _use_compilation_cache():
    """Keep compiled programs between runs in JAX's persistent compilation cache, so that a
    second ``bsfjax`` call on meshes of the same sizes skips compilation (most of a short
    call's time: docs/benchmarks.md).  The folder is ``$XDG_CACHE_HOME/bsfjax/jax`` (default
    ``~/.cache``); ``JAX_COMPILATION_CACHE_DIR`` chooses another, and setting it empty turns
    the cache off.  JAX keys entries by the program, its options and the backend.

    Every program is kept, however fast it compiled: JAX keeps by default only those that took
    a second or more, and most of ours take 0.05–1 s each, so a second ``bsfjax transfer`` of a
    5.5K-vertex target took 6.4 s instead of 4.1 s (one entry kept instead of 50, 0.46 MB in
    all).  ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS`` still overrides it.

    A Python caller of [`main`][bsfjax.cli.main] gets its own threshold back when the command
    returns.  The folder stays: JAX sets its cache up once per process, at the first
    compilation that uses it, and a folder changed afterwards would not be read."""
    import os

    import jax

    previous = jax.config.jax_persistent_cache_min_compile_time_secs
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    if "JAX_COMPILATION_CACHE_DIR" not in os.environ:  # (set: JAX reads it itself; '' = off)
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"),
                                                                ".cache")
        jax.config.update("jax_compilation_cache_dir", os.path.join(base, "bsfjax", "jax"))
    try:
        yield
    finally:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", previous)


def _format_warning(message, category, filename, lineno, line=None) -> str:
    """A warning of the command as one line, ``bsfjax: warning: …`` (not Python's
    ``file:line: Category: …`` and source line, which mean nothing to a user of the command)."""
    text = " ".join(str(message).split()) or category.__name__
    return f"bsfjax: warning: {text}\n"


def _main(argv: list[str] | None) -> int:
    # the format only, while the command runs: a Python caller of main() that records
    # warnings (catch_warnings(record=True), pytest.warns) still gets them, and its own
    # format is back afterwards
    previous = warnings.formatwarning
    warnings.formatwarning = _format_warning
    try:
        return _run(argv)
    finally:
        warnings.formatwarning = previous


def _run(argv: list[str] | None) -> int:
    parser = build_parser()
    args = parser.parse_args(_join_option_values(sys.argv[1:] if argv is None else argv))
    if getattr(args, "func", None) is None:
        parser.print_help()
        return 0
    warnings.filterwarnings("ignore", message="JAXopt is no longer maintained")
    try:
        from .._util import output_transaction

        _check_options(args)
        # all outputs of the command are renamed together, or none
        with _use_compilation_cache(), output_transaction():
            return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:  # bad input: one line, no traceback
        msg = " ".join(str(exc).split()) or type(exc).__name__
        print(f"bsfjax {args.command}: error: {msg}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # pragma: no cover
        print(f"bsfjax {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
