"""The family's terms, one file each, in one table (as the statistics are ``observables.SUMS``).

Each entry (:class:`~stochpend.terms.base.Term`) declares its parameters, how it enters the
step and its step bound; :mod:`stochpend.model.dynamics` declares the family's parameters, terms and
kernel record from the table, the step control composes the bounds of the terms that are on at
compile time (:func:`stochpend.engine.integrator.build`), params and the CUDA backend's variants read
it. Each term's kick is still written in the step (``family_step``): composed from per-term
functions, the kicks of the drive and the modulation stayed calls in the SIMD lane loop (Numba
does not inline a function called from a function it inlines), which stopped its vectorization
(5x slower per step); docs/numerics.md, "The family's terms".

The additive noise channel is not in the table: like the damping, it is part of the step's
Ornstein-Uhlenbeck flow or has a state of its own (:mod:`stochpend.model.dynamics`).
"""

from __future__ import annotations

from stochpend.model.terms.base import COUPLINGS, Term
from stochpend.model.terms.damping import DAMPING
from stochpend.model.terms.drive import DRIVE
from stochpend.model.terms.parametric import PARAMETRIC
from stochpend.model.terms.torque import TORQUE

__all__ = ["COUPLINGS", "TABLE", "Term"]

#: The terms in the order of their parameters and of the step bounds (each bound is taken on the
#: step the previous left).
TABLE: tuple[Term, ...] = (DAMPING, TORQUE, DRIVE, PARAMETRIC)
