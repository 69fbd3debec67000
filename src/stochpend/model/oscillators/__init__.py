"""The oscillators, one file each, and where ``potential=`` names are looked up.

Built in: ``pendulum`` (:mod:`.pendulum`), ``harmonic`` (:mod:`.harmonic`) and ``power``
(:mod:`.power`, U = x**(2n)/(2n)). A user's oscillator is a :class:`stochpend.models.Model`,
registered with :func:`stochpend.models.register`; :func:`get` finds both.
"""

from __future__ import annotations

from stochpend.model.oscillators.base import Oscillator, OscillatorKernel
from stochpend.model.oscillators.harmonic import HARMONIC
from stochpend.model.oscillators.pendulum import PENDULUM
from stochpend.model.oscillators.power import POWER

__all__ = ["BUILTIN", "COUPLINGS", "Oscillator", "OscillatorKernel", "get", "names"]

BUILTIN = {osc.name: osc for osc in (PENDULUM, HARMONIC, POWER)}

#: Where the noise acts: on the force (G = the oscillator's noise_shape) or on x (G = x).
COUPLINGS = ("force", "position")


def names() -> tuple[str, ...]:
    return tuple(BUILTIN)


def get(name: str) -> Oscillator | None:
    """The built-in oscillator, or the registered user model, called ``name``."""
    if not isinstance(name, str):
        return None
    if name in BUILTIN:
        return BUILTIN[name]
    from stochpend.model import user_models as models

    model = models.get(name)
    return None if model is None else model.oscillator
