"""Sweeps: TOML validation, the result's layout, and exactness (no Dask needed here)."""

from __future__ import annotations

import io as io_text
import math
import sys
import textwrap

import numpy as np
import pytest
from rich.console import Console
from typer.testing import CliRunner

import stochpend
from stochpend import cli, io
from stochpend.cli import _common as common
from stochpend.cli._scale import resume_command, sweep_command, sweep_table
from stochpend.model.settings import SimulationConfig
from stochpend.numerics._sources import BUILD
from stochpend.runs.simulate import run
from stochpend.sweep import load_spec, plan_tasks, run_block, sweep

BASE = """
description = "tiny"
[base]
noise = "ou"
omega = 1.0
paths = 24
t_max = 2.0
n_times = 4
seed = 11
n_batches = 6
"""

GRID = BASE + """
[grid]
D = [1, 10]
tau = [0.1, 1, 10]
"""

CASES = BASE + """
[[case]]
D = 1
tau = 0.5

[[case]]
D = 10
tau = 2
seed = 3

[[case]]
noise = "white"
D = 2
"""


def _write(tmp_path, text, name="sweep.toml"):
    p = tmp_path / name
    p.write_text(textwrap.dedent(text))
    return p


def _assert_identical(a, b):
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.variables:
        assert np.array_equal(a[name].values, b[name].values, equal_nan=a[name].dtype.kind == "f"), name


@pytest.fixture
def app():
    """The main app with the sweep and resume commands registered (as cli.py will)."""
    names = {c.name for c in cli.app.registered_commands}
    if "sweep" not in names:
        cli.app.command("sweep")(sweep_command)
    if "resume" not in names:
        cli.app.command("resume")(resume_command)
    return cli.app


def test_grid_layout_and_exactness(tmp_path):
    ds = sweep(_write(tmp_path, GRID), tasks_per_set=4)
    assert ds.mean_E.dims == ("D", "tau", "time")
    assert ds.E_hist.dims[:3] == ("D", "tau", "time")
    assert ds.sizes["D"] == 2 and ds.sizes["tau"] == 3
    assert ds.D.values.tolist() == [1.0, 10.0] and ds.tau.values.tolist() == [0.1, 1.0, 10.0]
    assert ds.path_steps.dims == ("D", "tau")
    assert ds.attrs["noise"] == "ou" and ds.attrs["paths"] == 24 and "D" not in ds.attrs
    assert ds.attrs["sweep_tasks"] == 6 * 4 and ds.attrs["description"] == "tiny"
    # Every set equals the same simulation run on its own, to the last bit.
    for D in (1, 10):
        for tau in (0.1, 1, 10):
            cfg = SimulationConfig.build(noise="ou", omega=1.0, paths=24, t_max=2.0, n_times=4, seed=11,
                                         n_batches=6, D=D, tau=tau)
            ref = run(cfg)  # its bias estimate too, with the default pairs
            one = ds.sel(D=float(D), tau=float(tau))
            assert "mean_E_bias" in ref and "mean_E_bias_verdict" in ref
            for name in ref.data_vars:
                assert np.array_equal(one[name].values, ref[name].values, equal_nan=True), name
            assert int(one.path_steps) == ref.attrs["path_steps"]


def test_bias_variables_of_a_set_equal_simulate_of_its_config(tmp_path):
    ds = sweep(_write(tmp_path, CASES), tasks_per_set=2, bias_paths=20)
    assert ds.mean_E_bias.dims == ("case", "time") and ds.mean_E_bias_verdict.dims == ("case", "time")
    assert ds.attrs["bias_paths"] == 20 and ds.attrs["accuracy"] == "fixed"
    assert "bias_wall_time_s" not in ds.attrs and "bias_wall_time_s" not in ds
    for i, case in enumerate(({"D": 1.0, "tau": 0.5}, {"D": 10.0, "tau": 2.0, "seed": 3}, {"noise": "white", "D": 2.0})):
        params = {"noise": "ou", "omega": 1.0, "paths": 24, "t_max": 2.0, "n_times": 4, "seed": 11, "n_batches": 6}
        ref = stochpend.simulate(**{**params, **case}, bias_paths=20)
        names = [n for n in ref.data_vars if "_bias" in str(n)]
        assert len(names) > 10
        for name in names:
            assert np.array_equal(ds[name].isel(case=i).values, ref[name].values, equal_nan=True), name
        for key in ("bias_certified_until", "bias_horizon", "bias_path_steps", "bias_nonfinite_pairs"):
            value = ds[key].isel(case=i).item() if key in ds else ds.attrs[key]
            assert np.array_equal(value, ref.attrs[key], equal_nan=True), key
    none = sweep(_write(tmp_path, CASES), bias_paths=0)
    assert not [n for n in none.data_vars if "_bias" in str(n)] and "bias_paths" not in none.attrs
    with pytest.raises(ValueError, match="bias_paths=1 is not accepted"):
        sweep(_write(tmp_path, CASES), bias_paths=1)


def test_tasks_per_set_does_not_change_numbers(tmp_path):
    p = _write(tmp_path, GRID)
    _assert_identical(sweep(p, tasks_per_set=1), sweep(p, tasks_per_set=5))


def test_case_list_layout(tmp_path):
    ds = sweep(_write(tmp_path, CASES), tasks_per_set=2)
    assert ds.mean_E2.dims == ("case", "time")
    assert ds.case.values.tolist() == [0, 1, 2]
    assert ds.D.dims == ("case",) and ds.D.values.tolist() == [1.0, 10.0, 2.0]
    assert ds.noise.values.tolist() == ["ou", "ou", "white"]
    assert ds.seed.values.tolist() == [11, 3, 11]
    # each set records the compiled kernel it ran, as a single run does
    assert ds.kernel.values.tolist() == ["pendulum/force/ou/float64/adaptive/fast"] * 2 + [
        "pendulum/force/white/float64/adaptive/fast"]
    assert ds.tau.values[:2].tolist() == [0.5, 2.0] and np.isnan(ds.tau.values[2])
    ref = run(SimulationConfig.build(noise="white", D=2, omega=1.0, paths=24, t_max=2.0, n_times=4, seed=11,
                                     n_batches=6), bias_paths=0)
    for name in ref.data_vars:
        assert np.array_equal(ds[name].isel(case=2).values, ref[name].values, equal_nan=True), name


def test_dict_spec_and_netcdf_round_trip(tmp_path):
    spec = {"base": {"paths": 16, "t_max": 1.0, "n_times": 3, "n_batches": 4}, "grid": {"tau": [0.5, 2.0]}}
    ds = sweep(spec)
    out = io.to_netcdf(ds, tmp_path / "s.nc")
    back = io.open_results(out)
    _assert_identical(ds, back)


def test_sets_with_different_output_times(tmp_path):
    ds = sweep(_write(tmp_path, BASE.replace("t_max = 2.0", "") + "[grid]\nt_max = [1.0, 2.0]\n"))
    assert "time" not in ds.coords and ds.times.dims == ("t_max", "time")
    assert ds.times.values[:, -1].tolist() == [1.0, 2.0]
    back = io.open_results(io.to_netcdf(ds, tmp_path / "s.nc"))
    _assert_identical(ds, back)


def test_plan_tasks_covers_every_batch_once():
    spec = load_spec({"base": {"paths": 50, "n_batches": 7, "t_max": 1.0}, "grid": {"D": [1, 2]}})
    for per_set in (1, 3, 7, 100):
        tasks = plan_tasks(spec, per_set)
        for i, c in enumerate(spec.configs):
            mine = sorted((t.b0, t.b1) for t in tasks if t.set_index == i)
            assert mine[0][0] == 0 and mine[-1][1] == c.n_batches
            assert all(a[1] == b[0] for a, b in zip(mine, mine[1:], strict=False))
            assert sum(t.paths for t in tasks if t.set_index == i) == c.paths


class Recorder:
    def __init__(self):
        self.updates, self.task_counts, self.notes = [], [], []

    def start(self, total, description):
        self.total = total

    def update(self, done):
        self.updates.append(done)

    def finish(self):
        self.finished = True

    def tasks(self, done, total):
        self.task_counts.append((done, total))


def test_progress_reports_paths_and_tasks(tmp_path):
    rec = Recorder()
    sweep(_write(tmp_path, GRID), progress=rec, tasks_per_set=2)
    assert rec.total == 6 * 24 and rec.updates[-1] == 6 * 24
    assert rec.task_counts[0] == (0, 12) and rec.task_counts[-1] == (12, 12)
    assert all(b >= a for a, b in zip(rec.updates, rec.updates[1:], strict=False)) and rec.finished


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        (BASE + "[grid]\nDx = [1, 2]\n", "grid.Dx is not accepted: unknown parameter"),
        (BASE.replace("seed = 11", "sead = 11") + "[grid]\nD = [1, 2]\n", "base.sead is not accepted: unknown parameter"),
        (BASE + "[[case]]\nD = 1\nfoo = 2\n", "case[0].foo is not accepted: unknown parameter"),
        ("D = 1\n" + BASE + "[grid]\ntau = [1, 2]\n", "D is not accepted: unknown key (parameters go under"),
        (BASE + "[grid]\nD = [1, -1]\n", "grid set (D=-1): D=-1.0 is not accepted"),
        (BASE + "[grid]\ntau = [1, 0]\n", "tau=0.0 is not accepted"),
        (BASE + "[grid]\nD = 1\n", "grid.D=1 is not accepted: a grid axis is a non-empty list"),
        (BASE + "[grid]\nD = []\n", "grid.D=[] is not accepted"),
        (BASE + "[grid]\nD = [1, 1.0]\n", "grid.D=[1, 1.0] is not accepted: repeated values"),
        (BASE + "[grid]\nD = [[1], [2]]\n", "grid.D=[[1], [2]] is not accepted: each value"),
        (BASE + "[grid]\ntimes = [[1.0], [2.0]]\n", "grid.times is not accepted: times is a list"),
        (BASE + "[grid]\nseed = [1, 2]\n", "grid.seed is not accepted: seed is also set in [base]"),
        (BASE.replace("seed = 11", "seed = [1, 2]") + "[grid]\nD = [1, 2]\n", "base.seed=[1, 2] is not accepted: a single"),
        (BASE.replace("seed = 11", "seed = true") + "[grid]\nD = [1, 2]\n", "base.seed=True is not accepted"),
        (BASE + "[grid]\nD = [1, 2]\n[[case]]\nD = 3\n", "exactly one of [grid]"),
        (BASE, "exactly one of [grid]"),
        (BASE + "[grid]\n", "grid is not accepted: empty"),
        (BASE.replace('noise = "ou"', 'noise = "white"') + "[grid]\ntau = [1, 2]\n",
         "is the same simulation as grid set (tau=1)"),
        (BASE + "[[case]]\nn_times = 3\n[[case]]\nn_times = 5\n", "n_times is not accepted: it differs"),
        (BASE + "[[case]]\nhist_bins = 3\n[[case]]\nhist_bins = 5\n", "hist_bins is not accepted: it differs"),
        (BASE + "[[case]]\nnoise = 'pink'\n", "case[0]: noise='pink' is not accepted"),
        (BASE + "[grid\nD = [1]\n", "invalid TOML"),
        ('description = 3\n[grid]\nD = [1, 2]\n', "description=3 is not accepted"),
    ],
)
def test_validation_names_the_key(tmp_path, text, needle):
    p = _write(tmp_path, text)
    with pytest.raises(ValueError) as info:
        load_spec(p)
    message = str(info.value)
    assert needle in message, message
    assert "\n" not in message


def test_missing_file_and_bad_arguments(tmp_path):
    with pytest.raises(ValueError, match="no such file"):
        sweep(tmp_path / "nope.toml")
    p = _write(tmp_path, GRID)
    with pytest.raises(ValueError, match="scheduler='bogus' is not accepted: one of sync, threads, local"):
        sweep(p, scheduler="bogus")
    with pytest.raises(ValueError, match="tasks_per_set=0 is not accepted"):
        sweep(p, tasks_per_set=0)
    with pytest.raises(ValueError, match="workers=0 is not accepted"):
        sweep(p, workers=0)


@pytest.mark.parametrize("scheduler", ["threads", "local", "tcp://127.0.0.1:8786"])
def test_missing_dask_extra_is_one_clear_line(tmp_path, monkeypatch, scheduler):
    import stochpend.engine

    for name in ("dask", "distributed", "stochpend.runs.dask"):
        monkeypatch.setitem(sys.modules, name, None)
    monkeypatch.delattr(stochpend.engine, "dask", raising=False)
    with pytest.raises(ValueError) as info:
        sweep(_write(tmp_path, GRID), scheduler=scheduler)
    assert str(info.value) == f"scheduler={scheduler!r} requires the `dask` extra: pip install 'stochpend[dask]'"


def test_cli_sweep_writes_netcdf(tmp_path, app):
    p = _write(tmp_path, GRID)
    out = tmp_path / "sweep.nc"
    result = CliRunner().invoke(app, ["sweep", str(p), "--out", str(out), "--tasks-per-set", "3"])
    assert result.exit_code == 0, result.output
    assert "stochpend sweep: 6 parameter sets" in result.output and "wrote" in result.output
    back = io.open_results(out)
    assert back.mean_E.dims == ("D", "tau", "time")
    assert back.attrs["command_line"].startswith("stochpend")
    ref = sweep(p)
    for name in ref.data_vars:
        assert np.array_equal(back[name].values, ref[name].values, equal_nan=True), name


def test_cli_sweep_table_shows_the_bias_it_estimated_and_counts_workers_in_words(tmp_path, app):
    """Walk-through M22: the sweep printed "estimating the discretisation bias" and then no bias
    column, and its caption said "(1 workers)"."""
    p = _write(tmp_path, CASES)
    wide = {"COLUMNS": "250", "TERMINAL_WIDTH": "250"}
    result = CliRunner().invoke(app, ["sweep", str(p), "--bias-paths", "8", "--out", str(tmp_path / "s.nc")], env=wide)
    assert result.exit_code == 0, result.output
    assert "bias <E>" in result.output and "discretisation bias at the last time" in result.output
    assert "(1 worker)" in result.output and "workers)" not in result.output
    back = io.open_results(tmp_path / "s.nc")
    cells = common._bias_cell(float(back.mean_E_bias.isel(case=0, time=-1)),
                              float(back.mean_E_bias_stderr.isel(case=0, time=-1)),
                              int(back.mean_E_bias_verdict.isel(case=0, time=-1)))
    assert cells in result.output
    result = CliRunner().invoke(app, ["sweep", str(p), "--bias-paths", "0"], env=wide)
    assert result.exit_code == 0 and "bias <E>" not in result.output, result.output


@pytest.mark.parametrize(
    ("text", "args", "needle"),
    [
        (GRID.replace("tau = [0.1, 1, 10]", "taux = [0.1, 1]"), [], "grid.taux is not accepted"),
        (GRID.replace("D = [1, 10]", "D = [1, -10]"), [], "D=-10.0 is not accepted"),
        (GRID, ["--scheduler", "nowhere"], "--scheduler 'nowhere' is not accepted"),
        (GRID, ["--workers", "0"], "--workers 0 is not accepted"),
    ],
)
def test_cli_refusals_exit_2(tmp_path, app, text, args, needle):
    p = _write(tmp_path, text)
    result = CliRunner().invoke(app, ["sweep", str(p), "--quiet", *args])
    assert result.exit_code == 2, result.output
    assert needle in result.output
    assert "Traceback" not in result.output


def test_cli_refuses_existing_out_before_work(tmp_path, app):
    p = _write(tmp_path, GRID)
    out = tmp_path / "s.nc"
    out.write_text("x")
    result = CliRunner().invoke(app, ["sweep", str(p), "--out", str(out)])
    assert result.exit_code == 2 and "the file exists" in result.output


def test_run_block_refuses_another_build():
    config = SimulationConfig.build(paths=4, t_max=0.1, n_times=1)
    assert run_block(config, 0, 0, 1, expect_version=BUILD).paths == 1
    with pytest.raises(ValueError, match=r"a worker runs stochpend .* \(code [0-9a-f]{12}\), the client stochpend 0.0.0"):
        run_block(config, 0, 0, 1, expect_version="0.0.0 (code 000000000000)")


# -- a sweep of targets (issue 35: "sweeps accept a target") ---------------------------------------
GAMMA, D_A = 0.5, 0.4
#: The damped pendulum started in its Boltzmann law (tests/unit/test_multilevel.py's cheap case);
#: the last set's coarse step needs more levels (5) than the others (3): the level dimension padded.
TARGET_BASE = dict(noise="white", D=0.0, omega=1.0, t_max=2.0, times=[1.0, 2.0], h_max=0.5, gamma=GAMMA,
                   additive_D=D_A, initial_temperature=0.4)
TARGET_CASES = [dict(seed=3), dict(seed=5, h_max=0.25), dict(seed=4, h_max=2.0)]


def _target_spec(**target):
    return {"base": TARGET_BASE, "case": TARGET_CASES, **target}


def test_a_sweep_of_targets_gives_each_set_the_numbers_of_its_own_target_run():
    import warnings

    ds = sweep(_target_spec(target_error=0.05))
    assert ds.attrs["title"] == "stochpend parameter sweep" and ds.attrs["target_error"] == 0.05
    assert ds.sizes["case"] == 3 and ds.sizes["level"] == int(ds["target_levels"].max()) > 3
    for i, case in enumerate(TARGET_CASES):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", stochpend.StochpendWarning)
            one = stochpend.simulate(**{**TARGET_BASE, **case}, target_error=0.05)
        n_levels = one.sizes["level"]
        row = ds.isel(case=i)
        for name, var in one.data_vars.items():
            got = row[name].isel(level=slice(0, n_levels)) if "level" in var.dims else row[name]
            assert got.dtype == var.dtype and np.array_equal(got.values, var.values, equal_nan=True), (i, name)
        pad = row.isel(level=slice(n_levels, None))
        assert np.all(pad["n_samples"].values == 0) and np.all(np.isnan(pad["mean_E_level_mean"].values))
        for key in ("target_level_seeds", "target_levels", "target_certified", "path_steps"):
            got = row[key].item() if key in row else ds.attrs[key]
            assert got == one.attrs[key], (i, key)
    assert int(ds.path_steps.sum()) == ds.attrs["path_steps"]
    assert sum(n_levels > 3 for n_levels in ds["target_levels"].values) == 1


@pytest.mark.parametrize(("spec", "kwargs", "needle"), [
    (_target_spec(target_error=0.0), {}, "sweep: target_error=0.0 is not accepted: a number in (0, 1)"),
    (_target_spec(target_error=0.05), {"target_error": math.nan}, "target_error=nan is not accepted"),
    (_target_spec(target_confidence=0.9), {}, "sweep: target_confidence=0.9 is not accepted without target_error"),
    (_target_spec(target_error=0.05, target_statistics="kurtosis"), {}, "target_statistics='kurtosis' is not accepted"),
    ({**_target_spec(target_error=0.05, target_times=[2.0]), "case": [dict(seed=3), dict(seed=5, times=[1.0, 3.0], t_max=3.0)]},
     {}, "target_times=[2.0] is not accepted: times among the run's output times (2 from 1 to 3; set them "
         "with times=) (parameter set 2 of 2)"),
    (_target_spec(target_error=0.05), {"scheduler": "sync"},
     "scheduler='sync' is not accepted with target_error: a target run plans each round from the last"),
    (_target_spec(target_error=0.05), {"max_path_steps": 1e4}, "its pilot alone (256 samples on each of levels "
                                                                "0..2) needs about"),
])
def test_a_bad_target_in_a_sweep_is_refused_before_any_work(spec, kwargs, needle, monkeypatch):
    from stochpend.runs import multilevel

    def no_work(*args, **kwargs):
        raise AssertionError("a level ran")

    monkeypatch.setattr(multilevel, "run_level", no_work)
    with pytest.raises(ValueError) as info:
        sweep(spec, **kwargs)
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_cli_sweep_of_targets_writes_prints_and_shows(tmp_path, app):
    text = BASE.replace('noise = "ou"', 'noise = "white"\ngamma = 0.5\nadditive_D = 0.4\ninitial_temperature = 0.4\n'
                                          'D = 0.0\nh_max = 0.5\ntimes = [1.0, 2.0]').replace("n_times = 4\n", "")
    p = _write(tmp_path, text + "[[case]]\nseed = 3\n[[case]]\nseed = 5\nh_max = 0.25\n")
    out = tmp_path / "s.nc"
    wide = {"COLUMNS": "250", "TERMINAL_WIDTH": "250"}
    result = CliRunner().invoke(app, ["sweep", str(p), "--target-error", "0.05", "--target-statistics", "mean_E",
                                      "--out", str(out)], env=wide)
    assert result.exit_code == 0, result.output
    assert "2 parameter sets, target 0.05 at 95 %" in result.output and "2/2" in result.output
    back = io.open_results(out)
    ref = sweep(p, target_error=0.05, target_statistics="mean_E")
    for name, var in ref.data_vars.items():  # target_level_seeds: strings
        assert np.array_equal(back[name].values, var.values, equal_nan=var.dtype.kind == "f"), name
    shown = CliRunner().invoke(app, ["show", str(out)], env=wide)
    assert shown.exit_code == 0 and "2 parameter sets, target 0.05" in shown.output, shown.output
    # two statistics in 80 columns: every value whole ('4.90e-02' had been cut to '4.90e-…')
    two = sweep(p, target_error=0.05)
    console = Console(width=80, record=True, file=io_text.StringIO())
    console.print(sweep_table(two))
    screen = console.export_text()
    assert "…" not in screen and max(len(line) for line in screen.splitlines()) <= 80, screen
    assert "%" in screen
    for args, needle in ((["--target-error", "0"], "--target-error 0.0 is not accepted"),
                         (["--target-error", "0.05", "--target-times", "x"], "--target-times 'x' is not accepted"),
                         (["--target-error", "0.05", "--scheduler", "threads"], "--scheduler 'threads' is not accepted"),
                         (["--target-confidence", "0.9"], "--target-confidence 0.9 is not accepted without target_error")):
        refused = CliRunner().invoke(app, ["sweep", str(p), "--out", str(tmp_path / "r.nc"), *args])
        assert refused.exit_code == 2 and needle in " ".join(refused.output.split()), refused.output
        assert len(refused.output.strip().splitlines()) == 1 and not (tmp_path / "r.nc").exists()
