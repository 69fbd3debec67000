"""Parameters that a noise declares for itself (issue 22, "pieces declare their parameters").

A :class:`~stochpend.noises.Noise` lists the fields of its kernel record in ``parameters``:
a name of the run's shared settings (``"D"``, ``"tau"``, ``"omega_noise"``, validated by
:class:`stochpend.params.SimulationConfig`) or a :class:`Parameter` of its own, which states its
name, default, accepted range and meaning once. From that one declaration:

* the Python API takes it as a keyword (``simulate(noise="two-ou", tau1=0.5)``) and refuses a
  bad value or an unknown name in one line naming it (:func:`resolve`);
* the command line takes it as ``--param NAME=VALUE`` (``stochpend simulate --noise two-ou
  --param tau1=0.5``), a sweep file as a key like any other, and ``stochpend list`` prints it;
* the configuration stores it (``SimulationConfig.noise_params``), so checkpoints, provenance
  (NetCDF attributes, ``noise_parameters``) and ``show`` carry it;
* the kernels receive it in the noise's record (:meth:`stochpend.noises.Noise.record`).

The values are floats (the kernels' parameters are real numbers).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["Parameter", "resolve", "own", "describe"]

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
#: Names a noise's own parameter may not take: the shared settings of every run.
RESERVED = frozenset({
    "noise", "D", "tau", "omega", "paths", "t_max", "times", "n_times", "seed", "theta0", "Omega0",
    "xi0", "h_max", "step_c", "hist_bins", "hist_E_max", "n_batches", "potential", "power_n", "n",
    "coupling", "omega_noise", "observables", "noise_params", "extra", "backend", "threads",
    "chunk_paths", "progress", "precision", "max_path_steps", "bias_paths", "accuracy", "rtol",
})


@dataclass(frozen=True)
class Parameter:
    """A real parameter of a noise: ``name`` (a Python identifier, also the command line's
    ``--param name=...`` and a sweep file's key), ``default``, ``meaning`` (one line, for help
    and errors), and the accepted range ``[low, high]`` (``low_open``/``high_open``: the end
    itself is not accepted)."""

    name: str
    default: float
    meaning: str
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False
    high_open: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name) or self.name in RESERVED:
            raise ValueError(f"Parameter name {self.name!r} is not accepted: an identifier (letters, digits, _) "
                             "that is not one of the run's own settings")
        self.check(self.default)  # a declaration whose default it refuses is a bug of the piece

    def accepted(self) -> str:
        """What the parameter accepts, in words: 'a finite number in (0, inf)'."""
        left = "(" if self.low_open or self.low == -math.inf else "["
        right = ")" if self.high_open or self.high == math.inf else "]"
        return f"a finite number in {left}{self.low:g}, {self.high:g}{right} ({self.meaning})"

    def check(self, value: Any) -> float:
        """``value`` as a float, or a one-line ValueError naming the parameter."""
        try:
            if isinstance(value, bool) or isinstance(value, complex):
                raise TypeError
            v = float(value)
        except (TypeError, ValueError, OverflowError):
            raise ValueError(f"{self.name}={value!r} is not accepted: {self.accepted()}") from None
        below = v <= self.low if self.low_open else v < self.low
        above = v >= self.high if self.high_open else v > self.high
        if not math.isfinite(v) or below or above:
            raise ValueError(f"{self.name}={value!r} is not accepted: {self.accepted()}")
        return v


def own(noise: Any) -> tuple[Parameter, ...]:
    """The parameters a noise declares for itself (not the run's shared D, tau, omega_noise)."""
    return tuple(p for p in getattr(noise, "parameters", ()) if isinstance(p, Parameter))


def resolve(noise: Any, values: Mapping[str, Any] | Any) -> tuple[tuple[str, float], ...]:
    """Validate ``values`` (name -> value) against ``noise``'s own parameters, fill the
    defaults, and return them as sorted (name, float) pairs, the form a configuration stores.
    A name the noise does not declare is refused in one line that lists those it does."""
    declared = {p.name: p for p in own(noise)}
    try:
        values = dict(values or {})  # a mapping, or (name, value) pairs (a checkpoint's JSON)
    except (TypeError, ValueError):
        raise ValueError(f"noise_params={values!r} is not accepted: a mapping of the noise's own parameters "
                         "to numbers") from None
    for name in values:
        if name not in declared:
            accepted = ", ".join(declared) or "none"
            raise ValueError(f"{name}={values[name]!r} is not accepted: not a parameter of noise "
                             f"{getattr(noise, 'name', noise)!r} (its own parameters: {accepted})")
    return tuple(sorted((name, p.check(values.get(name, p.default))) for name, p in declared.items()))


def describe(pairs: tuple[tuple[str, float], ...]) -> str:
    """``"tau1=0.5, weight=0.3"``: a configuration's noise parameters in one line."""
    return ", ".join(f"{name}={value:g}" for name, value in pairs)
