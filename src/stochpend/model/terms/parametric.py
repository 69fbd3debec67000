"""A deterministic modulation beside the parametric noise, -eps cos(nu_p t) G(x) in dOmega/dt:
its kick is the exact integral of eps cos(nu_p t) over the step, 2 eps/nu_p cos(nu_p t_mid)
sin(nu_p h/2), without cancellation, times G(x_half) as the noise's; it bounds h <= c/nu_p."""

from __future__ import annotations

from stochpend.model.parameters import Parameter
from stochpend.model.terms.base import Term

PARAMETRIC = Term(
    name="parametric",
    parameters=(
        Parameter("parametric_amplitude", 0.0, "amplitude eps of the modulation eps cos(nu_p t) G(x)"),
        Parameter("parametric_frequency", 1.0, "frequency nu_p of the modulation", low=0.0, low_open=True),
    ),
    switch="parametric_amplitude",
    rate="parametric_frequency",
    coupling="noise",
)
