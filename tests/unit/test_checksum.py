"""Results files carry a checksum over what they say (C01, issue 20): a flipped byte in a data
variable, a coordinate or an attribute is one line and exit 1 in `show` and `DamagedResults` in
`open_results`; a file written before checksums opens with a note; every kind of file the tool
writes verifies."""

from __future__ import annotations

import warnings
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import stochpend
from stochpend import cli, io
from stochpend.text._warnings import StochpendWarning


def _cli(*args: object) -> SimpleNamespace:
    """The command in this process (typer's CliRunner, stdout and stderr apart): what a real
    process's exit code and streams would be. A process of its own cost ~3 s each (imports,
    kernels loaded from the cache); the program as a real process is tested in tests/system
    (test_hostile's `show` of a crafted file among them)."""
    result = CliRunner().invoke(cli.app, [str(a) for a in args], env={"COLUMNS": "100"})
    return SimpleNamespace(returncode=result.exit_code, stdout=result.stdout, stderr=result.stderr)


@pytest.fixture(scope="module")
def run_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=256, t_max=10.0, n_times=6, seed=3)
    path = tmp_path_factory.mktemp("checksum") / "run.nc"
    io.to_netcdf(ds, path)
    return path


def _flipped(src: Path, dst: Path, offset: int, mask: int = 0x01) -> Path:
    data = bytearray(src.read_bytes())
    data[offset] ^= mask
    dst.write_bytes(bytes(data))
    return dst


def _data_offset(path: Path, name: str) -> tuple[int, int]:
    with h5py.File(path, "r") as f:
        return f[name].id.get_offset(), f[name].id.get_storage_size()


def test_a_written_file_verifies_and_its_checksum_covers_what_a_reader_sees(run_file: Path) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", StochpendWarning)
        ds = io.open_results(run_file)
    stored = ds.attrs[io.CHECKSUM_ATTR]
    assert stored.startswith("sha256:") and len(stored) == 7 + 64
    assert io.checksum(ds) == stored
    # Every part counts: a value, a coordinate, a variable's attribute, a file attribute, a name.
    changed = [ds.copy(deep=True) for _ in range(5)]
    changed[0]["mean_E"].values[2] = np.nextafter(changed[0]["mean_E"].values[2], np.inf)
    changed[1] = changed[1].assign_coords(time=ds["time"].values * (1 + 2**-52))
    changed[2]["mean_E"].attrs["units"] = "J"
    changed[3].attrs["D"] = 1.0000000001
    changed[4] = changed[4].rename({"mean_E2": "mean_E2x"})
    assert len({io.checksum(c) for c in changed} | {stored}) == 6
    # NaN payloads are not part of what a file says (a decoder may make them canonical).
    a, b = ds.copy(deep=True), ds.copy(deep=True)
    a["mean_E"].values[0] = np.nan
    b["mean_E"].values[0] = -np.float64("nan")
    assert io.checksum(a) == io.checksum(b)


@pytest.mark.parametrize("name", ["mean_E", "time", "mean_E_stderr"])
def test_a_flipped_byte_in_the_data_is_one_line_and_exit_1(run_file: Path, tmp_path: Path, name: str) -> None:
    offset, size = _data_offset(run_file, name)
    for k in (0, size // 2, size - 1):
        with pytest.raises(io.DamagedResults, match="is damaged: its contents do not match its checksum"):
            io.open_results(_flipped(run_file, tmp_path / "bad.nc", offset + k))
    r = _cli("show", _flipped(run_file, tmp_path / "bad.nc", offset + size // 2, 0x10))
    assert r.returncode == 1 and r.stdout == "", (r.returncode, r.stdout)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "is damaged" in lines[0], r.stderr


def test_an_edited_attribute_is_caught(run_file: Path, tmp_path: Path) -> None:
    path = tmp_path / "edited.nc"
    path.write_bytes(run_file.read_bytes())
    with h5py.File(path, "r+") as f:
        f.attrs["D"] = 2.0  # the numbers would then be read against the wrong noise strength
    with pytest.raises(io.DamagedResults):
        io.open_results(path)
    path.write_bytes(run_file.read_bytes())
    with h5py.File(path, "r+") as f:
        f.attrs[io.CHECKSUM_ATTR] = "sha256:" + "0" * 64
    with pytest.raises(io.DamagedResults):
        io.open_results(path)


def test_any_flipped_byte_is_refused_or_changes_nothing(run_file: Path, tmp_path: Path) -> None:
    """Bytes anywhere in the file (a fixed random sample): the file is refused (damaged, or not
    readable at all) or reads back exactly as written (a byte HDF5 does not use); never a
    changed number accepted."""
    original = io.open_results(run_file)
    source = run_file.read_bytes()
    offsets = np.random.default_rng(20).integers(0, len(source), 40)
    outcomes = {"damaged": 0, "unreadable": 0, "same": 0}
    for offset in offsets:
        path = _flipped(run_file, tmp_path / "any.nc", int(offset), 0x04)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", StochpendWarning)
                ds = io.open_results(path)
        except io.DamagedResults:
            outcomes["damaged"] += 1
            continue
        except ValueError:
            outcomes["unreadable"] += 1
            continue
        assert ds.identical(original), int(offset)
        outcomes["same"] += 1
    assert outcomes["damaged"] > 0 and outcomes["unreadable"] > 0, outcomes


def test_a_file_without_a_checksum_opens_with_a_note(run_file: Path, tmp_path: Path) -> None:
    path = tmp_path / "legacy.nc"
    path.write_bytes(run_file.read_bytes())
    with h5py.File(path, "r+") as f:
        del f.attrs[io.CHECKSUM_ATTR]
    with pytest.warns(StochpendWarning, match="carries no checksum"):
        ds = io.open_results(path)
    assert float(ds["mean_E"][-1]) == float(io.open_results(run_file)["mean_E"][-1])
    r = _cli("show", path)
    assert r.returncode == 0, r.stderr
    assert r.stderr.count("carries no checksum") == 1 and "mean" in r.stdout.lower() or "<E>" in r.stdout


def test_show_formats_csv_and_json_go_to_stdout(run_file: Path) -> None:
    ds = io.open_results(run_file)
    r = _cli("show", run_file, "--format", "csv")
    assert r.returncode == 0, r.stderr
    header, *rows = r.stdout.strip().splitlines()
    cols = header.split(",")
    assert cols[0] == "time" and "mean_E" in cols and "mean_E_stderr" in cols
    assert len(rows) == ds.sizes["time"]  # every output time, not the table's 12
    k = cols.index("mean_E")
    assert [float(row.split(",")[k]) for row in rows] == ds["mean_E"].values.tolist()  # full precision
    assert "E_hist" in r.stderr  # what the CSV leaves out is said, on stderr
    import json

    r = _cli("show", run_file, "--format", "json")
    assert r.returncode == 0, r.stderr
    doc = json.loads(r.stdout)
    assert doc["data_vars"]["mean_E"]["data"] == ds["mean_E"].values.tolist()
    assert doc["attrs"][io.CHECKSUM_ATTR] == ds.attrs[io.CHECKSUM_ATTR]
    r = _cli("show", run_file, "--format", "xml")
    assert r.returncode == 2 and r.stderr.strip() == "error: --format='xml' is not accepted: one of table, csv, json"


def test_every_kind_of_result_verifies(tmp_path: Path) -> None:
    """simulate, a checkpointed run, sweep, reduced and bfpe write files that open verified
    (the checksum is taken over the file as a reader decodes it: strings, flags, encodings)."""
    sweep_toml = tmp_path / "s.toml"
    sweep_toml.write_text('[base]\nnoise = "white"\nomega = 1.0\npaths = 64\nt_max = 2.0\nn_times = 3\n'
                          '[grid]\nD = [0.5, 1.0]\n', encoding="utf-8")
    commands = {
        "sim": ("simulate", "--noise", "white", "--paths", "64", "--t-max", "2", "--n-times", "3", "--quiet"),
        "ckpt": ("simulate", "--noise", "white", "--paths", "64", "--t-max", "2", "--n-times", "3", "--quiet",
                 "--checkpoint", tmp_path / "c.ckpt"),
        "sweep": ("sweep", sweep_toml, "--quiet"),
        "reduced": ("reduced", "--order", "first", "--paths", "64", "--t-max", "2", "--quiet"),
        "bfpe": ("bfpe", "--t-max", "2", "--quiet"),
    }
    for name, args in commands.items():
        out = tmp_path / f"{name}.nc"
        r = _cli(*args, "--out", out)
        assert r.returncode == 0, (name, r.stderr)
        with warnings.catch_warnings():
            warnings.simplefilter("error", StochpendWarning)
            ds = io.open_results(out)
        assert io.checksum(ds) == ds.attrs[io.CHECKSUM_ATTR], name
        assert isinstance(ds, xr.Dataset)
        # the faster read (io._load_netcdf) gives exactly what xarray's own gives
        with xr.open_dataset(out, engine="h5netcdf") as plain:
            assert ds.identical(plain.load()), name


def test_without_the_h5netcdf_pieces_the_read_is_xarrays_own(tmp_path: Path, monkeypatch) -> None:
    """io._load_netcdf subclasses h5netcdf's File; where h5netcdf has not the pieces it knows,
    xarray's own read is used, with the same result."""
    ds = xr.Dataset({"mean_E": ("time", np.arange(3.0))}, coords={"time": [1.0, 2.0, 3.0]}, attrs={"noise": "ou"})
    ds.to_netcdf(tmp_path / "x.nc", engine="h5netcdf")
    fast = io._load_netcdf(tmp_path / "x.nc")
    assert io._ReadOnceFile._cls not in (None, False)
    monkeypatch.setattr(io._ReadOnceFile, "_cls", False)
    assert io._ReadOnceFile.make(None) is None
    plain = io._load_netcdf(tmp_path / "x.nc")
    assert fast.identical(plain) and fast.identical(ds)
