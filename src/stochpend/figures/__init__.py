"""The paper's four figures, and the exponent table beyond it: what each runs, how it is drawn,
and its table.

Each module in :data:`FIGURES` provides

* ``NAME``, ``TITLE`` and ``CONFIG`` (the runs of the caption, their seeds and final times),
* ``runs(paths, t_max, quick) -> list[RunSpec]``: the simulations to make,
* ``caption(specs) -> str``: what was run and why the time range,
* ``theory(datasets) -> dict``: the predictions needed to draw (e.g. B.F.P.E. solutions),
* ``draw(datasets, theory) -> matplotlib.figure.Figure`` (Agg canvas, no pyplot),
* ``table(datasets, theory=None) -> list[Row]``: late-time values against the predictions.

:data:`CASES` holds named long runs for a GPU (``fig4-crossover``, ``fig2-long``:
:mod:`stochpend.figures.cases`), with the same interface; ``all`` does not include them.

``datasets`` maps each run's key (``RunSpec.key``) to its result ``Dataset``, in the order of
``runs``. :func:`stochpend.reproduce.reproduce` ties them together.
"""

from __future__ import annotations

from types import ModuleType

from stochpend.figures import exponents, fig1, fig2, fig3, fig4
from stochpend.figures._common import COLUMNS, Fit, Row, RunSpec
from stochpend.figures.cases import CASES

#: Figure name -> module.
FIGURES: dict[str, ModuleType] = {
    "fig1": fig1, "fig2": fig2, "fig3": fig3, "fig4": fig4, "exponents": exponents,
}

__all__ = ["CASES", "COLUMNS", "FIGURES", "Fit", "Row", "RunSpec"]
