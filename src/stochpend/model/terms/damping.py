"""Linear damping, -gamma Omega in dOmega/dt: part of the step's Ornstein-Uhlenbeck flow of
Omega (exp(-gamma h), with the additive white noise), not a kick, so the step writes it
(:func:`stochpend.engine.integrator.build`); the table gives its parameter and its bound h <= c/gamma."""

from __future__ import annotations

from stochpend.model.parameters import Parameter
from stochpend.model.terms.base import Term

DAMPING = Term(
    name="damping",
    parameters=(Parameter("gamma", 0.0, "linear damping gamma, -gamma Omega in dOmega/dt", low=0.0),),
    switch="gamma",
    rate="gamma",
    coupling="flow",
)
