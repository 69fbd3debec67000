"""Named long runs beyond the default reproduction, for a GPU: one run of a paper figure taken
to a final time the CPU cannot reach.

* ``fig4-crossover``: Fig. 4's tau = 0.01 run (OU, omega = 0, D = 1, seed 402) to t = 10^5, ten
  times its crossover time t_c = 1/(D tau^2) = 10^4 (the default stops at 10^3, in the
  white-like regime);
* ``fig2-long``: Fig. 2's (D, tau) = (1, 10) run (OU, omega = 1, seed 203) to t = 10^5 (the
  default stops at 10^4).

Each is drawn and tabulated by its figure's own ``draw`` and ``table``; ``stochpend reproduce
fig4-crossover --backend cuda --paths N`` runs it (``--t-max`` and ``--quick`` shorten it as for
the figures). They are not part of ``all``. :func:`expected_path_steps` is the cost model of
docs/reproduction.md, which :func:`stochpend.paper.reproduce.reproduce` prints with the lower bound of
:func:`stochpend.runs.resources.estimate` before a run starts.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from stochpend.model.settings import DEFAULT_H_MAX
from stochpend.paper.figures import fig2, fig4
from stochpend.paper.figures._common import FigureRun, fmt_num

__all__ = ["CASES", "Case", "expected_path_steps"]

#: The cost model of docs/reproduction.md ("What each figure runs"): with the default step
#: controls (h_max = 0.05, c = 0.1) a path costs ~4.7 t^{3/2} steps while the noise acts as
#: white (t < t_c; measured 3.8 t^{3/2} at t = 10^3) and ~6.6 D^{1/4} t^{5/4}/tau^{1/2} past t_c
#: (measured 0.8-0.9 times that at t = 10^4); never fewer than t/h_max.
WHITE_STEPS = 4.7
COLOURED_STEPS = 6.6


def expected_path_steps(figure_run: FigureRun) -> float:
    """Path-steps of an OU pendulum run by the cost model (:data:`WHITE_STEPS`,
    :data:`COLOURED_STEPS`): a rough figure, good to a factor of about 1.5."""
    D, tau, T = float(figure_run.D), float(figure_run.tau or 0.0), float(figure_run.t_max)
    h_max = figure_run.h_max or DEFAULT_H_MAX
    if tau <= 0.0:  # white noise: white-like throughout
        per_path = WHITE_STEPS * T**1.5
    else:
        t_c = 1.0 / (D * tau * tau)
        per_path = WHITE_STEPS * min(T, t_c) ** 1.5
        if T > t_c:
            per_path += COLOURED_STEPS * D**0.25 / math.sqrt(tau) * (T**1.25 - t_c**1.25)
    return float(figure_run.paths) * max(per_path, T / h_max)


class Case:
    """A named run: one run of ``figure`` (picked by (D, tau)) to ``t_max``, drawn by it."""

    def __init__(self, name: str, figure: Any, D: float, tau: float, t_max: float, why: str) -> None:
        self.NAME = name
        self.figure = figure
        self.D = D
        self.tau = tau
        self.t_max = t_max
        self.why = why
        self.TITLE = f"{figure.TITLE} — (D, τ) = ({D:g}, {tau:g}) to t = {fmt_num(t_max)}"
        self.CONFIG = {"figure": figure.NAME, "D": D, "tau": tau, "t_max": t_max,
                       "quick_t_max": figure.CONFIG["quick_t_max"]}

    def runs(self, paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
        T = t_max if t_max is not None else (self.CONFIG["quick_t_max"] if quick else self.t_max)
        picked = [s for s in self.figure.runs(paths, None, quick) if (s.D, s.tau) == (self.D, self.tau)]
        if len(picked) != 1:  # pragma: no cover - a figure's CONFIG changed under the case
            raise ValueError(f"{self.NAME}: {self.figure.NAME} has no single run with (D, tau) = "
                             f"({self.D:g}, {self.tau:g})")
        return [dataclasses.replace(picked[0], t_max=float(T))]

    def caption(self, figure_runs: list[FigureRun]) -> str:
        s = figure_runs[0]
        return (f"{self.figure.NAME}'s run (D, τ) = ({s.D:g}, {s.tau:g}), ω = {s.omega:g}, OU noise, "
                f"{s.paths} realizations, seed {s.seed}, to t = {fmt_num(s.t_max)} ({self.why}); "
                f"t_c = 1/(Dτ²) = {fmt_num(s.t_c)}; stationary ξ(0), θ(0) uniform, Ω(0) = 0, times "
                f"log-spaced from {s.t_min:g}. Drawn and tabulated as in {self.figure.NAME}.")

    def theory(self, datasets: dict) -> dict:
        return self.figure.theory(datasets)

    def draw(self, datasets: dict, theory: dict) -> Any:
        return self.figure.draw(datasets, theory)

    def table(self, datasets: dict, theory_values: dict | None = None) -> list:
        return self.figure.table(datasets, theory_values)

    @staticmethod
    def expected_path_steps(figure_run: FigureRun) -> float:
        return expected_path_steps(figure_run)


#: Name -> case (``stochpend reproduce NAME``; not part of ``all``).
CASES: dict[str, Case] = {
    "fig4-crossover": Case("fig4-crossover", fig4, 1.0, 0.01, 1e5,
                           "ten times its crossover time: the coloured regime of Fig. 4"),
    "fig2-long": Case("fig2-long", fig2, 1.0, 10.0, 1e5,
                      "a decade beyond the default 10⁴ of Fig. 2"),
}
