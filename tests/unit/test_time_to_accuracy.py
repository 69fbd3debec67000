"""benchmarks/time_to_accuracy.py's speed-up table (issue 35, "Fast"): a speed-up only where the
target run certified its target, against the best of the other routes."""

from __future__ import annotations

from benchmarks.time_to_accuracy import Row, speedups, table


def _rows(a_how: str, a_note: str) -> list[Row]:
    return [Row("ou-pendulum", 1.0, 1e-3, "(a) target_error, h_max 0.2", 40.0, 2e9, a_how, a_note),
            Row("ou-pendulum", 1.0, 1e-3, "(b) best fixed step", 120.0, 1.6e10, "projected"),
            Row("ou-pendulum", 1.0, 1e-3, "(e) C reference", 90.0, 1.6e10, "projected"),
            Row("ou-pendulum", 1.0, 1e-3, "(d) diffrax", float("nan"), float("nan"), "not available")]


def test_the_speed_up_is_against_the_best_other_route_and_only_for_a_certified_run():
    line = speedups(_rows("run", "levels 6, worst relative total 0.00098, certified")).splitlines()[-1]
    assert "40 s (run, certified)" in line and "90 s (e)" in line and line.endswith("| 2.25× |")
    line = speedups(_rows("run", "levels 3, worst relative total 0.64, NOT certified")).splitlines()[-1]
    assert "(run, NOT certified)" in line and line.endswith("| – |")
    line = speedups(_rows("refused", "target_error=0.001 is not accepted")).splitlines()[-1]
    assert line.endswith("| – |")


def test_a_refused_target_row_keeps_both_ends_of_the_plan(monkeypatch):
    # The refusal after a pilot names the plan at the estimates and, much lower, the plan two
    # standard errors up (1.71e12 against 1.8e10 on the OU pendulum at t = 1, 3e-4): the row's
    # path-steps are the first, its note carries both.
    from benchmarks import time_to_accuracy

    def refuse(**_kwargs):
        raise ValueError("target_error=0.0003 is not accepted: the plan would bring the work to 1.71e+12 "
                         "path-steps at the estimates so far and to 1.8e+10, about 7.2 min here if each "
                         "target statistic is two standard errors larger (3.1e+08 already spent), more than ...")

    monkeypatch.setattr(time_to_accuracy, "_simulate", refuse)
    row = time_to_accuracy.method_a({}, 1.0, 3e-4, 1e13, 1, 0.2, 400.0)
    assert row.how == "refused" and row.path_steps == 1.71e12
    assert row.note.startswith("plan 1.71e+12 path-steps at the pilot's estimates, 1.8e+10 two standard errors up; ")


def test_the_table_gives_no_ratio_to_a_refused_runs_projection():
    """A refused (a)'s seconds project the plan at its pilot's estimates (1.71e12 path-steps
    named where 2.4e10 was about right): the row printed 0.258x, which was no result."""
    rows = _rows("projected (refused)", "plan 1.71e+12 path-steps at the pilot's estimates")
    a_line, b_line = table(rows).splitlines()[2:4]
    assert "projected (refused)" in a_line and a_line.endswith("| – |")
    assert b_line.endswith("| 1× |")
    rows = _rows("run", "levels 6, worst relative total 0.00098, certified")
    assert table(rows).splitlines()[2].endswith("| 3× |")  # a run's ratio stays
