"""Output files: one preflight check before any work, and one atomic write, for every file the
tool writes (results, checkpoints, sweeps, figures, tables, reports).

Rules (the exit-code contract of the README):

- *Preflight*: an output is checked before any work: its name is valid text (a name that is not
  UTF-8 could not be stored in the file's provenance), its directory exists and is writable, and
  an existing entry is a regular file and is only replaced when ``--overwrite`` was given on the
  command line that runs. Directories, devices, FIFOs, sockets and symbolic links are never
  replaced (``os.replace`` swaps the directory entry, whatever it is: ``--out /dev/null
  --overwrite`` as root would replace the system's ``/dev/null``).
- *Atomic write*: the content is built completely in memory, written to a temporary file in the
  destination's directory with ``os.write`` (a full disk is a plain ``OSError`` here, where
  libhdf5 flushing its own file on ENOSPC dies with SIGSEGV), fsynced, then renamed into place.
  Any failure removes the temporary file and raises :class:`WriteError`: one line saying which
  file, why, and that nothing was written there.
- *Temporary files and signals*: every temporary file is registered while it exists, so that a
  signal handler can remove it before the process ends (:func:`remove_temporaries`).
"""

from __future__ import annotations

import contextlib
import os
import signal
import stat
import tempfile
import threading
from collections.abc import Callable, Iterator
from pathlib import Path

__all__ = ["Signalled", "WriteError", "check_output", "raise_pending", "reason", "record_signal", "remove_temporaries",
           "signals_interrupt", "take_pending", "write_all", "write_atomic"]

# Temporary files being written now, removed by a signal handler before the process ends.
_TEMPORARIES: set[str] = set()
# Files this process put in place (absolute paths): a signal that lands just after a result was
# written must not be reported as if the result were still to be written (M17).
_PLACED: set[str] = set()


def placed(path: str | os.PathLike) -> bool:
    """Whether this process has put ``path`` in place with :func:`write_atomic`."""
    return os.path.abspath(path) in _PLACED


class WriteError(OSError):
    """A file could not be written (disk full, I/O error, permission): one line saying which
    file, why, and what was kept. ``errno`` is the operating system's error number."""

    def __init__(self, message: str, errno: int | None = None) -> None:
        super().__init__(message)
        self.errno = errno

    def __str__(self) -> str:
        return str(self.args[0])


def reason(error: BaseException) -> str:
    """The operating system's one-line reason for ``error`` ("No space left on device"); HDF5's
    multi-line messages are cut to that."""
    errno = getattr(error, "errno", None)
    if isinstance(errno, int) and errno > 0:
        return os.strerror(errno)
    text = " ".join(str(error).split())
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def _show(p: Path | str) -> str:
    """A path for a message: ``repr`` of its text (surrogates from undecodable bytes escaped)."""
    return repr(str(p))


def _kind(mode: int) -> str:
    if stat.S_ISDIR(mode):
        return "a directory, not a file"
    if stat.S_ISFIFO(mode):
        return "a FIFO (named pipe), not a regular file"
    if stat.S_ISCHR(mode) or stat.S_ISBLK(mode):
        return "a device, not a regular file"
    if stat.S_ISSOCK(mode):
        return "a socket, not a regular file"
    return "not a regular file"


def check_output(path: str | os.PathLike, *, overwrite: bool = False, name: str = "out",
                 directory: bool = True) -> Path:
    """Refuse, before any work, an output that cannot be written or must not be replaced.

    ``name`` is the CLI parameter (``out``, ``checkpoint``) the message names. Raises
    ``ValueError`` (bad input, exit 2) with one line; returns the path. ``directory=False``
    leaves the directory to the write itself: after the work, a directory that went away is a
    failure (:class:`WriteError`, exit 1), not bad input.
    """
    p = Path(path)
    text = str(p)
    label = f"{name}={_show(p)} is not accepted"
    if text in ("", "."):
        raise ValueError(f"{label}: an empty name; give a file name")
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        raise ValueError(f"{label}: the name is not valid UTF-8 text; choose a name in UTF-8") from None
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        st = None
    except OSError as exc:
        raise ValueError(f"{label}: {reason(exc)}") from None
    if st is not None:
        if stat.S_ISLNK(st.st_mode):
            target = os.readlink(p)
            raise ValueError(f"{label}: it is a symbolic link (to {_show(target)}); name the file itself")
        if not stat.S_ISREG(st.st_mode):
            raise ValueError(f"{label}: it is {_kind(st.st_mode)}")
        if not overwrite:
            raise ValueError(f"{label}: the file exists (pass --overwrite to replace it)")
    parent = p.parent if str(p.parent) else Path(".")
    if not directory:
        return p
    if not parent.is_dir():
        raise ValueError(f"{label}: the directory {_show(parent)} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ValueError(f"{label}: the directory {_show(parent)} is not writable")
    _probe(p, parent, label)
    return p


#: The temporary name :func:`write_atomic` writes first, ``.NAME.XXXXXXXX.tmp``, is this many
#: bytes longer than NAME.
TEMP_EXTRA = len(".") + len(".") + 8 + len(".tmp")


def _probe(p: Path, parent: Path, label: str) -> None:
    """Create and remove the temporary file the write will create, before any work.

    ``os.access`` answers from permission bits: root is "allowed" to write in ``/sys`` or
    ``/proc``, where creating a file then fails, and a valid name 242 to 255 bytes long makes
    the temporary name (:data:`TEMP_EXTRA` bytes longer) exceed the file system's NAME_MAX.
    Both were found only when the finished result was written, and the result lost."""
    size = len(os.fsencode(p.name))
    try:
        name_max = os.pathconf(parent, "PC_NAME_MAX")
    except (OSError, ValueError):
        name_max = 255
    if size + TEMP_EXTRA > name_max:
        raise ValueError(f"{label}: the name is {size} bytes long; the file is written first under a "
                         f"temporary name {TEMP_EXTRA} bytes longer, and this file system allows "
                         f"{name_max}: choose a name of at most {name_max - TEMP_EXTRA} bytes")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=parent)
    except OSError as exc:
        raise ValueError(f"{label}: a file cannot be created in the directory {_show(parent)} "
                         f"({reason(exc)})") from None
    os.close(fd)
    with contextlib.suppress(OSError):
        os.unlink(tmp)


def write_all(fd: int, data: bytes | memoryview) -> None:
    view = memoryview(data).cast("B")
    while view:
        n = os.write(fd, view)
        view = view[n:]


def write_atomic(path: str | os.PathLike, data: bytes | memoryview | Callable[[int], None], *,
                 overwrite: bool = False, name: str = "out", kept: str = "nothing was written there") -> Path:
    """Put ``data`` at ``path`` atomically: temporary file in the same directory, fsync, rename.

    ``data`` is the complete content, or a function writing it to the open file descriptor it is
    given (for content too large to build twice). Without ``overwrite`` the file is put in place
    with a hard link, which fails if ``path`` exists: of two processes finishing at once one
    writes and the other is refused (``ValueError``), never a silent overwrite. With
    ``overwrite`` only a regular file is replaced. A failed write raises :class:`WriteError`
    ``cannot write NAME='PATH': REASON; KEPT``; the temporary file is always removed.
    """
    p = Path(path)
    parent = p.parent if str(p.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=parent)
    except OSError as exc:
        raise _write_error(p, name, exc, kept) from None
    _TEMPORARIES.add(tmp)
    try:
        try:
            try:
                if callable(data):
                    data(fd)
                else:
                    write_all(fd, data)
                os.fsync(fd)
                # mkstemp creates the file 0600; give it the permissions a plain open() would have.
                umask = os.umask(0)
                os.umask(umask)
                os.fchmod(fd, 0o666 & ~umask)
            finally:
                os.close(fd)
            _put_in_place(tmp, p, overwrite, name)
            _PLACED.add(os.path.abspath(p))
        except OSError as exc:
            raise _write_error(p, name, exc, kept) from None
    finally:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _TEMPORARIES.discard(tmp)
    with contextlib.suppress(OSError):  # make the rename itself durable (POSIX)
        dfd = os.open(parent, os.O_RDONLY)
        try:
            os.fsync(dfd)
        finally:
            os.close(dfd)
    return p


def _write_error(p: Path, name: str, exc: OSError, kept: str) -> WriteError:
    if isinstance(exc, FileNotFoundError):
        why = "its directory does not exist (any more)"
    else:
        why = reason(exc)
    return WriteError(f"cannot write {name}={_show(p)}: {why}; {kept}", getattr(exc, "errno", None))


def _put_in_place(tmp: str, p: Path, overwrite: bool, name: str) -> None:
    """Rename ``tmp`` to ``p``; without ``overwrite`` atomically refuse an existing ``p``; never
    replace anything but a regular file (what appeared there while the work ran is re-checked)."""
    try:
        st = os.lstat(p)
    except FileNotFoundError:
        st = None
    if st is not None and not stat.S_ISREG(st.st_mode):
        what = "a symbolic link" if stat.S_ISLNK(st.st_mode) else _kind(st.st_mode)
        raise ValueError(f"{name}={_show(p)} is not accepted: it is {what} (it appeared while this "
                         "run worked); it was not replaced")
    if overwrite:
        os.replace(tmp, p)
        return
    try:
        os.link(tmp, p)  # FileExistsError if another process got there first
    except FileExistsError:
        raise ValueError(f"{name}={_show(p)} is not accepted: the file exists (another process wrote it "
                         "while this one ran; pass --overwrite to replace it)") from None
    except OSError as exc:
        if isinstance(exc, FileNotFoundError):
            raise
        if p.exists() or p.is_symlink():  # a file system without hard links: check, then rename
            raise ValueError(f"{name}={_show(p)} is not accepted: the file exists (pass --overwrite "
                             "to replace it)") from None
        os.replace(tmp, p)


def remove_temporaries() -> None:
    """Remove the temporary files being written now (called by a signal handler before the
    process ends, so that no ``.NAME.*.tmp`` survives a signal)."""
    for tmp in list(_TEMPORARIES):
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        _TEMPORARIES.discard(tmp)


class Signalled(KeyboardInterrupt):
    """SIGTERM or SIGHUP arrived: unwind like Ctrl-C (``finally`` blocks remove temporary
    files, a checkpointed run has saved its state), then exit with ``128 + signum``."""

    def __init__(self, signum: int) -> None:
        super().__init__(f"signal {signum}")
        self.signum = int(signum)


# Signals delivered during a command (:func:`signals_interrupt`) whose exception may have been
# dropped: Python prints and discards an exception raised in a weakref callback or ``__del__``
# ("Exception ignored in ..."). A Ctrl-C that landed in the import system's module-lock
# callback vanished so, and the run went on to its end and exited 0 (a fresh-clone CI run at
# eced1d9). Each is taken back at the next point where the command can stop
# (:func:`raise_pending`, a checkpointed run's :func:`stochpend.runs.checkpoint.deferred_signals`).
_PENDING: list[int] = []
# Whether a command listens (inside signals_interrupt): only then is a signal recorded. A Python
# caller's second Ctrl-C of a checkpointed run raises as Python does, and nothing is left behind
# to stop that caller's next run.
_LISTENING = [False]


def _interrupt(signum: int) -> KeyboardInterrupt:
    return KeyboardInterrupt() if signum == signal.SIGINT else Signalled(signum)


def take_pending() -> int | None:
    """The first signal delivered during this command and not yet taken back (None: none), and
    forget them all. Called from ordinary code, not while the signal's exception unwinds: a
    signal still pending there had its exception dropped."""
    if not _PENDING:
        return None
    signum = _PENDING[0]
    _PENDING.clear()
    return signum


def record_signal(signum: int) -> None:
    """Record a signal whose exception a handler is about to raise (:func:`take_pending`), while
    a command listens (:func:`signals_interrupt`); outside one, nothing."""
    if _LISTENING[0]:
        _PENDING.append(int(signum))


def raise_pending() -> None:
    """Raise again a signal whose exception was dropped (:func:`take_pending`): at a kernel
    boundary, so that a Ctrl-C stops the run however it landed. Only in the main thread, where
    Python raises the signal's own exception (a Dask worker's thread leaves it there)."""
    if _PENDING and threading.current_thread() is threading.main_thread():
        signum = take_pending()
        assert signum is not None
        raise _interrupt(signum)


@contextlib.contextmanager
def signals_interrupt() -> Iterator[None]:
    """Turn SIGTERM and SIGHUP (a batch system's stop, a dropped SSH session) into
    :class:`Signalled` for the duration of a command, as Python does SIGINT into
    ``KeyboardInterrupt``, and record each of the three signals until the command takes it back
    (:func:`raise_pending`: an exception dropped in a weakref callback must not lose it). A
    signal ignored when the command started stays ignored. Outside the main thread this does
    nothing."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        record_signal(signum)
        if signum != signal.SIGINT:
            remove_temporaries()
        raise _interrupt(signum)

    previous = {}
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        current = signal.getsignal(sig)
        # SIGINT only where it is Python's own (a caller's handler, or SIG_IGN, stays).
        if current is not signal.SIG_IGN and (sig != signal.SIGINT or current is signal.default_int_handler):
            previous[sig] = signal.signal(sig, handler)
    _PENDING.clear()
    _LISTENING[0] = True
    try:
        yield
    finally:
        _LISTENING[0] = False
        for sig, old in previous.items():
            # A disposition set meanwhile stays: an exiting command ignores further signals
            # (stochpend.cli._common._stop_listening), and a second Ctrl-C must not kill it.
            if signal.getsignal(sig) is handler:
                signal.signal(sig, old)
        _PENDING.clear()
