"""A results file read without xarray, for ``show``: importing xarray and pandas costs about
0.45 s on a 2-core machine, more than the rest of ``show`` of a run (issue 36, item 1).

:func:`read` (through ``stochpend.io.open_results(path, plain=True)``) returns a :class:`Plain`
holding what xarray's reader (``stochpend.io._load_netcdf``) holds: the same names, dimensions,
dtypes, values and attributes, so the same checksum verifies it. It reads only files whose
decoding by xarray changes nothing but what this module repeats (UTF-8 attribute text, NaN fill
values of floats, byte order); a file with anything else xarray decodes (masked or scaled
integers, times, booleans, character arrays, non-index coordinates, text that is not UTF-8)
gives None, for xarray to read. :class:`Plain` answers the part of a Dataset's API that the
tables of a run use (``ds[name].values``, ``ds.attrs``, ``name in ds``, ``ds.time``,
``ds.sizes``, ``ds.isel(time=i)``); :meth:`Plain.to_xarray` gives the Dataset for everything
else.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np
    import xarray as xr

#: Attributes xarray decodes a variable by (``_FillValue`` is handled here: NaN of a float).
_DECODED = frozenset({"missing_value", "scale_factor", "add_offset", "_Unsigned", "dtype", "calendar",
                      "coordinates", "_Encoding"})
#: Units xarray decodes a variable as durations by (xarray.coding.times.TIME_UNITS); "since" in
#: the units makes it dates.
_TIME_UNITS = frozenset({"days", "hours", "minutes", "seconds", "milliseconds", "microseconds", "nanoseconds"})


class Variable:
    """One variable: ``dims``, ``values`` (a NumPy array) and ``attrs``, as a DataArray has them."""

    __slots__ = ("attrs", "dims", "values")

    def __init__(self, dims: tuple[str, ...], values: np.ndarray, attrs: dict[str, Any]) -> None:
        self.dims, self.values, self.attrs = dims, values, attrs

    @property
    def shape(self) -> tuple[int, ...]:
        return self.values.shape

    @property
    def ndim(self) -> int:
        return self.values.ndim

    def __float__(self) -> float:
        return float(self.values)

    def __int__(self) -> int:
        return int(self.values)


class Plain:
    """A result's variables (data and coordinates, in the file's order) and attributes."""

    def __init__(self, variables: dict[str, Variable], attrs: dict[str, Any]) -> None:
        self.variables, self.attrs = variables, attrs

    def __contains__(self, name: object) -> bool:
        return name in self.variables

    def __getitem__(self, name: str) -> Variable:
        return self.variables[name]

    def __getattr__(self, name: str) -> Variable:
        try:
            return self.__dict__["variables"][name]
        except KeyError:
            raise AttributeError(name) from None

    @property
    def sizes(self) -> dict[str, int]:
        return {d: n for v in self.variables.values() for d, n in zip(v.dims, v.shape, strict=True)}

    def isel(self, **indexers: int) -> Plain:
        """The result at one index of each dimension named (``isel(time=i)``), those dimensions dropped."""
        def pick(v: Variable) -> Variable:
            key = tuple(indexers.get(d, slice(None)) for d in v.dims)
            return Variable(tuple(d for d in v.dims if d not in indexers), v.values[key], v.attrs)

        return Plain({name: pick(v) for name, v in self.variables.items()}, self.attrs)

    def to_xarray(self) -> xr.Dataset:
        """The Dataset xarray's reader gives for the same file (a variable named as its one
        dimension is that dimension's coordinate, as there)."""
        import xarray as xr

        made = {name: xr.Variable(v.dims, v.values, v.attrs) for name, v in self.variables.items()}
        coords = {name: v for name, v in made.items() if v.dims == (name,)}
        return xr.Dataset({name: v for name, v in made.items() if name not in coords}, coords=coords,
                          attrs=self.attrs)


def _attrs(obj: Any) -> dict[str, Any] | None:
    """``obj``'s attributes as xarray's h5netcdf backend reads them (bytes decoded as UTF-8);
    None where that fails (xarray warns and keeps the bytes)."""
    out: dict[str, Any] = {}
    for key, value in obj.attrs.items():
        if isinstance(value, bytes) and key not in ("_FillValue", "missing_value"):
            try:
                value = value.decode("utf-8")
            except UnicodeDecodeError:
                return None
        out[key] = value
    return out


def _variable(name: str, var: Any, h5py: Any) -> Variable | None:
    """``var`` decoded as xarray decodes it, or None where xarray would do more."""
    import numpy as np  # here: the command line imports this module (its Plain) before it needs NumPy

    attrs = _attrs(var)
    if attrs is None or _DECODED & attrs.keys():
        return None
    units = attrs.get("units")
    if isinstance(units, str) and ("since" in units or units in _TIME_UNITS):
        return None
    dims = tuple(var.dimensions)
    if name in dims and dims != (name,):  # xarray refuses or reads this another way
        return None
    kind = var.dtype.kind
    if not (kind in "fiu" or (kind == "O" and h5py.check_dtype(vlen=var.dtype) is str)):
        return None
    if "_FillValue" in attrs:
        fill = np.asarray(attrs.pop("_FillValue"))
        # A NaN fill masks nothing that is not NaN already; another fill changes values (and an
        # integer's dtype) as xarray decodes them.
        if kind != "f" or fill.size != 1 or not np.isnan(fill).all():
            return None
    values = np.asarray(var[...])
    if not values.dtype.isnative:  # xarray decodes to the machine's byte order
        values = values.astype(values.dtype.newbyteorder("="))
    return Variable(dims, values, attrs)


def read(f: Any) -> Plain | None:
    """The result in ``f`` (an open ``h5netcdf.File``, as xarray's reader opens it), or None
    where xarray must read it: anything this module does not decode as xarray does, and any
    file it cannot read (xarray's reader then says why in its words)."""
    import h5py

    try:
        attrs = _attrs(f)
        if attrs is None or "coordinates" in attrs:
            return None
        variables = {}
        for name, var in f.variables.items():
            v = _variable(name, var, h5py)
            if v is None:
                return None
            variables[name] = v
    except Exception:  # noqa: BLE001 - a file this reader cannot read is xarray's to refuse, in its words
        return None
    return Plain(variables, attrs)
