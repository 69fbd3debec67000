"""Bad input is refused before any work: one line naming the parameter; CLI exit code 2."""

from __future__ import annotations

import math

import pytest
from typer.testing import CliRunner

import stochpend
from stochpend.cli import app

BAD_API = [
    (dict(D=-1.0), "D=-1.0"),
    (dict(tau=0.0), "tau=0.0"),
    (dict(tau=-2.0), "tau=-2.0"),
    (dict(omega=-0.5), "omega=-0.5"),
    (dict(paths=0), "paths=0"),
    (dict(paths=2.5), "paths=2.5"),
    (dict(t_max=0.0), "t_max=0.0"),
    (dict(t_max=math.inf), "t_max=inf"),
    (dict(seed=-1), "seed=-1"),
    (dict(seed=2**64), "seed="),
    (dict(D=math.nan), "D=nan"),
    (dict(omega=math.inf), "omega=inf"),
    (dict(noise="pink"), "noise='pink'"),
    (dict(times=[5.0, 1.0]), "times="),
    (dict(times=[1.0, 2000.0]), "times="),
    (dict(times=[-1.0, 2.0]), "times="),
    (dict(times=[1.0, math.nan]), "times="),
    (dict(theta0=0.0, Omega0=0.0), "theta0=0.0"),
    (dict(theta0=math.pi, Omega0=0.0), "theta0="),
    (dict(theta0="random"), "theta0='random'"),
    (dict(h_max=0.0), "h_max=0.0"),
    (dict(step_c=-1.0), "step_c=-1.0"),
    (dict(hist_bins=0), "hist_bins=0"),
    (dict(backend="tpu"), "backend='tpu'"),
    (dict(potential="duffing"), "potential='duffing'"),
    (dict(coupling="position"), "coupling='position'"),
    (dict(threads=0), "threads=0"),
]


@pytest.mark.parametrize("kwargs,needle", BAD_API)
def test_api_refuses_bad_input_with_one_line(kwargs, needle):
    with pytest.raises(ValueError) as info:
        stochpend.simulate(**{"paths": 10, "t_max": 1.0, "n_times": 2, **kwargs})
    message = str(info.value)
    assert needle in message, f"message does not name the value: {message!r}"
    assert "\n" not in message, f"message is not one line: {message!r}"
    assert "accepted" in message


def test_fixed_point_refusal_only_at_rest():
    # theta0 = 0 is fine when the pendulum moves
    ds = stochpend.simulate(paths=4, t_max=0.1, n_times=1, theta0=0.0, Omega0=0.5, n_batches=2)
    assert int(ds.n_finite_paths[-1]) == 4


BAD_CLI = [
    (["--D", "-1"], "--D -1.0"),
    (["--tau", "0"], "--tau 0.0"),
    (["--omega", "-1"], "--omega -1.0"),
    (["--paths", "0"], "--paths 0"),
    (["--t-max", "0"], "--t-max 0.0"),
    (["--seed", "-3"], "--seed -3"),
    (["--D", "nan"], "--D nan"),
    (["--t-max", "inf"], "--t-max inf"),
    (["--noise", "pink"], "--noise 'pink'"),
    (["--times", "10,5"], "--times "),
    (["--times", "1,2000"], "--times "),
    (["--times", "a,b"], "--times 'a,b'"),
    (["--theta0", "0"], "--theta0 0.0"),
    (["--theta0", "north"], "--theta0 'north'"),
    (["--out", "/nonexistent-dir/x.nc"], "--out "),
    (["--potential", "cubic"], "--potential 'cubic'"),
    (["--coupling", "velocity"], "--coupling 'velocity'"),
    (["--coupling", "position"], "--coupling 'position'"),  # the pendulum's angle is periodic
    (["--potential", "power", "--n", "0"], "--n 0"),
    (["--noise", "ou", "--omega-noise", "2"], "--omega-noise 2.0"),
    (["--noise", "harmonic", "--omega-noise", "0"], "--omega-noise 0.0"),
    (["--noise", "dichotomous", "--tau", "-1"], "--tau -1.0"),
]


def test_cli_runs_the_other_models_and_says_when_they_blow_up():
    """The new flags reach the simulation, the table's title names the model, and a blow-up is
    diagnosed in one line."""
    runner = CliRunner()
    ok = runner.invoke(app, ["simulate", "--paths", "20", "--t-max", "2", "--n-times", "3",
                             "--noise", "harmonic", "--omega-noise", "1.5", "--potential", "power",
                             "--n", "2", "--coupling", "position"])
    assert ok.exit_code == 0, ok.output
    assert "U = x^4/4 (position coupling), harmonic noise" in ok.output and "W=1.5" in ok.output
    boom = runner.invoke(app, ["simulate", "--paths", "200", "--t-max", "3", "--n-times", "4",
                               "--noise", "white", "--potential", "power", "--coupling", "force"])
    assert boom.exit_code == 0, boom.output
    assert "growth of <E>: finite-time blow-up" in boom.output


@pytest.mark.parametrize("args,needle", BAD_CLI)
def test_cli_refuses_bad_input_exit_2_one_line(args, needle, tmp_path):
    runner = CliRunner()
    extra = ["--omega", "0"] if args[:2] == ["--theta0", "0"] else []
    result = runner.invoke(app, ["simulate", "--paths", "10", "--t-max", "1", *args, *extra])
    assert result.exit_code == 2, result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, f"expected one line, got: {result.output!r}"
    assert needle in lines[0] and "Traceback" not in result.output


def test_cli_refuses_existing_out_without_overwrite(tmp_path):
    out = tmp_path / "run.nc"
    out.write_bytes(b"keep me")
    result = CliRunner().invoke(app, ["simulate", "--paths", "10", "--t-max", "1", "--out", str(out)])
    assert result.exit_code == 2
    assert "exists" in result.output
    assert out.read_bytes() == b"keep me", "an existing file was touched"


def test_cuda_refused_with_reason_where_there_is_no_gpu():
    from stochpend.engine import cuda as cuda_backend

    usable, _ = cuda_backend.availability()
    if usable:
        pytest.skip("a usable GPU is present: nothing to refuse")
    result = CliRunner().invoke(app, ["simulate", "--paths", "10", "--t-max", "1", "--backend", "cuda"])
    assert result.exit_code == 2
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and "--backend 'cuda'" in lines[0] and "stochpend[cuda]" in lines[0], result.output
    # auto falls back to the CPU
    ds = stochpend.simulate(paths=10, t_max=0.5, n_times=1, backend="auto")
    assert ds.attrs["backend"] == "cpu"
