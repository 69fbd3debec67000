"""The paper (Mallick & Marcq 2004): its equation numbers, its figures and their
one-command reproduction.

The names here are :mod:`stochpend.text.equations`' (the printed equation numbers,
``stochpend.paper.EQUATIONS``, as always); the figures are :mod:`stochpend.paper.figures`,
``stochpend reproduce`` is :mod:`.reproduce` with its HTML report (:mod:`.report`), and the
plotting helpers are :mod:`.plotting` (public as ``stochpend.plotting``).
"""

from __future__ import annotations

from stochpend.text.equations import EQUATIONS, cite, eq, number_equations, with_numbers

__all__ = ["EQUATIONS", "cite", "eq", "number_equations", "with_numbers"]
