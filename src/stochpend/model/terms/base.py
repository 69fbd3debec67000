"""What one of the family's terms declares: :class:`Term`."""

from __future__ import annotations

from dataclasses import dataclass

from stochpend.model.parameters import Parameter

#: How a term enters the step (:func:`stochpend.engine.integrator.build`): ``"force"`` a force f(t) in
#: dOmega/dt (the kick takes its exact integral over the step off), ``"noise"`` beside the
#: parametric noise, -f(t) G(x) (the kick adds its integral times G(x_half), as the noise's),
#: ``"flow"`` part of the exact Ornstein-Uhlenbeck flow of Omega (the damping).
COUPLINGS = ("force", "noise", "flow")


@dataclass(frozen=True)
class Term:
    """One entry of the family's table (:data:`stochpend.terms.TABLE`), as a statistic is one of
    ``observables.SUMS``: its parameters, how it enters the step and its step bound.

    ``switch``: the parameter that turns the term on (nonzero: on; zero: not compiled).
    ``rate``: the parameter whose value r bounds the adaptive step, h <= c/r (None: no bound).
    ``coupling``: one of :data:`COUPLINGS`.
    """

    name: str
    parameters: tuple[Parameter, ...]
    switch: str
    rate: str | None = None
    coupling: str = "force"

    def __post_init__(self) -> None:
        names = {p.name for p in self.parameters}
        if self.switch not in names or (self.rate is not None and self.rate not in names):
            raise ValueError(f"term {self.name!r}: switch={self.switch!r} and rate={self.rate!r} must be "
                             f"among its parameters {sorted(names)}")
        if self.coupling not in COUPLINGS:
            raise ValueError(f"term {self.name!r}: coupling={self.coupling!r}, one of {', '.join(COUPLINGS)}")

    @property
    def moves_rest(self) -> bool:
        """Whether the term pushes a path at rest: a force (a term beside the noise vanishes where
        G does, and the damping where Omega does)."""
        return self.coupling == "force"
