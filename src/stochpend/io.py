"""Results files: NetCDF (h5netcdf engine), written atomically."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import xarray as xr

from stochpend._files import WriteError, check_output, reason, write_atomic

__all__ = ["WriteError", "check_output_path", "open_results", "reason", "to_netcdf"]


# The preflight check and the atomic write every output goes through live in stochpend._files;
# they are re-exported here, where callers have always found them.
check_output_path = check_output


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

    The NetCDF file is built in memory first and written with ``os.write``: libhdf5 writing
    its own file dies with SIGSEGV when the disk fills during the flush, where a plain write
    raises ``OSError``. A crash or a full disk never leaves a half-written result under
    ``path``. Without ``overwrite`` an existing ``path`` is refused (``ValueError``), also one
    that another process wrote while this one ran; only a regular file is ever replaced. A
    write that fails (full disk, I/O error) raises :class:`WriteError` (an ``OSError``) with one
    line; nothing is left behind.
    """
    # The directory is the write's to find missing (WriteError, exit 1): this may run after the work.
    p = check_output(path, overwrite=overwrite, directory=False)
    ds = ds.copy()
    ds.attrs = _clean_attrs(ds.attrs)
    for v in ds.variables.values():
        v.attrs = _clean_attrs(v.attrs)
    image = ds.to_netcdf(engine="h5netcdf")
    return write_atomic(p, image, overwrite=overwrite)


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
