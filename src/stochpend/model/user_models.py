"""Oscillators a user defines in Python, run by the same kernels as the built-in ones.

A model is four plain scalar functions of the coordinate x (floats in, a float out), of the
kind the built-in oscillators define (:mod:`stochpend.oscillators`):

* ``potential(x)``: U(x); the energy is E = Omega**2/2 + omega**2 U(x);
* ``force(x)``: U'(x); the deterministic force is -omega**2 U'(x);
* ``curvature(x)``: |U''(x)| (or a bound on it), used only by the step control
  h <= c / sqrt(|omega**2 + xi| |U''(x)|); default 1;
* ``noise_shape(x)``: G(x), what the noise multiplies in dOmega/dt = -omega**2 U' - xi G;
  default U'(x) (the pendulum's placement). With ``coupling="position"`` G = x regardless.

A model may declare parameters of its own (``parameters``: a tuple of
:class:`stochpend.model.parameters.Parameter`); its functions then take them after x, in declared
order: ``potential(x, a)``, ``force(x, a)``, ... (a model without parameters keeps
``potential(x)``). Their values are given like a noise's own parameters:
``simulate(potential="tilted", a=0.2)``, ``--param a=0.2``, a sweep file's key; the
configuration stores them in ``osc_params`` and the kernels receive them in the oscillator's
record (:meth:`stochpend.oscillators.Oscillator.record`).

They must be compilable by Numba in nopython mode (``math`` functions, arithmetic,
conditionals; no Python objects), which also makes them CUDA device functions.

How it works, and why it is the same code: a model is an oscillator like the built-in ones
(:class:`stochpend.oscillators.Oscillator`, :attr:`Model.oscillator`): its functions are
wrapped as ``register_jitable`` device functions, and the integrator
(:mod:`stochpend.engine.integrator`) compiles its one step loop for (this oscillator, the noise, the
precision), on the CPU and on CUDA. The noise updates, the random streams, the step control,
the statistics and the outputs are therefore those of the built-in models. In float32 kernels
the user's functions compute in float64 (a Python float literal is float64 in Numba) and their
results are rounded to float32. These kernels are compiled in memory (not cached on disk):
the first run of a model in a process pays the compilation.

Example (docs/models.md)::

    import math
    import stochpend
    from stochpend.models import Model, register

    register(Model(
        name="double-well",
        potential=lambda x: 0.25 * x**4 - 0.5 * x**2,
        force=lambda x: x**3 - x,
        curvature=lambda x: abs(3.0 * x * x - 1.0),
    ))
    ds = stochpend.simulate(potential="double-well", noise="ou", D=0.5, tau=1.0, paths=10_000)
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from stochpend.model.oscillators.base import Oscillator, OscillatorKernel
from stochpend.model.parameters import Parameter
from stochpend.numerics._jitable import register_jitable

__all__ = ["Model", "get", "names", "register", "unregister"]

#: The built-in potentials' names (a model may not take one).
BUILTIN = ("pendulum", "harmonic", "power")

_REGISTRY: dict[str, Model] = {}


def _one(x: float, *parameters: float) -> float:
    return 1.0


@dataclass(frozen=True)
class Model:
    """A user-defined oscillator (see the module docstring for the meaning of each function).

    ``periodic``: x is an angle, reduced to [-pi, pi) after each step (like the pendulum's).
    ``E_min``: the lowest energy per omega**2 (min of U), for the histogram's lower edge;
    default: the minimum of U on [-10, 10] (or [-pi, pi] when periodic), at the parameters'
    values. ``parameters``: the model's own parameters (:class:`stochpend.model.parameters.Parameter`),
    passed to each function after x in this order.
    """

    name: str
    potential: Callable[[float], float]
    force: Callable[[float], float]
    curvature: Callable[[float], float] = _one
    noise_shape: Callable[[float], float] | None = None
    periodic: bool = False
    E_min: float | None = None
    description: str = ""
    parameters: tuple[Parameter, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name in BUILTIN:
            raise ValueError(f"name={self.name!r} is not accepted: a non-empty name other than "
                             f"the built-in {', '.join(BUILTIN)}")
        for attr in ("potential", "force", "curvature"):
            if not callable(getattr(self, attr)):
                raise ValueError(f"{attr}={getattr(self, attr)!r} is not accepted: a function of x")
        if self.noise_shape is not None and not callable(self.noise_shape):
            raise ValueError(f"noise_shape={self.noise_shape!r} is not accepted: a function of x or None")
        parameters = tuple(self.parameters) if isinstance(self.parameters, (tuple, list)) else None
        if parameters is None or not all(isinstance(p, Parameter) for p in parameters):
            raise ValueError(f"parameters={self.parameters!r} is not accepted: a tuple of "
                             "stochpend.model.parameters.Parameter")
        names = [p.name for p in parameters]
        if len(set(names)) != len(names):
            raise ValueError(f"parameters={self.parameters!r} is not accepted: a name is repeated")
        object.__setattr__(self, "parameters", parameters)
        # Evaluate once in Python: a function that fails here would fail inside a kernel.
        defaults = self.defaults
        where = "x=0.5" + "".join(f", {p.name}={p.default:g}" for p in parameters)
        for attr in ("potential", "force", "curvature", "noise_shape"):
            f = getattr(self, attr)
            if f is None:
                continue
            try:
                value = float(f(0.5, *defaults))
            except Exception as error:
                raise ValueError(f"{attr} is not accepted: calling it with {where} raised "
                                 f"{type(error).__name__}: {error}") from None
            if not math.isfinite(value):
                raise ValueError(f"{attr} is not accepted: it returned {value} at {where}")

    # -- plain Python views (validation, histogram edges) ----------------------------------
    @property
    def defaults(self) -> tuple[float, ...]:
        """The parameters' defaults, in declared order."""
        return tuple(float(p.default) for p in self.parameters)

    def G(self, x: float, coupling: str, values: tuple[float, ...] | None = None) -> float:
        if coupling == "position":
            return x
        values = self.defaults if values is None else tuple(values)
        return float((self.noise_shape or self.force)(x, *values))

    def energy_floor(self, values: tuple[float, ...] | None = None) -> float:
        """min U (per omega**2) at the parameters' ``values`` (default: their defaults), for
        the histogram's lower edge."""
        if self.E_min is not None:
            return float(self.E_min)
        values = self.defaults if values is None else tuple(values)
        span = math.pi if self.periodic else 10.0
        grid = np.linspace(-span, span, 20001)
        return float(min(self.potential(float(x), *values) for x in grid))

    def source(self) -> str:
        """The functions' source, for provenance (empty where Python cannot find it)."""
        parts = []
        for attr in ("potential", "force", "curvature", "noise_shape"):
            f = getattr(self, attr)
            if f is None or f is _one:
                continue
            try:
                parts.append(inspect.getsource(f).strip())
            except Exception:  # noqa: BLE001 - provenance never stops a run
                # OSError/TypeError: no file; tokenize/Syntax errors: code compiled under a file
                # name whose lines are other text (exec of a docs block, a notebook cell).
                parts.append(f"{attr}: source unavailable")
        return "\n".join(parts)

    @functools.cached_property
    def oscillator(self) -> Oscillator:
        """This model as an :class:`~stochpend.oscillators.Oscillator` (what kernels run)."""
        k = len(self.parameters)
        return Oscillator(name=self.name, build=functools.partial(_build, self),
                          description=self.description or "user-defined model",
                          periodic=bool(self.periodic), parameters=self.parameters,
                          energy_floor=lambda q: self.energy_floor(tuple(q[:k])))


@register_jitable
def _unit_curvature(x, q):
    return 1.0


def _with_record(f: Callable, k: int) -> Callable:
    """``f(x, a, b, ...)`` as a device function of (x, q): the record's k entries passed after
    x in order (``f(x)`` for k = 0; the record is then ``(0.0,)``, unused)."""
    if f is _one:
        return _unit_curvature
    g = register_jitable(f)
    args = "".join(f", q[{i}]" for i in range(k))
    namespace: dict = {"g": g}
    exec(f"def call(x, q):\n    return g(x{args})\n", namespace)
    call = namespace["call"]
    call.__qualname__ = f"_with_record.<locals>.call{k}"
    return register_jitable(call)


def _build(model: Model, real, mathlib) -> OscillatorKernel:
    """The model's device functions: the user's functions, with the model's parameters from
    the record q after x, results rounded to ``real``."""
    k = len(model.parameters)
    U = _with_record(model.potential, k)
    dU = _with_record(model.force, k)
    d2U = _with_record(model.curvature, k)
    G = _with_record(model.noise_shape, k) if model.noise_shape is not None else dU
    periodic = bool(model.periodic)
    pi = real(math.pi)
    two_pi = real(2.0 * math.pi)

    @register_jitable
    def potential(x, q):
        return real(U(x, q))

    @register_jitable
    def force(x, q):
        return real(dU(x, q))

    @register_jitable
    def noise_shape(x, q):
        return real(G(x, q))

    @register_jitable
    def step_scales(x, Omega, omega2, q):
        return abs(Omega), real(abs(d2U(x, q)))

    @register_jitable
    def wrap(x):
        if periodic:
            return x - two_pi * real(math.floor((x + pi) / two_pi))
        return x

    return OscillatorKernel(potential, force, noise_shape, step_scales, wrap)


def register(model: Model) -> Model:
    """Make ``model`` available as ``potential=model.name`` everywhere (replaces one of the
    same name). Returns it."""
    if not isinstance(model, Model):
        raise ValueError(f"model={model!r} is not accepted: a stochpend.models.Model")
    from stochpend.model import noises
    from stochpend.model.parameters import own

    mine = {p.name for p in model.parameters}
    for name in noises.names():  # one keyword space: a name a noise already declares is refused
        clash = sorted(mine & {p.name for p in own(noises.get(name))})
        if clash:
            raise ValueError(f"model={model.name!r} is not accepted: its parameter {clash[0]!r} is also "
                             f"a parameter of noise {name!r} (rename it)")
    _REGISTRY[model.name] = model
    return model


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def get(name: str) -> Model | None:
    return _REGISTRY.get(name)
