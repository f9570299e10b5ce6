"""Ctrl-C for the ``bsfjax`` command: one line, exit status 130, no temporary file left.

Python's default SIGINT handling raises ``KeyboardInterrupt`` wherever the main thread is:
inside an import of the start-up it prints a traceback (and an exception caught by a library
can even end in exit status 0), and after it the interpreter finalizes while XLA's thread
pools are still running, which segfaults now and then.  The command's handler therefore does
its own clean-up (the temporary files of `bsfjax._util._files`), prints one line and ends the
process with ``os._exit(130)``, skipping the interpreter finalization altogether.

It is installed as early as possible: by ``bsfjax/__init__.py`` *before* its heavy imports
when this process is the ``bsfjax`` command (the console script or ``python -m bsfjax.cli``),
and again by [`bsfjax.cli.main`][bsfjax.cli.main].  A library user's process (``import bsfjax``, or
``bsfjax.cli.main([...])`` called from Python) keeps the ordinary ``KeyboardInterrupt``.

This module imports nothing heavy: it runs before jax is imported.
"""

from __future__ import annotations

import os
import signal
import sys

EXIT_INTERRUPTED = 130


def is_cli_process() -> bool:
    """Whether this interpreter was started as the ``bsfjax`` command."""
    argv = list(getattr(sys, "orig_argv", None) or [])
    if "-m" in argv[:-1]:
        return argv[argv.index("-m") + 1] in ("bsfjax.cli", "bsfjax")
    script = os.path.basename(sys.argv[0]) if sys.argv and sys.argv[0] else ""
    return script in ("bsfjax", "bsfjax.exe", "bsfjax-script.py")


def _on_sigint(signum, frame) -> None:  # pragma: no cover - runs in a subprocess
    try:
        files = sys.modules.get(__name__.rsplit(".", 1)[0] + "._files")  # loaded, never imported here
        if files is not None:
            files.remove_live_temps()
        sys.stdout.flush()
    except BaseException:  # a closed pipe must not stop the exit
        pass  # (best effort: the process ends on the next lines whatever happened here)
    try:
        os.write(2, b"bsfjax: interrupted\n")
    except OSError:  # stderr closed: the exit status alone says it was interrupted
        pass
    os._exit(EXIT_INTERRUPTED)


def exit_now(status: int) -> None:  # pragma: no cover - ends the process
    """End the command with ``status`` without finalizing the interpreter: a SIGINT during the
    finalization would meet the default handler again (status -2), and XLA's threads torn
    down under a finalizing interpreter can segfault.  The outputs are already committed."""
    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})  # the end is decided
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except BaseException:  # a closed pipe: the outputs are committed, the exit goes on
            pass
    os._exit(int(status))


def install_sigint_handler() -> bool:
    """Install the command's SIGINT handler (only in the ``bsfjax`` command's own process, and
    only from the main thread); returns whether this is the command's process.

    An inherited ``SIG_IGN`` (``nohup bsfjax … &``, a background job of a script) is kept, as
    Python itself keeps it: such a job is not meant to be stopped by the terminal's Ctrl-C.
    """
    if not is_cli_process():
        return False
    try:
        if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:
            signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:  # not the main thread
        return False
    return True
