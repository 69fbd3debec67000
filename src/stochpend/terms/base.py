"""What one of the family's terms declares: :class:`Term`."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from stochpend.parameters import Parameter

#: Where a term's kick enters the step's kick (``Omega_new = Omega - kick``): ``"force"`` a force
#: f(t) in dOmega/dt (the kick takes its integral over the step off), ``"noise"`` beside the
#: parametric noise, -f(t) G(x) (the kick adds its integral times G(x_half), as the noise's).
COUPLINGS = ("force", "noise")


@dataclass(frozen=True)
class Term:
    """One entry of the family's table (:data:`stochpend.terms.TABLE`), as a statistic is one of
    ``observables.SUMS``: its parameters, its kick and its step bound.

    ``switch``: the parameter that turns the term on (nonzero: on; zero: not compiled).
    ``rate``: the parameter whose value r bounds the adaptive step, h <= c/r (None: no bound).
    ``kick(real, mathlib, at)``: the kernel's function ``f(x_half, t0, h_clock, d)``, the exact
    integral of the term's ``integrand`` over ``[t0, t0 + h_clock]`` in the precision ``real``
    (``d`` the family's record, ``at[name]`` a parameter's position in it); None for a term of
    the Ornstein-Uhlenbeck flow (the damping), which the step writes itself.
    ``integrand(t, values)``: the same function of time on the host (``values`` by parameter
    name), what the kick integrates (tests/unit/test_terms.py checks one against the other).
    """

    name: str
    parameters: tuple[Parameter, ...]
    switch: str
    rate: str | None = None
    coupling: str = "force"
    kick: Callable[[Any, Any, Mapping[str, int]], Callable[..., Any]] | None = None
    integrand: Callable[[float, Mapping[str, float]], float] | None = None

    def __post_init__(self) -> None:
        names = {p.name for p in self.parameters}
        if self.switch not in names or (self.rate is not None and self.rate not in names):
            raise ValueError(f"term {self.name!r}: switch={self.switch!r} and rate={self.rate!r} must be "
                             f"among its parameters {sorted(names)}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"term {self.name!r}: coupling={self.coupling!r}, one of {', '.join(COUPLINGS)}")
        if (self.kick is None) != (self.integrand is None):
            raise ValueError(f"term {self.name!r}: a kick and its integrand go together")

    @property
    def moves_rest(self) -> bool:
        """Whether the term pushes a path at rest: a force (a term beside the noise vanishes where
        G does, and the damping where Omega does)."""
        return self.kick is not None and self.coupling == "force"


def cosine_kick(real: Any, mathlib: Any, amplitude: int, frequency: int, phase: int | None = None) -> Any:
    """The kick of a term A cos(nu t + phi) (record positions ``amplitude``, ``frequency``,
    ``phase``; None: no phase, not even + 0): its exact integral over [t0, t0 + h], 2 A/nu
    cos(nu t_mid + phi) sin(nu h/2), without cancellation."""
    sincos = mathlib.sincos
    PHASED = phase is not None
    PHI = phase if phase is not None else 0

    def kick(x_half, t0, h_clock, d):
        nu = d[frequency]
        s_half, _ = sincos(0.5 * nu * h_clock)
        arg = nu * (t0 + 0.5 * h_clock)
        if PHASED:
            arg = arg + d[PHI]
        _, c_mid = sincos(arg)
        return real(2.0 * d[amplitude] / nu * c_mid * s_half)

    return kick
