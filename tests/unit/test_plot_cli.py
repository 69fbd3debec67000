"""`stochpend plot`: <E>(t) of a saved run with its error band and the predicted law."""

from __future__ import annotations

import numpy as np
import pytest
from typer.testing import CliRunner

import stochpend
from stochpend import io, plotting
from stochpend.cli import app
from tests.conftest import SEED

MAGIC = {"png": b"\x89PNG\r\n\x1a\n", "pdf": b"%PDF-", "svg": b"<?xml"}


@pytest.fixture(scope="module")
def run_file(tmp_path_factory):
    folder = tmp_path_factory.mktemp("plot")
    ds = stochpend.simulate(noise="ou", paths=400, t_max=20.0, n_times=10, seed=SEED, bias_paths=0)
    return io.to_netcdf(ds, folder / "run.nc")


@pytest.mark.parametrize("fmt", ["png", "pdf", "svg"])
def test_writes_each_format(run_file, tmp_path, fmt):
    out = tmp_path / f"fig.{fmt}"
    result = CliRunner().invoke(app, ["plot", str(run_file), "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_bytes().startswith(MAGIC[fmt])
    assert [p.name for p in tmp_path.iterdir()] == [out.name]  # no temporary file left


def test_default_name_and_refusals(run_file, tmp_path):
    result = CliRunner().invoke(app, ["plot", str(run_file)])
    assert result.exit_code == 0, result.output
    png = run_file.with_suffix(".png")
    assert png.read_bytes().startswith(MAGIC["png"])
    again = CliRunner().invoke(app, ["plot", str(run_file)])
    assert again.exit_code == 2 and "the file exists (pass --overwrite" in " ".join(again.output.split())
    for args, needle in ((["--format", "jpg"], "--format='jpg' is not accepted"),
                         (["--out", str(tmp_path / "f.gif")], "its extension must be one of"),
                         (["--band", "-1", "--out", str(tmp_path / "g.png")], "--band=-1.0 is not accepted")):
        bad = CliRunner().invoke(app, ["plot", str(run_file), *args])
        assert bad.exit_code == 2 and needle in " ".join(bad.output.split()), bad.output
        assert "Traceback" not in bad.output
    assert not any(p.name.startswith(("f.", "g.")) for p in tmp_path.iterdir())


def test_predicted_laws_follow_the_model():
    """The pendulum with OU noise gets both of the paper's laws; dichotomous noise the predicted
    power law through the last point; the harmonic oscillator (exponential growth) none."""
    t = np.array([1.0, 10.0, 100.0])
    ou = stochpend.simulate(noise="ou", paths=200, times=tuple(t), t_max=100.0, seed=SEED, bias_paths=0)
    laws = plotting.predicted_mean_E(ou, t)
    assert len(laws) == 2
    np.testing.assert_allclose(laws[0][1], t / 4)  # D t/4 with D = 1
    np.testing.assert_allclose(laws[1][1], 0.33799 * np.sqrt(t), rtol=1e-4)
    tele = stochpend.simulate(noise="dichotomous", paths=200, times=tuple(t), t_max=100.0,
                              seed=SEED, bias_paths=0)
    (label, y, _), = plotting.predicted_mean_E(tele, t)
    nu = stochpend.theory.scaling.predicted_exponent("pendulum", "dichotomous").exponent
    assert y[-1] == pytest.approx(float(tele.mean_E[-1])) and y[0] == pytest.approx(y[-1] * 100.0**-nu)
    harm = stochpend.simulate(potential="harmonic", noise="white", paths=200, times=(1.0, 2.0),
                              t_max=2.0, seed=SEED, bias_paths=0, theta0=1.0)
    assert plotting.predicted_mean_E(harm, np.array([1.0, 2.0])) == []


def test_every_kind_of_file_the_tool_writes(tmp_path):
    """M7: plot of a sweep result (IndexError) and of a B.F.P.E. solution (KeyError
    'mean_E_stderr') ended in tracebacks. A run of the reduced dynamics is drawn; a sweep and a
    B.F.P.E. solution are refused in one line that says what the file is and what shows it;
    show of a checkpoint says it is one (M8)."""
    toml = tmp_path / "s.toml"
    toml.write_text("[base]\npaths = 100\nt_max = 2.0\nn_times = 3\n[grid]\nD = [0.5, 1.0]\n")
    made = {
        "sweep": ["sweep", str(toml), "--bias-paths", "0", "--quiet", "--out", str(tmp_path / "sweep.nc")],
        "bfpe": ["bfpe", "--t-max", "10", "--quiet", "--out", str(tmp_path / "bfpe.nc")],
        "reduced": ["reduced", "--paths", "100", "--t-max", "2", "--quiet", "--out", str(tmp_path / "reduced.nc")],
    }
    for kind, args in made.items():
        result = CliRunner().invoke(app, args)
        assert result.exit_code == 0, (kind, result.output)
    drawn = CliRunner().invoke(app, ["plot", str(tmp_path / "reduced.nc")])
    assert drawn.exit_code == 0, drawn.output
    assert (tmp_path / "reduced.png").read_bytes().startswith(MAGIC["png"])
    for kind, what in (("sweep", "a parameter sweep's result"), ("bfpe", "a B.F.P.E. solution")):
        path = tmp_path / f"{kind}.nc"
        refused = CliRunner().invoke(app, ["plot", str(path)])
        assert refused.exit_code == 2, refused.output
        text = " ".join(refused.output.split())
        assert "Traceback" not in refused.output and len(refused.output.strip().splitlines()) <= 3
        assert f"this is {what}; `stochpend show {path}` prints its table" in text, text
        assert CliRunner().invoke(app, ["show", str(path)]).exit_code == 0
        assert not path.with_suffix(".png").exists()
    ckpt = tmp_path / "x.ckpt"
    ckpt.write_bytes(b"STOCHPEND-CKPT\x00\x01" + b"\x00" * 64)
    shown = CliRunner().invoke(app, ["show", str(ckpt)])
    assert shown.exit_code == 2
    assert "it is a checkpoint, not a result; `stochpend resume" in " ".join(shown.output.split())


def test_show_warns_of_escaped_paths_as_simulate_does(tmp_path):
    """N17: show of a run with 63 of 100 non-finite paths printed nothing of them."""
    ds = stochpend.simulate(noise="ou", paths=64, t_max=1.0, n_times=2, seed=SEED, bias_paths=0)
    ds["nonfinite_paths"].values[-1] = 7
    path = io.to_netcdf(ds, tmp_path / "esc.nc")
    result = CliRunner().invoke(app, ["show", str(path)])
    assert result.exit_code == 0, result.output
    assert "7 paths went non-finite (or ran away) and are excluded." in " ".join(result.output.split())
