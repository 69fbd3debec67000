"""The commands that compute nothing start without Numba or Dask (issue 36, item 1).

Numba takes about a second to import on a 2-core machine and Dask (pulled by xarray's checks
for Dask arrays) 0.6 s; ``--help``, ``--version``, ``show``, ``info``, ``list`` and ``theory``
need neither. Each runs in a fresh process under ``python -X importtime``, which lists every
module the process imported; the test reads that list (no times are compared: the benchmark,
benchmarks/startup.py, measures them).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import stochpend
from stochpend import io

SRC = str(Path(stochpend.__file__).resolve().parents[1])
HEAVY = ("numba", "llvmlite", "dask", "distributed")


def _env() -> dict[str, str]:
    """The environment of a fresh process that imports this checkout's stochpend."""
    return {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [SRC, os.environ.get("PYTHONPATH")]))}


def _python(code: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code, *args], env=_env(), capture_output=True, text=True, timeout=300)


def _imported(args: list[str], cwd: Path) -> tuple[set[str], subprocess.CompletedProcess]:
    env = _env()
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    done = subprocess.run([sys.executable, "-X", "importtime", "-c", "from stochpend.cli import main; main()", *args],
                          cwd=cwd, env=env, capture_output=True, text=True, timeout=300)
    modules = {m.group(1) for m in re.finditer(r"^import time:\s+\d+ \|\s+\d+ \|\s+(\S+)", done.stderr, re.M)}
    return {name.split(".")[0] for name in modules}, done


@pytest.fixture(scope="module")
def small_result(tmp_path_factory) -> Path:
    ds = stochpend.simulate(paths=200, t_max=5, n_times=3, seed=1)  # with its bias estimate
    path = tmp_path_factory.mktemp("light") / "r.nc"
    io.to_netcdf(ds, path)
    # the other kinds show reads: a sweep and a B.F.P.E. solution
    from stochpend.sweep import load_spec, sweep
    from stochpend.theory import solve_bfpe

    plan = load_spec({"base": {"noise": "ou", "paths": 100, "t_max": 2.0, "n_times": 2}, "grid": {"omega": [0.0, 1.0]}})
    io.to_netcdf(sweep(plan, bias_paths=0), path.parent / "sweep.nc")
    io.to_netcdf(solve_bfpe(D=1.0, tau=1.0, t_max=10.0, n_times=3, n_cells=50), path.parent / "bfpe.nc")
    return path


@pytest.mark.parametrize("args", [["--help"], ["--version"], ["list", "--help"], ["show", "r.nc"], ["show", "r.nc", "--format", "csv"],
                                  ["show", "sweep.nc"], ["show", "bfpe.nc"],
                                  ["info"], ["theory"], ["theory", "--noise", "white"], ["simulate", "--help"]])
def test_light_commands_import_neither_numba_nor_dask(args, small_result):
    top, done = _imported(args, small_result.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    assert not top & set(HEAVY), f"stochpend {' '.join(args)} imported {sorted(top & set(HEAVY))}"
    # Typer converts option values with Pydantic (0.15 s to import and build); an option with its
    # own parser, text and a default need none (stochpend.cli._types.fast_coercion)
    assert "pydantic" not in top, f"stochpend {' '.join(args)} imported pydantic"


@pytest.mark.parametrize("args", [["--help"], ["list"], ["info"], ["theory"], ["theory", "--noise", "white"]])
def test_commands_without_a_file_import_no_xarray(args, small_result):
    """Nothing to read, so no xarray and pandas (0.5 s): ``theory`` used to import them with
    the B.F.P.E. solver (stochpend.theory imports solve_bfpe on first use)."""
    top, done = _imported(args, small_result.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    assert not top & {"xarray", "pandas", "h5py"}, f"stochpend {' '.join(args)} imported {sorted(top & {'xarray', 'pandas', 'h5py'})}"


def test_a_value_pydantic_converts_still_converts(small_result):
    """A float given on the command line still goes through Typer's own conversion: a bad one
    is refused in one line, a good one is used."""
    top, done = _imported(["theory", "--D", "abc"], small_result.parent)
    assert done.returncode == 2 and done.stderr.strip().splitlines()[-1].startswith("error: --D 'abc' is not accepted")
    assert "pydantic" in top
    top, done = _imported(["theory", "--D", "2", "--time", "1e3"], small_result.parent)
    assert done.returncode == 0, done.stderr[-2000:]


def test_list_imports_no_numba(small_result):
    """``list`` reads the noises', oscillators' and models' modules, whose functions are
    ``register_jitable``: stochpend.numerics._jitable defers their registration until Numba is imported."""
    top, done = _imported(["list"], small_result.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "white" in done.stdout and "pendulum" in done.stdout
    assert not top & set(HEAVY), f"stochpend list imported {sorted(top & set(HEAVY))}"


def test_the_probe_sees_an_import(small_result):
    """The test can fail: a command that runs a simulation does import Numba."""
    top, done = _imported(["simulate", "--paths", "20", "--t-max", "1", "--n-times", "1", "-q", "--bias-paths", "0"],
                          small_result.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "numba" in top


def test_xarray_reads_and_builds_without_dask(small_result):
    """In a fresh process, opening a result and building a Dataset leave Dask unimported; once Dask
    is imported, xarray still recognises a Dask array (stochpend.files._xarray_nodask)."""
    code = ("import sys; import stochpend, xarray as xr, numpy as np; from stochpend import io;"
            "ds = io.open_results(sys.argv[1]); xr.Dataset({'a': ('t', np.arange(3.0))}, coords={'t': [1, 2, 3]});"
            "print('dask' in sys.modules);"
            "import dask.array as da; d = xr.Dataset({'a': ('t', da.arange(3, chunks=2))});"
            "print(type(d.a.data).__module__.split('.')[0], d.chunks['t'])")
    done = _python(code, str(small_result))
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split("\n")[:2] == ["False", "dask (2, 1)"]


def test_show_of_a_run_imports_no_xarray(small_result):
    """``show`` of a run's table reads the file without xarray and pandas (0.45 s to import:
    stochpend.files._plain); its CSV still goes through the Dataset."""
    top, done = _imported(["show", "r.nc"], small_result.parent)
    assert done.returncode == 0, done.stderr[-2000:]
    assert "<E>" in done.stdout
    assert not top & {"xarray", "pandas"}, f"stochpend show imported {sorted(top & {'xarray', 'pandas'})}"
    top, done = _imported(["show", "r.nc", "--format", "csv"], small_result.parent)
    assert done.returncode == 0 and "xarray" in top, done.stderr[-2000:]


@pytest.mark.parametrize("name", ["r.nc", "sweep.nc"])
def test_the_plain_reader_reads_what_xarray_reads(small_result, name):
    """The same variables, coordinates, values and attributes, so the file's checksum verifies it."""
    from stochpend.files import _plain

    path = small_result.parent / name
    plain, ds = io.open_results(path, plain=True), io._load_netcdf(path)
    assert isinstance(plain, _plain.Plain)
    assert plain.to_xarray().identical(ds)
    assert io.checksum(plain) == io.checksum(ds) == ds.attrs[io.CHECKSUM_ATTR]


@pytest.mark.parametrize("args", [[], ["--rows", "2"]])
def test_show_prints_the_same_without_xarray(small_result, monkeypatch, args):
    from typer.testing import CliRunner

    from stochpend import cli
    from stochpend.files import _plain

    def shown() -> tuple[int, str, str]:
        done = CliRunner().invoke(cli.app, ["show", str(small_result), *args])
        return done.exit_code, done.stdout, done.stderr

    plain = shown()
    monkeypatch.setattr(_plain, "read", lambda *args: None)  # every file to xarray, as before
    assert shown() == plain and plain[0] == 0


def test_a_file_xarray_decodes_further_is_left_to_xarray(small_result, tmp_path):
    """A boolean variable (stored as int8 with a dtype attribute, which xarray decodes): the
    plain reader declines, xarray reads the file."""
    from stochpend.files import _plain

    ds = io.open_results(small_result)
    ds["flag"] = ("time", ds["nonfinite_paths"].values > 0)
    io.to_netcdf(ds, tmp_path / "flag.nc")
    back = io.open_results(tmp_path / "flag.nc", plain=True)
    assert not isinstance(back, _plain.Plain) and back["flag"].dtype == bool
    assert isinstance(io.open_results(small_result, plain=True), _plain.Plain)


def test_help_imports_neither_markdown_nor_pygments(small_result):
    """Typer's help renderer imports rich.markdown and rich.traceback (markdown-it, Pygments)
    for Markdown help and Rich tracebacks, which the app does not use (stochpend.cli._NOT_FOR_HELP)."""
    for args in (["--help"], ["simulate", "--help"]):
        top, done = _imported(args, small_result.parent)
        assert done.returncode == 0 and "Usage" in done.stdout, done.stderr[-2000:]
        assert not top & {"markdown_it", "pygments"}, f"stochpend {' '.join(args)} imported {sorted(top)}"


def test_the_help_renderers_stand_ins_are_the_real_classes_when_used():
    """After the help, the modules left out import as themselves, and the renderer's names for
    them build the real objects."""
    code = ("from stochpend import cli; cli._import_help_renderer(); import typer.rich_utils as r;"
            "import rich.markdown, rich.traceback;"
            "assert r.Markdown is not rich.markdown.Markdown;"
            "assert isinstance(r.Markdown('*x*'), rich.markdown.Markdown);"
            "assert r.Traceback.from_exception == rich.traceback.Traceback.from_exception; print('ok')")
    done = _python(code)
    assert done.returncode == 0 and done.stdout == "ok\n", done.stderr[-2000:]
