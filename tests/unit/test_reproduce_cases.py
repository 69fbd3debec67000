"""The named long runs for a GPU (stochpend.paper.figures.cases) and the cost lines of reproduce."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import pytest

from stochpend.paper import reproduce as rp
from stochpend.paper.figures import CASES, FIGURES
from tests import _background

ROOT = Path(__file__).resolve().parents[2]


def test_cases_are_the_two_long_runs_and_not_part_of_all():
    crossover = CASES["fig4-crossover"].runs(10**6, None, False)
    assert len(crossover) == 1
    (s,) = crossover
    fig4_run = next(r for r in FIGURES["fig4"].runs(10**6, None, False) if r.tau == 0.01)
    assert (s.noise, s.D, s.tau, s.omega, s.seed, s.t_max) == ("ou", 1.0, 0.01, 0.0, fig4_run.seed, 1e5)
    assert s.t_max == 10 * s.t_c
    (long,) = CASES["fig2-long"].runs(10**6, None, False)
    assert (long.D, long.tau, long.omega, long.t_max) == (1.0, 10.0, 1.0, 1e5)
    assert CASES["fig2-long"].runs(8, 0.3, False)[0].t_max == 0.3  # --t-max shortens it
    assert CASES["fig2-long"].runs(8, None, True)[0].t_max == 100.0  # --quick too
    assert rp._figure_names("all") == list(FIGURES)
    assert rp._figure_names("fig4-crossover fig2-long") == ["fig4-crossover", "fig2-long"]
    with pytest.raises(ValueError, match="fig4-crossover, fig2-long, all"):
        rp._figure_names("fig5")


def test_cost_model_matches_the_documented_figures():
    """docs/reproduction.md: a tau = 0.01 path costs ~1e8 steps to t = 1e5 (4.7 t^{3/2} to t_c =
    1e4, then 6.6 D^{1/4} t^{5/4}/tau^{1/2}); a white-like path 1.5e5 at t = 1e3."""
    (s,) = CASES["fig4-crossover"].runs(1, None, False)
    per_path = CASES["fig4-crossover"].expected_path_steps(s)
    assert 0.9e8 < per_path < 1.3e8, per_path
    short = FIGURES["fig4"].runs(1, 1e3, False)[0]
    assert CASES["fig4-crossover"].expected_path_steps(short) == pytest.approx(4.7 * 1e3**1.5)
    (long,) = CASES["fig2-long"].runs(10, None, False)
    assert CASES["fig2-long"].expected_path_steps(long) == pytest.approx(
        10 * 6.6 / 10**0.5 * (1e5**1.25 - 0.01**1.25) + 10 * 4.7 * 0.01**1.5)


def background_run(folder: Path) -> _background.Command:
    """`stochpend reproduce fig4-crossover fig2-long --backend cuda` at toy size under
    NUMBA_ENABLE_CUDASIM=1 (about 75 s, most of it the simulator's threads), started with the
    session (tests/_background.py)."""
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")])}
    command = [sys.executable, "-m", "stochpend", "reproduce", "fig4-crossover", "fig2-long",
               "--backend", "cuda", "--paths", "8", "--t-max", "0.3", "--out", str(folder / "gpu-scale")]
    return _background.Command(command, env=env)


@pytest.mark.gpu
def test_cases_run_end_to_end_in_the_cuda_simulator_and_print_their_cost():
    """`stochpend reproduce fig4-crossover fig2-long --backend cuda` at toy size under
    NUMBA_ENABLE_CUDASIM=1: a cost line per run and a total before the work, then every file."""
    run = _background.start(__name__, background_run)
    out = run.folder / "gpu-scale"
    res = run.wait(timeout=600)
    text = res.stdout + res.stderr
    assert res.returncode == 0, text[-4000:]
    cost = [line for line in text.splitlines() if line.startswith("cost:")]
    assert len(cost) == 3, text[-4000:]
    assert "fig4-crossover" in cost[0] and "fig2-long" in cost[1]
    for line in cost[:2]:
        assert "8 paths to t = 0.3" in line and "on the GPU" in line
        assert "by the cost model" in line and "path-steps/s" in line
    assert cost[2].startswith("cost: 2 run(s) to simulate on cuda (float64)")
    assert text.index(cost[-1]) < text.index("fig4-crossover: 1 runs")  # before the work
    for name in ("fig4-crossover", "fig2-long"):
        assert (out / f"{name}.png").stat().st_size > 0
        assert (out / f"{name}_table.csv").is_file()
    results = json.loads((out / "results.json").read_text())
    assert results["settings"]["backend"] == "cuda"
    assert {r["t_max"] for r in results["runs"].values()} == {0.3}
    assert len(list((out / "runs").glob("*.nc"))) == 2
