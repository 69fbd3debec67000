"""Results files: NetCDF (h5netcdf engine), written atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import xarray as xr

__all__ = ["WriteError", "check_output_path", "open_results", "reason", "to_netcdf"]


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


def check_output_path(path: str | os.PathLike, *, overwrite: bool = False, name: str = "out") -> Path:
    """Refuse, before any work, an output that exists (without overwrite) or cannot be written."""
    p = Path(path)
    if p.exists() and not overwrite:
        raise ValueError(f"{name}={str(p)!r} is not accepted: the file exists (pass --overwrite to replace it)")
    if p.exists() and p.is_dir():
        raise ValueError(f"{name}={str(p)!r} is not accepted: it is a directory, not a file")
    parent = p.parent if str(p.parent) else Path(".")
    if not parent.is_dir():
        raise ValueError(f"{name}={str(p)!r} is not accepted: the directory {str(parent)!r} does not exist")
    if not os.access(parent, os.W_OK):
        raise ValueError(f"{name}={str(p)!r} is not accepted: the directory {str(parent)!r} is not writable")
    return p


def _clean_attrs(attrs: dict) -> dict:
    out = {}
    for k, v in attrs.items():
        if isinstance(v, bool | np.bool_):
            out[k] = int(v)
        elif v is None:
            out[k] = "none"
        elif isinstance(v, dict | list | tuple):
            out[k] = repr(v)
        else:
            out[k] = v
    return out


def to_netcdf(ds: xr.Dataset, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``ds`` to ``path`` atomically: a temporary file in the same directory, then rename.

    A crash or a full disk never leaves a half-written result under ``path``. Without
    ``overwrite`` the file is put in place with a hard link, which fails if ``path`` exists:
    of two processes finishing at once, one writes and the other is refused (``ValueError``),
    never a silent overwrite. A write that fails (full disk, I/O error) raises
    :class:`WriteError` (an ``OSError``) with one line; nothing is left behind.
    """
    p = check_output_path(path, overwrite=overwrite)
    ds = ds.copy()
    ds.attrs = _clean_attrs(ds.attrs)
    for v in ds.variables.values():
        v.attrs = _clean_attrs(v.attrs)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent if str(p.parent) else ".")
    os.close(fd)
    try:
        try:
            ds.to_netcdf(tmp, engine="h5netcdf")
            # mkstemp creates the file 0600; give it the permissions a plain open() would have.
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
            _put_in_place(tmp, p, overwrite)
        except OSError as exc:
            if isinstance(exc, FileExistsError) and not overwrite:
                raise ValueError(f"out={str(p)!r} is not accepted: the file exists (another process wrote it "
                                 "while this one ran; pass --overwrite to replace it)") from None
            raise WriteError(f"cannot write out={str(p)!r}: {reason(exc)}; nothing was written there",
                             getattr(exc, "errno", None)) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return p


def write_bytes_atomic(data: bytes, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``data`` to ``path`` as :func:`to_netcdf` writes a result: a temporary file in the
    same directory, flushed to disk, then put in place (refused if ``path`` appeared meanwhile
    without ``overwrite``); a failed write raises :class:`WriteError` and leaves nothing."""
    p = check_output_path(path, overwrite=overwrite)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent if str(p.parent) else ".")
    try:
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
                f.flush()
                os.fsync(f.fileno())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
            _put_in_place(tmp, p, overwrite)
        except OSError as exc:
            if isinstance(exc, FileExistsError) and not overwrite:
                raise ValueError(f"out={str(p)!r} is not accepted: the file exists (another process wrote it "
                                 "while this one ran; pass --overwrite to replace it)") from None
            raise WriteError(f"cannot write out={str(p)!r}: {reason(exc)}; nothing was written there",
                             getattr(exc, "errno", None)) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return p


def _put_in_place(tmp: str, p: Path, overwrite: bool) -> None:
    """Rename ``tmp`` to ``p``; without ``overwrite``, atomically refuse an existing ``p``."""
    if overwrite:
        os.replace(tmp, p)
        return
    try:
        os.link(tmp, p)  # FileExistsError if another process got there first
    except FileExistsError:
        raise
    except OSError:  # a file system without hard links: check, then rename (a small race)
        if p.exists():
            raise FileExistsError(p) from None
        os.replace(tmp, p)


def open_results(path: str | os.PathLike) -> xr.Dataset:
    """Open a results file written by :func:`to_netcdf` (loaded into memory, file closed)."""
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"path={str(p)!r} is not accepted: it is a directory, not a results file")
    if not p.is_file():
        raise ValueError(f"path={str(p)!r} is not accepted: no such file")
    try:
        with xr.open_dataset(p, engine="h5netcdf") as ds:
            return ds.load()
    except (OSError, ValueError) as exc:
        raise ValueError(f"path={str(p)!r} is not accepted: not a readable NetCDF results file ({exc})") from None
