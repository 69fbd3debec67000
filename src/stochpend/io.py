"""Results files: NetCDF (h5netcdf engine), written atomically."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
import xarray as xr

__all__ = ["check_output_path", "open_results", "to_netcdf"]


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

    A crash or a full disk never leaves a half-written result under ``path``.
    """
    p = check_output_path(path, overwrite=overwrite)
    ds = ds.copy()
    ds.attrs = _clean_attrs(ds.attrs)
    for v in ds.variables.values():
        v.attrs = _clean_attrs(v.attrs)
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent if str(p.parent) else ".")
    os.close(fd)
    try:
        ds.to_netcdf(tmp, engine="h5netcdf")
        # mkstemp creates the file 0600; give it the permissions a plain open() would have.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, p)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return p


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
