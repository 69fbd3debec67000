"""An external force A cos(nu t + phi) in dOmega/dt: its kick is the exact integral over the
step, 2 A/nu cos(nu t_mid + phi) sin(nu h/2), without cancellation; it bounds h <= c/nu."""

from __future__ import annotations

from stochpend.model.parameters import Parameter
from stochpend.model.terms.base import Term

DRIVE = Term(
    name="drive",
    parameters=(
        Parameter("drive_amplitude", 0.0, "amplitude A of the external force A cos(nu t + phi)"),
        Parameter("drive_frequency", 1.0, "frequency nu of the external force", low=0.0, low_open=True),
        Parameter("drive_phase", 0.0, "phase phi of the external force"),
    ),
    switch="drive_amplitude",
    rate="drive_frequency",
)
