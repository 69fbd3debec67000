"""The paper's four figures, and the exponent table beyond it: what each runs, how it is drawn,
and its table.

Each module in :data:`FIGURES` provides

* ``NAME``, ``TITLE`` and ``CONFIG`` (the runs of the caption, their seeds and final times),
* ``runs(paths, t_max, quick) -> list[FigureRun]``: the simulations to make,
* ``caption(figure_runs) -> str``: what was run and why the time range,
* ``theory(datasets) -> dict``: the predictions needed to draw (e.g. B.F.P.E. solutions),
* ``draw(datasets, theory) -> matplotlib.figure.Figure`` (Agg canvas, no pyplot),
* ``table(datasets, theory=None) -> list[Row]``: late-time values against the predictions.

:data:`GALLERY` holds the family's figures (``family-boltzmann``, ``family-kramers``,
``family-washboard``, ``family-random-frequency``; ``family`` names the four), with the same
interface; ``all`` does not include them. :data:`CASES` holds named long runs for a GPU (``fig4-crossover``, ``fig2-long``:
:mod:`stochpend.paper.figures.cases`), with the same interface; ``all`` does not include them.

``datasets`` maps each run's key (``FigureRun.key``) to its result ``Dataset``, in the order of
``runs``. :func:`stochpend.paper.reproduce.reproduce` ties them together.
"""

from __future__ import annotations

from types import ModuleType

from stochpend.paper.figures import (
    exponents,
    family_boltzmann,
    family_kramers,
    family_random_frequency,
    family_washboard,
    fig1,
    fig2,
    fig3,
    fig4,
)
from stochpend.paper.figures._common import COLUMNS, FigureRun, Fit, Row
from stochpend.paper.figures.cases import CASES

#: Figure name -> module.
FIGURES: dict[str, ModuleType] = {
    "fig1": fig1, "fig2": fig2, "fig3": fig3, "fig4": fig4, "exponents": exponents,
}

#: The family's gallery (issue 23 item 5): one command each, ``stochpend reproduce family-*``,
#: or ``family`` for the four. Not part of ``all``, which stays the paper's reproduction
#: (docs/family.md, "Gallery": together they add several minutes on two cores).
GALLERY: dict[str, ModuleType] = {
    m.NAME: m for m in (family_boltzmann, family_kramers, family_washboard, family_random_frequency)
}

__all__ = ["CASES", "COLUMNS", "FIGURES", "GALLERY", "Fit", "Row", "FigureRun"]
