"""The ``theory``, ``bfpe`` and ``reduced`` commands (stochpend.cli._theory)."""

from __future__ import annotations

import pytest
import xarray as xr
from typer.testing import CliRunner

from stochpend import cli
from stochpend.cli._theory import bfpe_command, reduced_command, theory_command

COMMANDS = {"theory": theory_command, "bfpe": bfpe_command, "reduced": reduced_command}


@pytest.fixture(scope="module")
def app():
    """The main app with the three commands registered (once, as cli.py will)."""
    names = {c.name for c in cli.app.registered_commands}
    for name, fn in COMMANDS.items():
        if name not in names:
            cli.app.command(name)(fn)
    return cli.app


def _run(app, args):
    return CliRunner().invoke(app, args)


def _one_error_line(result) -> str:
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("error:"), result.output
    assert "Traceback" not in result.output
    return lines[0]


def test_theory_ou_table(app) -> None:
    result = _run(app, ["theory", "--noise", "ou", "--D", "1", "--tau", "1", "--omega", "1", "--t", "1000"])
    assert result.exit_code == 0, result.output
    out = result.output
    for needle in ("Predictions at t = 1000", "crossover", "white-like", "first-order", "second-order",
                   "t >> t_c", "tau << t << t_c", "known-wrong", "10.6882", "250", "2.02793", "second-order averaging (Eq. (53))"):
        assert needle in out, (needle, out)


def test_theory_white_and_bfpe(app) -> None:
    result = _run(app, ["theory", "--noise", "white", "--D", "2", "--t", "3"])
    assert result.exit_code == 0, result.output
    assert "white noise" in result.output and "1.5" in result.output and "2.88675" in result.output
    result = _run(app, ["theory", "--D", "1", "--tau", "0.1", "--t", "1000", "--bfpe"])
    assert result.exit_code == 0, result.output
    assert "numerically" in result.output and "phi" in result.output


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--tau", "-1"], "--tau -1.0 is not accepted"),
        (["--D", "-2"], "--D -2.0 is not accepted"),
        (["--t", "-5"], "--time -5.0 is not accepted"),
        (["--noise", "pink"], "--noise 'pink' is not accepted"),
        (["--omega", "-1"], "--omega -1.0 is not accepted"),
    ],
)
def test_theory_bad_input_one_line(app, args, needle) -> None:
    line = _one_error_line(_run(app, ["theory", *args]))
    assert needle in line


def test_bfpe_writes_netcdf(app, tmp_path) -> None:
    out = tmp_path / "bfpe.nc"
    result = _run(app, ["bfpe", "--D", "1", "--tau", "0.1", "--t-max", "1e4", "--n-times", "5", "--n-cells", "200",
                        "--steps-per-decade", "20", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "Averaged B.F.P.E." in result.output and "wrote" in result.output
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.sizes["time"] == 5 and "mean_E" in ds and "phi" in ds
        assert float(ds.time[-1]) == pytest.approx(1e4)
        assert ds.attrs["command_line"].startswith("stochpend")
    # an existing file is refused before any work, and replaced with --overwrite
    line = _one_error_line(_run(app, ["bfpe", "--t-max", "10", "--out", str(out)]))
    assert "the file exists" in line
    result = _run(app, ["bfpe", "--t-max", "1e3", "--n-times", "3", "--n-cells", "100", "--steps-per-decade", "10",
                        "--out", str(out), "--overwrite", "--quiet"])
    assert result.exit_code == 0, result.output
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.sizes["time"] == 3


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--tau", "0"], "--tau 0.0 is not accepted"),
        (["--D", "0"], "--D 0.0 is not accepted"),
        (["--t-max", "-1"], "--t-max -1.0 is not accepted"),
        (["--n-times", "0"], "--n-times 0 is not accepted"),
    ],
)
def test_bfpe_bad_input_one_line(app, args, needle) -> None:
    line = _one_error_line(_run(app, ["bfpe", *args]))
    assert needle in line


def test_reduced_writes_netcdf(app, tmp_path) -> None:
    out = tmp_path / "r.nc"
    result = _run(app, ["reduced", "--order", "asymptotic", "--D", "1", "--tau", "1", "--paths", "2000",
                        "--t-max", "1000", "--n-times", "6", "--seed", "3", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "Reduced dynamics, asymptotic order" in result.output and "0.337989" in result.output
    with xr.open_dataset(out, engine="h5netcdf") as ds:
        assert ds.sizes["time"] == 6 and int(ds.attrs["paths"]) == 2000
        assert ds.attrs["order"] == "asymptotic" and int(ds.nonfinite_paths[-1]) == 0
        assert ds.attrs["command_line"].startswith("stochpend")
    for order in ("zeroth", "first", "second"):
        result = _run(app, ["reduced", "--order", order, "--paths", "200", "--t-max", "5", "--n-times", "3",
                            "--quiet"])
        assert result.exit_code == 0, (order, result.output)


@pytest.mark.parametrize(
    "args,needle",
    [
        (["--order", "third"], "--order 'third' is not accepted"),
        (["--D", "0"], "--D 0.0 is not accepted"),
        (["--E0", "-1"], "--E0 -1.0 is not accepted"),
        (["--paths", "0"], "--paths 0 is not accepted"),
        (["--times", "3,2"], "--times [3.0, 2.0] is not accepted"),
        (["--times", "a,b"], "--times 'a,b' is not accepted"),
        (["--h-max", "-0.1"], "--h-max -0.1 is not accepted"),
    ],
)
def test_reduced_bad_input_one_line(app, args, needle) -> None:
    line = _one_error_line(_run(app, ["reduced", "--t-max", "10", *args]))
    assert needle in line


def test_reduced_refuses_existing_output(app, tmp_path) -> None:
    out = tmp_path / "exists.nc"
    out.write_text("x")
    line = _one_error_line(_run(app, ["reduced", "--paths", "10", "--out", str(out)]))
    assert "the file exists" in line
    assert out.read_text() == "x"


def test_scaling_command_prints_every_predicted_law_and_refuses_n1():
    runner = CliRunner()
    res = runner.invoke(cli.app, ["scaling"], terminal_width=200)
    assert res.exit_code == 0, res.output
    for needle in ("t^1/3", "t^1/2", "t^2/3", "t^2", "finite-time blow-up", "exponential"):
        assert needle in res.output, needle
    res6 = runner.invoke(cli.app, ["scaling", "--n", "3"], terminal_width=200)
    assert "x^6/6" in res6.output and "t^3/2" in res6.output  # n/(n-1) for white noise on x
    bad = runner.invoke(cli.app, ["scaling", "--n", "1"])
    assert bad.exit_code == 2
    lines = [ln for ln in bad.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--n 1 is not accepted" in lines[0]


def test_reduced_tables_say_reduced_and_the_bfpe_footer_names_its_limits(app, tmp_path) -> None:
    """Walk-through N15: the reduced run's table title read as the pendulum's own run; R18: the
    B.F.P.E. footer's first two limits (0.337989, 0.25) had no label."""
    result = _run(app, ["reduced", "--order", "first", "--paths", "200", "--t-max", "5", "--n-times", "3",
                        "--out", str(tmp_path / "r.nc")])
    assert result.exit_code == 0, result.output
    assert "stochpend reduced dynamics (first order):" in " ".join(result.output.split())
    shown = _run(app, ["show", str(tmp_path / "r.nc")])
    assert "stochpend reduced dynamics (first order):" in " ".join(shown.output.split()), shown.output
    result = _run(app, ["bfpe", "--D", "1", "--tau", "0.1", "--t-max", "1e3", "--n-times", "3", "--n-cells", "100",
                        "--steps-per-decade", "10"])
    text = " ".join(result.output.split())
    assert "<E>/(Dt/tau^2)^1/2 0.337989, <E2>/(Dt/tau^2) 0.25, phi" in text, result.output
