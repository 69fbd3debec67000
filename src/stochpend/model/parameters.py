"""Parameters that a noise or an oscillator declares for itself (issue 22, "pieces declare
their parameters").

A :class:`~stochpend.noises.Noise` lists the fields of its kernel record in ``parameters``:
a name of the run's shared settings (``"D"``, ``"tau"``, ``"omega_noise"``, validated by
:class:`stochpend.model.settings.SimulationConfig`) or a :class:`Parameter` of its own, which states its
name, default, accepted range and meaning once. From that one declaration:

* the Python API takes it as a keyword (``simulate(noise="two-ou", tau1=0.5)``) and refuses a
  bad value or an unknown name in one line naming it (:func:`resolve`);
* the command line takes it as ``--param NAME=VALUE`` (``stochpend simulate --noise two-ou
  --param tau1=0.5``), a sweep file as a key like any other, and ``stochpend list`` prints it;
* the configuration stores it (``SimulationConfig.noise_params``), so checkpoints, provenance
  (NetCDF attributes, ``noise_parameters``) and ``show`` carry it;
* the kernels receive it in the noise's record (:meth:`stochpend.noises.Noise.record`).

An oscillator does the same (:attr:`stochpend.oscillators.Oscillator.parameters`, a user
model's ``parameters``): its values are stored in ``SimulationConfig.osc_params`` and reach the
kernels in the oscillator's record (:meth:`stochpend.oscillators.Oscillator.record`); the API,
``--param``, sweep keys, ``list`` and ``show`` take and print them like a noise's. One keyword
space serves both (:func:`split`): a name both the run's noise and its oscillator declare is
refused, and a model whose parameter a registered noise already declares is refused when it is
registered.

The values are floats (the kernels' parameters are real numbers).
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

__all__ = ["Parameter", "resolve", "own", "describe", "split"]

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,31}")
#: Names a noise's own parameter may not take: the shared settings of every run.
RESERVED = frozenset({
    "noise", "D", "tau", "omega", "paths", "t_max", "times", "n_times", "seed", "theta0", "Omega0",
    "xi0", "h_max", "step_c", "hist_bins", "hist_E_max", "n_batches", "potential", "power_n", "n",
    "coupling", "omega_noise", "observables", "noise_params", "extra", "backend", "threads",
    "chunk_paths", "progress", "precision", "max_path_steps", "bias_paths", "accuracy", "rtol",
    "additive_noise",
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


def own(piece: Any) -> tuple[Parameter, ...]:
    """The parameters a noise or oscillator declares for itself (not the run's shared D, tau,
    omega_noise, power_n)."""
    return tuple(p for p in getattr(piece, "parameters", ()) if isinstance(p, Parameter))


def resolve(piece: Any, values: Mapping[str, Any] | Any, kind: str = "noise") -> tuple[tuple[str, float], ...]:
    """Validate ``values`` (name -> value) against ``piece``'s own parameters, fill the
    defaults, and return them as sorted (name, float) pairs, the form a configuration stores.
    A name the piece does not declare is refused in one line that lists those it does.
    ``kind``: "noise" or "potential" (an oscillator), for the messages."""
    declared = {p.name: p for p in own(piece)}
    field_name = "noise_params" if kind == "noise" else "osc_params"
    try:
        values = dict(values or {})  # a mapping, or (name, value) pairs (a checkpoint's JSON)
    except (TypeError, ValueError):
        raise ValueError(f"{field_name}={values!r} is not accepted: a mapping of the {kind}'s own parameters "
                         "to numbers") from None
    for name in values:
        if name not in declared:
            accepted = ", ".join(declared) or "none"
            raise ValueError(f"{name}={values[name]!r} is not accepted: not a parameter of {kind} "
                             f"{getattr(piece, 'name', piece)!r} (its own parameters: {accepted})")
    return tuple(sorted((name, p.check(values.get(name, p.default))) for name, p in declared.items()))


def split(noise: Any, oscillator: Any, values: Mapping[str, Any] | Any) -> tuple[dict[str, Any], dict[str, Any]]:
    """``values`` (name -> value: the keywords of ``simulate``, ``--param``, a sweep set's keys)
    as (the noise's, the oscillator's): a name the oscillator declares goes to it, any other to
    the noise (which refuses a name it does not declare, listing both pieces' parameters). A
    name both declare is refused in one line: the two pieces cannot run together."""
    noise_names = {p.name for p in own(noise)}
    osc_names = {p.name for p in own(oscillator)}
    both = sorted(noise_names & osc_names)
    if both:
        raise ValueError(f"noise={getattr(noise, 'name', noise)!r} with potential="
                         f"{getattr(oscillator, 'name', oscillator)!r} is not accepted: both declare the "
                         f"parameter {both[0]!r} (rename one)")
    try:
        values = dict(values or {})
    except (TypeError, ValueError):
        raise ValueError(f"noise_params={values!r} is not accepted: a mapping of the noise's and the "
                         "oscillator's own parameters to numbers") from None
    for name in values:  # (an oscillator without parameters: the noise's own message)
        if osc_names and name not in noise_names and name not in osc_names:
            raise ValueError(f"{name}={values[name]!r} is not accepted: not a parameter of noise "
                             f"{getattr(noise, 'name', noise)!r} (its own parameters: "
                             f"{', '.join(sorted(noise_names)) or 'none'}) nor of potential "
                             f"{getattr(oscillator, 'name', oscillator)!r} (its own parameters: "
                             f"{', '.join(sorted(osc_names)) or 'none'})")
    return ({k: v for k, v in values.items() if k not in osc_names},
            {k: v for k, v in values.items() if k in osc_names})


def describe(pairs: tuple[tuple[str, float], ...]) -> str:
    """``"tau1=0.5, weight=0.3"``: a configuration's noise parameters in one line."""
    return ", ".join(f"{name}={value:g}" for name, value in pairs)
