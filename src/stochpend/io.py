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


def write_bytes_atomic(data: bytes, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``data`` (a figure, a report) to ``path`` as :func:`to_netcdf` writes a result:
    checked first, then built whole and put in place atomically (:func:`stochpend._files.
    write_atomic`)."""
    p = check_output_path(path, overwrite=overwrite)
    return write_atomic(p, data, overwrite=overwrite)


#: A results file nests no deeper and holds no more objects than this (xarray writes a flat file).
_MAX_DEPTH, _MAX_OBJECTS = 8, 100_000
#: Declared data beyond the file's own size by more than this is refused before any allocation.
_SLACK_BYTES = 1 << 20


def _check_hdf5(p: Path) -> None:
    """Refuse, before xarray reads anything, what a crafted HDF5 file can use against a reader:
    data stored in other files (external storage: a FIFO hangs the reader, a private file's
    bytes are shown as numbers), links to elsewhere (external, soft: loops), virtual datasets,
    and datasets declaring more data than the file holds (1e11 elements in 71 KB ask for 745 GiB).
    A file whose datasets' filters (compression) hide their size is refused the same way: the
    tool writes none."""
    import h5py

    size = p.stat().st_size
    declared = 0
    objects = 0

    def refuse(why: str) -> ValueError:
        return ValueError(f"path={str(p)!r} is not accepted: {why}")

    def walk(group: h5py.Group, depth: int) -> None:
        nonlocal declared, objects
        if depth > _MAX_DEPTH:
            raise refuse(f"groups nested deeper than {_MAX_DEPTH}")
        for name in group:
            objects += 1
            if objects > _MAX_OBJECTS:
                raise refuse(f"more than {_MAX_OBJECTS} objects")
            where = f"{group.name.rstrip('/')}/{name}"
            if not isinstance(group.get(name, getlink=True), h5py.HardLink):
                raise refuse(f"{where!r} is a link to another place or file")
            obj = group[name]
            if isinstance(obj, h5py.Group):
                walk(obj, depth + 1)
            elif isinstance(obj, h5py.Dataset):
                if obj.external:
                    raise refuse(f"{where!r} keeps its data in another file")
                if obj.is_virtual:
                    raise refuse(f"{where!r} is a virtual dataset (data in other files)")
                declared += int(obj.size) * obj.dtype.itemsize
        if declared > size + _SLACK_BYTES:
            raise refuse(f"it declares {declared:.3g} bytes of data in a file of {size} bytes")

    with h5py.File(p, "r") as f:
        walk(f, 0)


def open_results(path: str | os.PathLike) -> xr.Dataset:
    """Open a results file written by :func:`to_netcdf` (loaded into memory, file closed).

    Only a regular file is read (a FIFO or device would hang or never end), and only after
    :func:`_check_hdf5` found nothing in it that reads other files or asks for more memory than
    the file holds. Every refusal is one ``ValueError`` line naming the file.
    """
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"path={str(p)!r} is not accepted: it is a directory, not a results file")
    if not p.is_file():
        raise ValueError(f"path={str(p)!r} is not accepted: no such file")
    try:
        _check_hdf5(p)
        with xr.open_dataset(p, engine="h5netcdf") as ds:
            return ds.load()
    except (ValueError, OSError, KeyError, TypeError, RuntimeError, RecursionError) as exc:
        if isinstance(exc, ValueError) and str(exc).startswith(f"path={str(p)!r}"):
            raise
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"path={str(p)!r} is not accepted: not a readable NetCDF results file ({why})") from None
