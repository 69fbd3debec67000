"""A constant force F in dOmega/dt (the tilted washboard): its kick over a step is F h."""

from __future__ import annotations

from stochpend.model.parameters import Parameter
from stochpend.model.terms.base import Term

TORQUE = Term(
    name="torque",
    parameters=(Parameter("torque", 0.0, "constant force F (the tilted washboard)"),),
    switch="torque",
)
