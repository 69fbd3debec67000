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
    """``stochpend.simulate`` is the function, whatever the module ``stochpend.runs.simulate``
    that defines it does when imported."""
    import stochpend.runs.simulate  # noqa: F401
    from stochpend.runs.simulate import run  # noqa: F401

    assert callable(stochpend.simulate) and stochpend.simulate.__module__ == "stochpend.runs.simulate"


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


def test_the_api_raises_the_cli_warnings_as_stochpend_warnings():
    """A resolved bias (the coarse harmonic case of test_bias) and lost paths are warned about
    through ``warnings`` in the Python API, as StochpendWarning; a quiet run warns nothing."""
    import warnings

    import pytest

    with pytest.warns(stochpend.StochpendWarning, match="discretisation bias"):
        stochpend.simulate(potential="harmonic", noise="white", D=0.5, theta0=1.0, h_max=0.2,
                           step_c=0.0, paths=80_000, t_max=4.0, times=(2.0, 4.0), seed=2,
                           bias_paths=10_000)
    with warnings.catch_warnings():
        warnings.simplefilter("error", stochpend.StochpendWarning)
        stochpend.simulate(noise="ou", paths=500, t_max=5.0, n_times=4, seed=1)


def test_progress_true_draws_a_bar_and_bad_objects_are_refused(capsys):
    import pytest

    ds = stochpend.simulate(noise="ou", paths=200, t_max=2.0, n_times=3, seed=1, progress=True)
    assert ds.sizes["time"] == 3
    with pytest.raises(ValueError, match="progress=.* is not accepted"):
        stochpend.simulate(noise="ou", paths=200, t_max=2.0, n_times=3, seed=1, progress="yes")


def test_variables_have_short_labels_and_units():
    ds = stochpend.simulate(noise="ou", paths=200, t_max=2.0, n_times=3, seed=1)
    assert ds.mean_E.attrs["long_name"] == "⟨E⟩" and ds.mean_E.attrs["units"] == "paper units"
    assert ds.skewness.attrs["units"] == "1" and "raw-moment" in ds.skewness.attrs["description"]
    assert ds.time.attrs["long_name"] == "time t"
