"""Results files: NetCDF (h5netcdf engine), written atomically, with a checksum over what they say.

Every file :func:`to_netcdf` writes carries ``checksum_sha256``: a SHA-256 over every data
variable, coordinate and attribute as a reader decodes them (names, dimensions, dtypes, shapes,
values; NaN payloads made canonical, since a decoder need not keep them). :func:`open_results`
recomputes it: a flipped byte anywhere in those is :class:`DamagedResults` (an ``OSError``, exit 1
on the command line); a file written before checksums existed opens with a
:class:`~stochpend.StochpendWarning` saying its numbers are not verified.
"""

from __future__ import annotations

import contextlib
import hashlib
import io as _io
import os
import shlex
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, overload

import numpy as np

from stochpend.files._files import WriteError, check_output, reason, write_atomic

if TYPE_CHECKING:  # pragma: no cover - xarray is imported where used: `show` reads a run without it
    import xarray as xr

    from stochpend.files._plain import Plain

__all__ = ["CHECKSUM_ATTR", "DamagedResults", "WriteError", "check_output_path", "checksum", "open_results",
           "reason", "to_netcdf"]

#: The attribute holding a results file's checksum ("sha256:" and 64 hex digits).
CHECKSUM_ATTR = "checksum_sha256"
#: Salt of the checksum's layout: a change of layout changes every checksum.
_CHECKSUM_SCHEME = b"stochpend results checksum 1\0"


class DamagedResults(OSError):
    """A results file whose contents do not match its checksum: changed or damaged after it
    was written. One line naming the file (exit 1 on the command line)."""

    def __str__(self) -> str:
        return str(self.args[0])


def _canonical(values: np.ndarray) -> tuple[bytes, bytes]:
    """(kind tag, bytes) of an array as a reader sees it, independent of byte order, of how
    strings are held (fixed width or objects) and of NaN payloads."""
    a = np.asarray(values)
    if a.dtype.kind in "USO":
        items = [x.decode("utf-8", "surrogateescape") if isinstance(x, bytes) else str(x) for x in a.ravel().tolist()]
        return b"U", b"".join(len(t).to_bytes(8, "little") + t for t in (x.encode("utf-8", "surrogatepass") for x in items))
    if a.dtype.kind == "b":
        return b"b", np.ascontiguousarray(a, dtype=np.uint8).tobytes()
    if a.dtype.kind in "fc":
        a = np.where(np.isnan(a), np.array(np.nan, dtype=a.dtype), a) if np.isnan(a).any() else a
    tag = f"{a.dtype.kind}{a.dtype.itemsize}".encode()
    return tag, np.ascontiguousarray(a, dtype=a.dtype.newbyteorder("<")).tobytes()


def _attr_value(value: object) -> tuple[bytes, bytes]:
    """An attribute's value as a reader sees it: text, or numbers widened to 64 bits and
    flattened (a one-element array and a scalar read back alike)."""
    if isinstance(value, str | bytes):
        return _canonical(np.array([value], dtype=object))
    a = np.atleast_1d(np.asarray(value))
    if a.dtype.kind in "USO":
        return _canonical(a)
    if a.dtype.kind in "biu":
        return b"i", np.ascontiguousarray(a.ravel(), dtype="<i8").tobytes() if a.dtype.kind != "u" else \
            np.ascontiguousarray(a.ravel(), dtype="<u8").tobytes()
    return _canonical(a.ravel().astype(np.complex128 if a.dtype.kind == "c" else np.float64))


def checksum(ds: xr.Dataset | Plain) -> str:
    """``"sha256:<hex>"`` over ``ds``'s variables (data and coordinates: name, dimensions,
    dtype, shape, values, attributes) and its attributes, :data:`CHECKSUM_ATTR` excepted."""
    h = hashlib.sha256(_CHECKSUM_SCHEME)

    def put(tag: bytes, data: bytes) -> None:
        h.update(tag + len(data).to_bytes(8, "little"))
        h.update(data)

    def put_attrs(attrs: dict) -> None:
        for key in sorted(str(k) for k in attrs if k != CHECKSUM_ATTR):
            put(b"k", key.encode("utf-8", "surrogatepass"))
            put(*_attr_value(attrs[key]))

    put_attrs(ds.attrs)
    for name in sorted(str(n) for n in ds.variables):
        var = ds.variables[name]
        put(b"n", name.encode("utf-8", "surrogatepass"))
        put(b"d", "\0".join(str(d) for d in var.dims).encode("utf-8", "surrogatepass"))
        put(b"s", np.asarray(var.shape, dtype="<i8").tobytes())
        put(*_canonical(var.values))
        put_attrs(var.attrs)
    return "sha256:" + h.hexdigest()


# The preflight check and the atomic write every output goes through live in stochpend.files._files;
# they are re-exported here, where callers have always found them.
check_output_path = check_output


def _clean_attrs(attrs: dict) -> dict:
    out: dict[str, Any] = {}
    for k, v in attrs.items():
        if isinstance(v, bool | np.bool_):
            out[k] = int(v)
        elif v is None:
            out[k] = "none"
        elif isinstance(v, dict | list | tuple):
            out[k] = repr(v)
        elif isinstance(v, str):
            # Text that is not valid Unicode (a lone surrogate from an undecodable command-line
            # byte, kept in an old checkpoint) is written escaped, never refused (E09c).
            out[k] = v.encode("utf-8", "backslashreplace").decode("utf-8")
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
    # Written once, with a stand-in checksum (the checksum leaves its own attribute out).
    ds.attrs[CHECKSUM_ATTR] = _STAND_IN
    first = ds.to_netcdf(engine="h5netcdf")
    import xarray as xr  # imported already by whoever built ds

    # The checksum is taken over the file as a reader decodes it (encodings, fill values and
    # string types as xarray reads them back), so that what open_results recomputes is the same.
    with xr.open_dataset(_io.BytesIO(first), engine="h5netcdf") as back:
        image = _put_checksum(first, checksum(back.load()))
    return write_atomic(p, image, overwrite=overwrite)


#: The checksum attribute's value in the first image, replaced in place by :func:`_put_checksum`.
_STAND_IN = "sha256:" + "0" * 64


def _put_checksum(image: bytes | memoryview, value: str) -> bytes:
    """``image`` (a NetCDF file in memory, :data:`_STAND_IN` in its checksum attribute) with
    ``value`` written into that attribute, nothing else changed.

    Writing the attribute's value in place keeps the file's size and layout; xarray writing
    the whole file again (as this module did before) costs as much as the first write, a third
    of a result's save: 0.47 s against 0.33 s for a small ``simulate`` result, measured."""
    import h5py

    buffer = _io.BytesIO(image)
    with h5py.File(buffer, "r+") as f:
        attr = f.attrs.get_id(CHECKSUM_ATTR)
        attr.write(np.array(value, dtype=attr.dtype))
    return buffer.getvalue()


def write_bytes_atomic(data: bytes, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write ``data`` (a figure, a report) to ``path`` as :func:`to_netcdf` writes a result:
    checked first, then built whole and put in place atomically (:func:`stochpend.files._files.
    write_atomic`)."""
    p = check_output_path(path, overwrite=overwrite)
    return write_atomic(p, data, overwrite=overwrite)


#: A results file nests no deeper and holds no more objects than this (xarray writes a flat file).
_MAX_DEPTH, _MAX_OBJECTS = 8, 100_000
#: Declared data beyond the file's own size by more than this is refused before any allocation.
_SLACK_BYTES = 1 << 20
#: A file system that compresses (ZFS, btrfs) holds a file in fewer blocks than its size: data
#: up to this many times the allocated bytes is still accepted.
_COMPRESSION = 16
#: A checkpoint's first bytes (stochpend.runs.checkpoint.MAGIC, not imported: it pulls Numba in).
_CHECKPOINT_MAGIC = b"STOCHPEND-CKPT"
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _check_hdf5(p: Path) -> None:
    """Refuse, before xarray reads anything, what a crafted HDF5 file can use against a reader:
    data stored in other files (external storage: a FIFO hangs the reader, a private file's
    bytes are shown as numbers), links to elsewhere (external, soft: loops), virtual datasets,
    and datasets declaring more data than the file holds (1e11 elements in 71 KB ask for 745 GiB).
    A file whose datasets' filters (compression) hide their size is refused the same way: the
    tool writes none."""
    import h5py

    st = p.stat()
    # A sparse file's apparent size (st_size) is not what it holds: 2 GiB apparent on 94 KB of
    # disk passed this check, and the reader then allocated the 2 GiB. What is allocated
    # (st_blocks, 512-byte units) bounds it too, with room for a compressing file system;
    # st_blocks = 0 (some network file systems do not count) falls back to st_size.
    allocated = getattr(st, "st_blocks", 0) * 512
    size = st.st_size if allocated <= 0 else min(st.st_size, _COMPRESSION * allocated)
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


#: What a file that is not HDF5 is, by its first bytes (the files a user may pass by mistake).
_KINDS = ((b"\x89PNG", "a PNG image"), (b"%PDF", "a PDF document"), (b"CDF\x01", "a NetCDF-3 file"),
          (b"CDF\x02", "a NetCDF-3 file"), (b"PK\x03\x04", "a zip archive"))


def _not_hdf5(p: Path, head: bytes) -> str | None:
    """What ``p`` is, in words, when it is not an HDF5 (NetCDF-4) file; None when it is one.
    HDF5's signature sits at byte 0 or after a user block of 512, 1024, 2048, ... bytes."""
    if head.startswith(_HDF5_SIGNATURE):
        return None
    size = p.stat().st_size
    with open(p, "rb") as fh:
        offset = 512
        while offset + len(_HDF5_SIGNATURE) <= size:
            fh.seek(offset)
            if fh.read(len(_HDF5_SIGNATURE)) == _HDF5_SIGNATURE:
                return None
            offset *= 2
    for magic, kind in _KINDS:
        if head.startswith(magic):
            return kind
    if not head:
        return "an empty file"
    text = head.lstrip()[:1]
    if text in (b"{", b"["):
        return "JSON or other text"
    if text == b"<":
        return "HTML, SVG or other XML text"
    return "text" if all(32 <= b < 127 or b in b"\t\r\n" for b in head) else "a file of another format"


def _load_netcdf(p: Path) -> xr.Dataset:
    """``xr.open_dataset(p, engine="h5netcdf").load()``, the same Dataset, in about 60 % of the
    time: h5netcdf looks each variable's HDF5 dataset up again in the file at every property
    read (some 40 lookups a variable, 2000 for a run's 55 variables: 0.07 of show's 0.17 s of
    reading, measured); here each variable keeps the one it found (:class:`_ReadOnceFile`).
    Any other h5netcdf than this subclass knows: xarray's own path."""
    import h5netcdf  # type: ignore[import-untyped]
    import xarray as xr

    file_cls = _ReadOnceFile.make(h5netcdf)
    if file_cls is None:
        with xr.open_dataset(p, engine="h5netcdf") as ds:
            return ds.load()
    with _open_h5netcdf(file_cls, p) as f, xr.open_dataset(xr.backends.H5NetCDFStore(f)) as ds:
        return ds.load()


def _open_h5netcdf(file_cls: Any, p: Path) -> Any:
    """``p`` opened as xarray's h5netcdf backend opens it (text as ``str``, dimensions without a
    variable named as they are met)."""
    return file_cls(p, "r", decode_vlen_strings=True, phony_dims="access")


def _read_plain(p: Path) -> Plain | None:
    """:func:`stochpend.files._plain.read` of ``p``, from the file :func:`_load_netcdf` would read;
    None where xarray must read it."""
    import h5netcdf

    from stochpend.files import _plain

    file_cls = _ReadOnceFile.make(h5netcdf)
    if file_cls is None:
        return None
    with _open_h5netcdf(file_cls, p) as f:
        return _plain.read(f)


class _ReadOnceFile:
    """An ``h5netcdf.File`` whose variables look their HDF5 dataset up once (a read-only file
    opened for one load, so the object cannot change under them)."""

    _cls: Any = None

    @classmethod
    def make(cls, h5netcdf: Any) -> Any:
        if cls._cls is None:
            variable: Any = getattr(getattr(h5netcdf, "core", None), "Variable", None)
            if variable is None or not isinstance(getattr(variable, "_h5ds", None), property) \
                    or getattr(h5netcdf.File, "_variable_cls", None) is not variable:
                cls._cls = False
                return None

            class Variable(variable):
                @property
                def _h5ds(self) -> Any:
                    found = self.__dict__.get("_stochpend_h5ds")
                    if found is None:
                        found = self.__dict__["_stochpend_h5ds"] = variable._h5ds.fget(self)
                    return found

            class File(h5netcdf.File):
                _variable_cls = Variable

            cls._cls = File
        return cls._cls or None


@overload
def open_results(path: str | os.PathLike, *, verify: bool = True, plain: Literal[False] = False) -> xr.Dataset: ...


@overload
def open_results(path: str | os.PathLike, *, verify: bool = True, plain: bool) -> xr.Dataset | Plain: ...


def open_results(path: str | os.PathLike, *, verify: bool = True, plain: bool = False) -> xr.Dataset | Plain:
    """Open a results file written by :func:`to_netcdf` (loaded into memory, file closed).

    Only a regular file is read (a FIFO or device would hang or never end), and only after
    :func:`_check_hdf5` found nothing in it that reads other files or asks for more memory than
    the file holds. Every refusal is one ``ValueError`` line naming the file. With ``verify``
    (the default) the file's checksum is recomputed: a mismatch raises :class:`DamagedResults`
    (an ``OSError``), a file without one (written before checksums existed) opens with a
    :class:`~stochpend.StochpendWarning`. Verifying costs one SHA-256 pass over the decoded
    data (docs/cli.md gives the figure for a large sweep file). With ``plain``, a file read
    without xarray where it can be (a :class:`stochpend.files._plain.Plain`, for ``show``), else the
    Dataset.
    """
    p = Path(path)
    if p.is_dir():
        raise ValueError(f"path={str(p)!r} is not accepted: it is a directory, not a results file")
    if not p.is_file():
        raise ValueError(f"path={str(p)!r} is not accepted: no such file")
    with contextlib.suppress(OSError), open(p, "rb") as fh:
        head = fh.read(max(len(_CHECKPOINT_MAGIC), 8))
        if head.startswith(_CHECKPOINT_MAGIC):
            raise ValueError(f"path={str(p)!r} is not accepted: it is a checkpoint, not a result; "
                             f"`stochpend resume {shlex.quote(str(p))}` continues its run and writes the result")
        kind = _not_hdf5(p, head)
        if kind is not None:  # said in words, not as HDF5's "file signature not found"
            raise ValueError(f"path={str(p)!r} is not accepted: it is {kind}, not a results file; stochpend "
                             "writes its results as NetCDF-4 (simulate, sweep, bfpe or reduced --out FILE.nc)")
    try:
        _check_hdf5(p)
        ds: xr.Dataset | Plain | None = None
        if plain:
            ds = _read_plain(p)
        if ds is None:
            ds = _load_netcdf(p)
    except (ValueError, OSError, KeyError, TypeError, RuntimeError, RecursionError) as exc:
        if isinstance(exc, ValueError) and str(exc).startswith(f"path={str(p)!r}"):
            raise
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"path={str(p)!r} is not accepted: not a readable NetCDF results file ({why})") from None
    if verify:
        _verify(p, ds)
    return ds


def _verify(p: Path, ds: xr.Dataset | Plain) -> None:
    stored = ds.attrs.get(CHECKSUM_ATTR)
    if stored is None:
        from stochpend.text._warnings import StochpendWarning

        warnings.warn(f"{str(p)!r} carries no checksum (written before results had one): its numbers "
                      "are not verified", StochpendWarning, stacklevel=3)
        return
    try:
        actual = checksum(ds)
    except (ValueError, TypeError, OverflowError, UnicodeError) as exc:
        raise DamagedResults(f"{str(p)!r} is damaged: its contents cannot be checksummed "
                             f"({type(exc).__name__}); its numbers cannot be trusted") from None
    if not isinstance(stored, str) or stored != actual:
        raise DamagedResults(f"{str(p)!r} is damaged: its contents do not match its checksum (changed "
                             "or corrupted after stochpend wrote it); its numbers cannot be trusted")
