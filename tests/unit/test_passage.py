"""The law of a first-passage time from each path's own time (issue 23, stochpend.model.passage):
order statistics, distribution-free intervals that hold their coverage, censoring, the
histogram; the same numbers whatever the chunks, the threads, an interruption or a sweep; the
tables ``show`` prints. The law against an exact one: tests/statistical/test_first_passage.py.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import stochpend
from stochpend.model import passage
from stochpend.model.settings import SimulationConfig
from stochpend.observables import FirstPassage, Observable, register, unregister
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run

RUN = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=6.0, times=(2.0, 6.0), seed=4)


@pytest.fixture(autouse=True)
def escape_passage():
    register(FirstPassage("escape", lambda x, Omega, xi, t: 0.5 * Omega * Omega - math.cos(x), threshold=1.0,
                          probabilities=(0.05, 0.5, 0.95), bins=6))
    yield
    unregister("escape")


def test_the_quantiles_are_order_statistics_and_censored_beyond_the_fraction_passed():
    values = np.array([0.5, -1.0, 0.2, np.nan, 0.9])  # 4 finite paths, 3 passed, 1 excluded
    s = passage.summary(values, (0.25, 0.5, 0.75, 0.9), bins=2, t_end=1.0)
    assert (s["n"], s["passed"], s["censored"]) == (4, 3, 1)
    assert np.array_equal(s["quantile"], [0.2, 0.5, 0.9, np.nan], equal_nan=True)  # rank ceil(4 p) = 1, 2, 3, 4
    assert s["hist"].tolist() == [1, 2] and s["edges"].tolist() == [0.0, 0.5, 1.0]
    # n p an integer up to rounding (1000 * 0.1 = 100.00000000000001): rank 100, not 101
    s = passage.summary(np.arange(1, 1001) / 1000.0, (0.1,), bins=1, t_end=1.0)
    assert s["quantile"][0] == 0.1


def test_the_intervals_cover_the_true_quantile_at_least_95_percent_of_the_time():
    """Exponential samples of 200, censored at t_end = 2 (P(tau > 2) = 0.135): over 1000
    samples the interval of each quantile must contain the true one at least 95 % of the time
    (within 4 binomial errors: 0.95 - 0.028); the upper end of the 0.8 quantile is often
    beyond t_end, then NaN and taken as covering (the bound is only known to lie past t_end)."""
    rng = np.random.default_rng(7)
    probabilities = (0.1, 0.5, 0.8)
    true = -np.log1p(-np.array(probabilities))
    covered = np.zeros(3)
    reps = 1000
    for _ in range(reps):
        tau = rng.exponential(size=200)
        s = passage.summary(np.where(tau <= 2.0, tau, -1.0), probabilities, bins=4, t_end=2.0)
        upper = np.where(np.isnan(s["upper"]), np.inf, s["upper"])
        covered += (s["lower"] <= true) & (true <= upper)
    coverage = covered / reps
    assert np.all(coverage >= 0.95 - 4 * math.sqrt(0.05 * 0.95 / reps)), coverage
    assert np.all(coverage <= 0.995), coverage  # not trivially wide


def test_the_law_is_the_same_whatever_the_chunks_threads_or_an_interruption(tmp_path):
    config = SimulationConfig.build(**RUN, observables=("escape",))
    ref = run(config, bias_paths=0)
    names = [v for v in ref.data_vars if str(v).startswith("fpt_escape")]
    assert len(names) == 8 and 0 < int(ref.fpt_escape_passed) < RUN["paths"]
    for other in (run(config, bias_paths=0, chunk_paths=90, threads=1),):
        for name in names:
            assert np.array_equal(other[name].values, ref[name].values, equal_nan=True), name

    class StopInSecondChunk(ck.FileCheckpointer):
        def maybe_save(self, state):  # interrupted once a chunk is done: its times are in the file
            self.save(state)
            if state.b0 > 0 and state.j > 0:
                raise KeyboardInterrupt

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90,
                            checkpointer=StopInSecondChunk(path, None, config=config, chunk_paths=90))
    saved = ck.read(path).state.acc.passage
    assert np.isfinite(saved[0, :90]).all() and np.isnan(saved[0, 90:]).all()
    done = ck.resume(path)
    for name in ref.data_vars:
        assert np.array_equal(done[name].values, ref[name].values, equal_nan=True), name


def test_a_sweep_reports_each_sets_passage_law_as_its_run_alone():
    spec = {"base": {**{k: v for k, v in RUN.items() if k not in ("times", "D")}, "times": list(RUN["times"]),
                     "observables": ["escape"]},
            "grid": {"D": [0.5, 2.0]}}
    ds = stochpend.sweep.sweep(spec, bias_paths=0, scheduler="sync", tasks_per_set=3)
    assert ds.fpt_escape_quantile.dims == ("D", "fpt_escape_probability")
    assert ds.fpt_escape_probability.values.tolist() == [0.05, 0.5, 0.95]
    for D in (0.5, 2.0):
        alone = stochpend.simulate(**{**RUN, "D": D}, bias_paths=0, observables=("escape",))
        for name in [v for v in alone.data_vars if str(v).startswith("fpt_escape")]:
            assert np.array_equal(ds[name].sel(D=D).values, alone[name].values, equal_nan=True), (D, name)


@pytest.mark.parametrize("kwargs, message", [
    (dict(probabilities=(0.5, 1.5)), r"probabilities=\(0\.5, 1\.5\) is not accepted: a non-empty increasing"),
    (dict(probabilities=(0.5, 0.25)), "is not accepted: a non-empty increasing"),
    (dict(probabilities=()), "is not accepted: a non-empty increasing"),
    (dict(probabilities="median"), "probabilities='median' is not accepted"),
    (dict(bins=0), r"bins=0 is not accepted: an integer in \[1, 10000\]"),
    (dict(bins=2.5), "bins=2.5 is not accepted"),
])
def test_a_passage_law_that_cannot_be_read_is_refused_in_one_line(kwargs, message):
    with pytest.raises(ValueError, match=message) as info:
        FirstPassage("a", lambda x, Omega, xi, t: x, threshold=1.0, **kwargs)
    assert "\n" not in str(info.value)


def test_show_prints_the_quantiles_and_histogram_within_80_columns(tmp_path):
    from typer.testing import CliRunner

    from stochpend.cli import app

    out = tmp_path / "run.nc"
    runner = CliRunner()
    done = runner.invoke(app, ["simulate", "--plugin", "tests.unit._passage_plugin", "--observable", "Omega_up",
                               "--noise", "white", "--D", "0", "--omega", "0", "-p", "gamma=0", "-p", "additive_D=1",
                               "--Omega0", "0", "--paths", "400", "--t-max", "4", "--n-times", "2", "--seed", "2",
                               "--bias-paths", "0", "--out", str(out)])
    assert done.exit_code == 0, done.output
    assert "τ_Omega_up: quantiles" in done.stdout
    shown = runner.invoke(app, ["show", str(out)])
    assert shown.exit_code == 0, shown.output
    text = shown.stdout
    for needle in ("τ_Omega_up: quantiles", "95% interval", "τ_Omega_up: histogram", "> t_end", "censored"):
        assert needle in text, needle
    start = text.index("τ_Omega_up: quantiles")
    assert max(len(line) for line in text[start:].splitlines()) <= 80  # laid out in 80, even on a wide pipe
    import xarray as xr

    with xr.open_dataset(out) as ds:
        passed, n = int(ds.fpt_Omega_up_passed), int(ds.fpt_Omega_up_paths)
        n_censored = int(np.sum(ds.fpt_Omega_up_probability.values > passed / n))
    assert n_censored >= 1  # P(tau <= 4) = 0.62: the 0.75 and 0.9 quantiles lie beyond t_end
    rows = [line for line in text[start:].splitlines() if line.startswith("│") and " censored " in line]
    assert len(rows) == n_censored and all(f"p > {passed}/{n} passed" in row for row in rows), rows


def test_the_tables_escape_what_a_file_says():
    """A name from a file (attrs['observables']) reaches the terminal escaped: no control
    character, and Rich markup printed as text."""
    import io as _io

    import xarray as xr
    from rich.console import Console

    from stochpend.cli._common import passage_tables

    name = "x\x1b[2J[red]"
    pre = f"fpt_{name}"
    p = ("probability", [0.5, 0.9])
    ds = xr.Dataset({f"{pre}_quantile": (p[0], [1.0, np.nan]), f"{pre}_quantile_lower": (p[0], [0.5, np.nan]),
                     f"{pre}_quantile_upper": (p[0], [2.0, np.nan]), f"{pre}_hist": ("bin", [3, 4]),
                     f"{pre}_bin_edges": ("edge", [0.0, 1.0, 2.0]), f"{pre}_paths": 10, f"{pre}_passed": 7,
                     f"{pre}_censored": 3},
                    coords={f"{pre}_probability": ("probability", [0.5, 0.9])}, attrs={"observables": name})
    buffer = _io.StringIO()
    console = Console(file=buffer, width=200, color_system=None)
    for table in passage_tables(ds):
        console.print(table)
    text = buffer.getvalue()
    assert "\x1b" not in text and "\\x1b" in text and "[red]" in text


def test_paths_that_went_non_finite_are_excluded_from_the_law_as_from_every_statistic():
    """An observable that is infinite where |Omega| > 1.2 makes those paths non-finite (excluded
    from then on): the law counts the finite paths only, and its fraction passed is
    passed_<name>'s at t_end; a run whose only output time is 0 still has a histogram."""
    import warnings

    register(Observable("boom", lambda x, Omega, xi, t: math.inf if abs(Omega) > 1.2 else 0.0))
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", stochpend.StochpendWarning)
            ds = stochpend.simulate(**RUN, bias_paths=0, observables=("boom", "escape"))
    finally:
        unregister("boom")
    lost = int(ds.nonfinite_paths.values[-1])
    n, passed = int(ds.fpt_escape_paths), int(ds.fpt_escape_passed)
    assert 0 < lost < RUN["paths"] and n == RUN["paths"] - lost == int(ds.n_finite_paths.values[-1])
    assert passed == round(float(ds.passed_escape.values[-1]) * n) and passed + int(ds.fpt_escape_censored) == n
    assert f"{lost} non-finite paths excluded" in ds.fpt_escape_quantile.attrs["censoring"]
    at_zero = stochpend.simulate(**{**RUN, "times": (0.0,)}, bias_paths=0, observables=("escape",))
    assert int(at_zero.fpt_escape_hist.sum()) == int(at_zero.fpt_escape_passed)
