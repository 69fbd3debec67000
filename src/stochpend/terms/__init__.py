"""The family's terms, one file each, in one table (as the statistics are ``observables.SUMS``).

Each entry (:class:`~stochpend.terms.base.Term`) declares its parameters, its kick over a step
and its step bound; :mod:`stochpend.dynamics` declares the family's parameters and record from
the table, and :func:`stochpend.integrator.build` composes the kick and the bound of the terms
that are on at compile time. A new term is one file here, its entry in :data:`TABLE` and its
test (tests/unit/test_terms.py walks the table: each kick against its integrand's integral).

The additive noise channel is not in the table: like the damping, it is part of the step's
Ornstein-Uhlenbeck flow or has a state of its own (:mod:`stochpend.dynamics`).
"""

from __future__ import annotations

from stochpend.terms.base import COUPLINGS, Term
from stochpend.terms.damping import DAMPING
from stochpend.terms.drive import DRIVE
from stochpend.terms.parametric import PARAMETRIC
from stochpend.terms.torque import TORQUE

__all__ = ["COUPLINGS", "TABLE", "Term"]

#: The terms in the order of their parameters, of the step bounds (each bound is taken on the
#: step the previous left) and, among the terms of one coupling, of their kicks.
TABLE: tuple[Term, ...] = (DAMPING, TORQUE, DRIVE, PARAMETRIC)
