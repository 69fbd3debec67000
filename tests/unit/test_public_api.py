"""The declared public API: reachable after ``import stochpend``, imported lazily."""

from __future__ import annotations

import subprocess
import sys

from typer.testing import CliRunner

import stochpend


def test_every_public_name_is_reachable_after_import():
    for name in stochpend.__all__:
        assert getattr(stochpend, name) is not None, name
    assert callable(stochpend.simulate)
    assert callable(stochpend.io.to_netcdf) and callable(stochpend.io.open_results)
    assert callable(stochpend.exponents.fit_exponent) and callable(stochpend.theory.solve_bfpe)
    assert set(stochpend.SUBMODULES) <= set(dir(stochpend))


def test_importing_the_simulate_module_keeps_the_function():
    """``stochpend.simulate`` is also a submodule; importing it must not replace the function."""
    import stochpend.simulate  # noqa: F401
    from stochpend.simulate import run  # noqa: F401

    assert callable(stochpend.simulate) and stochpend.simulate.__module__ == "stochpend.simulate"


def test_import_and_cli_import_load_no_heavy_module():
    """`import stochpend` and the CLI's module load neither Numba nor xarray nor Dask (they cost
    0.6-0.8 s each): `stochpend --help` and `--version` start at once."""
    code = ("import sys, stochpend, stochpend.cli; "
            "print(sorted(m for m in ('numba', 'xarray', 'dask', 'distributed', 'matplotlib', 'scipy') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_version_flag():
    from stochpend.cli import app

    result = CliRunner().invoke(app, ["--version"])
    assert result.exit_code == 0 and result.output.strip() == f"stochpend {stochpend.__version__}"
