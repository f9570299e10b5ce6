"""Atomic file writing: a reader sees either the old file or the complete new one.

Every file bsfjax writes goes through `atomic_path`: the content is written to a
temporary file in the destination folder (same filesystem, so the final ``os.replace`` is
atomic on POSIX and Windows), flushed to disk, then renamed over the destination.  An
interrupted run leaves the previous file untouched and at worst a stray ``.tmp`` file.

Two additions for the command line:

* every live temporary file is recorded in `LIVE_TEMPS`, so that the SIGINT handler of
  `bsfjax._util._signals` can remove them before it ends the process;
* `output_transaction`: inside it, `atomic_path` does not rename at the end but
  queues the rename; on a clean exit all queued files are renamed together (with SIGINT
  blocked), on an error none is, so one command writes all its outputs or none.
"""

from __future__ import annotations

import contextlib
import os
import signal
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

from ._errors import BSFError

#: Temporary files that exist right now (removed by the SIGINT handler of the CLI).
LIVE_TEMPS: set[Path] = set()
#: The open `output_transaction`'s queue of ``(temporary, destination)``, or ``None``.
_PENDING: list[tuple[Path, Path]] | None = None


@contextlib.contextmanager
def _no_sigint() -> Iterator[None]:
    """Defer SIGINT (main thread only) so that a temp file is never created unrecorded, nor a
    set of renames cut in half; the signal is delivered when the block ends."""
    main = threading.current_thread() is threading.main_thread()
    if main and hasattr(signal, "pthread_sigmask"):
        old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            yield
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)
    else:
        yield


def _cannot_write(dest: Path, exc: OSError) -> BSFError:
    # the user's path and the reason, never the temporary file's name
    anc = dest.parent
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if anc.exists() and not anc.is_dir():  # mkdir says "File exists", which misleads
        return BSFError(f"{dest}: cannot write ({anc} is not a folder)")
    return BSFError(f"{dest}: cannot write ({exc.strerror or type(exc).__name__})")


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike, suffix: str | None = None, *,
                immediate: bool = False) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success it is renamed onto ``path``.

    ``suffix`` defaults to the destination's own suffix so that writers that infer the
    format from the file name (meshio, numpy) pick the right one.  An ``OSError`` while
    writing becomes a [`BSFError`][bsfjax.BSFError] naming ``path``.  ``immediate``: rename at once even
    inside an `output_transaction` (caches, which are not outputs of the command).
    """
    dest = Path(path)
    suffix = dest.suffix if suffix is None else suffix
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
        with _no_sigint():
            fd, tmp = tempfile.mkstemp(prefix=f".{dest.name}.", suffix=".tmp" + suffix,
                                       dir=dest.parent)
            LIVE_TEMPS.add(Path(tmp))
        os.close(fd)
    except OSError as exc:
        raise _cannot_write(dest, exc) from None
    tmp_path = Path(tmp)
    # mkstemp creates 0600; give the result the permissions a plain open() would have
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)
    queued = False
    try:
        try:
            yield tmp_path
            with open(tmp_path, "rb+") as fh:  # make the bytes durable before the rename
                os.fsync(fh.fileno())
            if _PENDING is not None and not immediate:
                _PENDING.append((tmp_path, dest))
                queued = True
            else:
                with _no_sigint():
                    os.replace(tmp_path, dest)
                    LIVE_TEMPS.discard(tmp_path)
        except OSError as exc:
            raise _cannot_write(dest, exc) from None
    finally:
        if not queued:
            with _no_sigint():
                tmp_path.unlink(missing_ok=True)
                LIVE_TEMPS.discard(tmp_path)


@contextlib.contextmanager
def output_transaction() -> Iterator[None]:
    """All `atomic_path` writes inside are committed together at the end, or none.

    On success the queued temporaries are renamed onto their destinations with SIGINT
    deferred; if a rename fails, the files renamed before it are put back (the previous
    content from a hard-link backup, or removed if there was none) and the rest discarded.
    """
    global _PENDING
    if _PENDING is not None:  # nested: the outer transaction commits
        yield
        return
    _PENDING = []
    try:
        yield
        queue = list(_PENDING)
        _commit(queue)
    finally:
        queue, _PENDING = _PENDING, None
        with _no_sigint():
            for tmp, _ in queue:
                tmp.unlink(missing_ok=True)
                LIVE_TEMPS.discard(tmp)


def _commit(queue: list[tuple[Path, Path]]) -> None:
    with _no_sigint():
        backups: list[tuple[Path, Path | None]] = []
        try:
            for tmp, dest in queue:
                backup = None
                if dest.is_file():
                    backup = dest.with_name(f".{dest.name}.{os.getpid()}.bak")
                    LIVE_TEMPS.add(backup)
                    try:
                        os.link(dest, backup)
                    except OSError:
                        backup = None
                try:
                    os.replace(tmp, dest)
                except OSError as exc:
                    raise _cannot_write(dest, exc) from None
                LIVE_TEMPS.discard(tmp)
                backups.append((dest, backup))
        except BaseException:
            for dest, backup in reversed(backups):  # undo: old content back, new files gone
                if backup is not None:
                    os.replace(backup, dest)
                else:
                    dest.unlink(missing_ok=True)
            raise
        finally:
            for _, backup in backups:
                if backup is not None:
                    backup.unlink(missing_ok=True)
                    LIVE_TEMPS.discard(backup)


def remove_live_temps() -> None:
    """Remove every temporary file bsfjax is writing (the SIGINT handler's clean-up)."""
    for p in list(LIVE_TEMPS):
        try:
            p.unlink(missing_ok=True)
        except OSError:  # (on the way out: the other temporaries are still removed)
            pass
    LIVE_TEMPS.clear()


def write_bytes_atomic(path: str | os.PathLike, data: bytes, *, immediate: bool = False) -> None:
    """Write ``data`` to ``path`` atomically (``immediate``: as `atomic_path`)."""
    with atomic_path(path, immediate=immediate) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | os.PathLike, text: str, *, immediate: bool = False) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically (``immediate``: as `atomic_path`)."""
    write_bytes_atomic(path, text.encode("utf-8"), immediate=immediate)


def not_regular(path: str | os.PathLike) -> str | None:
    """What an existing input path that is neither a regular file nor a folder is (``"a named
    pipe (FIFO)"``, ``"a socket"``, ``"a character device"``, ``"a block device"``), or ``None``.
    Reading such a path would block (a FIFO without a writer) or never end, so readers refuse
    it by name instead of calling it a missing file."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except (OSError, ValueError):
        return None
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    for test, what in ((stat.S_ISFIFO, "a named pipe (FIFO)"), (stat.S_ISSOCK, "a socket"),
                       (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device")):
        if test(mode):
            return what
    return "a special file"


def input_problem(path: str | os.PathLike) -> str | None:
    """Why ``path`` cannot be read as an input file (``"no such file"``, ``"is a folder"``,
    ``"is a named pipe (FIFO), not a regular file"``, …), or ``None`` for a regular file."""
    p = Path(path)
    if p.is_file():
        return None
    if p.is_dir():
        return "is a folder"
    kind = not_regular(p)
    return f"is {kind}, not a regular file" if kind else "no such file"


def _same(a: Path, b: Path) -> bool:
    try:
        return a.resolve() == b.resolve() or (a.exists() and b.exists() and os.path.samefile(a, b))
    except OSError:
        return False


def check_outputs(outputs: dict[str, str | os.PathLike | None],
                  inputs: dict[str, str | os.PathLike | None] | None = None, *,
                  folders: tuple[str, ...] = ()) -> None:
    """Check output paths before any work, so that a bad one costs nothing.

    ``outputs`` / ``inputs``: ``{option name: path}`` (``None`` entries are skipped);
    ``folders``: the option names whose path is an output folder (created if missing), the
    others are files.  Raises [`BSFError`][bsfjax.BSFError] naming the option and the path as given when
    an output is an existing folder (file outputs) or file (folder outputs), lies in a folder
    that cannot be created or written, is the same path as an input, or two outputs are the
    same path.
    """
    outs = {k: Path(v) for k, v in outputs.items() if v is not None}
    ins = {k: Path(v) for k, v in (inputs or {}).items() if v is not None}
    for name, p in outs.items():
        is_folder = name in folders
        if is_folder and p.exists() and not p.is_dir():
            raise BSFError(f"{name} {str(p)!r}: exists and is not a folder")
        if not is_folder and p.is_dir():
            raise BSFError(f"{name} {str(p)!r}: is a folder; give a file name")
        # the nearest existing ancestor must be a writable folder (we create the rest)
        anc = (p if is_folder else p.parent).absolute()
        while not anc.exists() and anc != anc.parent:
            anc = anc.parent
        if not anc.is_dir():
            raise BSFError(f"{name} {str(p)!r}: {str(anc)!r} is not a folder")
        if not os.access(anc, os.W_OK | os.X_OK):
            raise BSFError(f"{name} {str(p)!r}: folder {str(anc)!r} is not writable")
        for iname, q in ins.items():
            if _same(p, q):
                raise BSFError(f"{name} {str(p)!r} is the same path as the input {iname} "
                               f"{str(q)!r}: it would be overwritten")
    names = list(outs)
    for i, a in enumerate(names):
        for b in names[i + 1:]:
            if _same(outs[a], outs[b]):
                raise BSFError(f"{a} and {b} are the same path {str(outs[a])!r}")


def check_path_clashes(outputs, inputs=()) -> None:
    """Check every output path of a command against every input path and against each
    other, before any work.

    ``outputs`` / ``inputs``: ``(what, path)`` pairs, ``what`` naming the option and the file
    (``"--out-dir output for target a.off"``).  Paths are compared resolved (symbolic links,
    ``..``), so a folder given twice under two spellings is one folder.  Raises
    [`BSFError`][bsfjax.BSFError], one line naming both: an output that is an input would be
    overwritten (or, existing, taken for a finished output); two equal outputs would replace
    each other."""
    def key(p) -> str:
        r = os.path.realpath(os.fspath(p))
        return os.path.normcase(r)

    ins: dict[str, tuple[str, str]] = {}
    for what, p in inputs:
        if p is not None:
            ins.setdefault(key(p), (what, os.fspath(p)))
    outs: dict[str, tuple[str, str]] = {}
    for what, p in outputs:
        if p is None:
            continue
        k = key(p)
        if k in ins:
            iwhat, ip = ins[k]
            raise BSFError(f"{what} {os.fspath(p)!r} is the same file as the input {iwhat} "
                           f"{ip!r}: it would be overwritten")
        if k in outs:
            owhat, op = outs[k]
            raise BSFError(f"{owhat} {op!r} and {what} {os.fspath(p)!r} are the same file: "
                           "one would overwrite the other")
        outs[k] = (what, os.fspath(p))
