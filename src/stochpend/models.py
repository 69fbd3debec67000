"""Oscillators a user defines in Python, run by the same kernels as the built-in ones.

A model is four plain scalar functions of the coordinate x (floats in, a float out), of the
kind the built-in oscillators define (:mod:`stochpend.oscillators`):

* ``potential(x)``: U(x); the energy is E = Omega**2/2 + omega**2 U(x);
* ``force(x)``: U'(x); the deterministic force is -omega**2 U'(x);
* ``curvature(x)``: |U''(x)| (or a bound on it), used only by the step control
  h <= c / sqrt(|omega**2 + xi| |U''(x)|); default 1;
* ``noise_shape(x)``: G(x), what the noise multiplies in dOmega/dt = -omega**2 U' - xi G;
  default U'(x) (the pendulum's placement). With ``coupling="position"`` G = x regardless.

They must be compilable by Numba in nopython mode (``math`` functions, arithmetic,
conditionals; no Python objects), which also makes them CUDA device functions.

How it works, and why it is the same code: a model is an oscillator like the built-in ones
(:class:`stochpend.oscillators.Oscillator`, :attr:`Model.oscillator`): its functions are
wrapped as ``register_jitable`` device functions, and the integrator
(:mod:`stochpend.integrator`) compiles its one step loop for (this oscillator, the noise, the
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
from numba.extending import register_jitable

from stochpend.oscillators.base import Oscillator, OscillatorKernel

__all__ = ["Model", "get", "names", "register", "unregister"]

#: The built-in potentials' names (a model may not take one).
BUILTIN = ("pendulum", "harmonic", "power")

_REGISTRY: dict[str, Model] = {}


def _one(x: float) -> float:
    return 1.0


@dataclass(frozen=True)
class Model:
    """A user-defined oscillator (see the module docstring for the meaning of each function).

    ``periodic``: x is an angle, reduced to [-pi, pi) after each step (like the pendulum's).
    ``E_min``: the lowest energy per omega**2 (min of U), for the histogram's lower edge;
    default: the minimum of U on [-10, 10] (or [-pi, pi] when periodic).
    """

    name: str
    potential: Callable[[float], float]
    force: Callable[[float], float]
    curvature: Callable[[float], float] = _one
    noise_shape: Callable[[float], float] | None = None
    periodic: bool = False
    E_min: float | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name in BUILTIN:
            raise ValueError(f"name={self.name!r} is not accepted: a non-empty name other than "
                             f"the built-in {', '.join(BUILTIN)}")
        for attr in ("potential", "force", "curvature"):
            if not callable(getattr(self, attr)):
                raise ValueError(f"{attr}={getattr(self, attr)!r} is not accepted: a function of x")
        if self.noise_shape is not None and not callable(self.noise_shape):
            raise ValueError(f"noise_shape={self.noise_shape!r} is not accepted: a function of x or None")
        # Evaluate once in Python: a function that fails here would fail inside a kernel.
        for attr in ("potential", "force", "curvature", "noise_shape"):
            f = getattr(self, attr)
            if f is None:
                continue
            try:
                value = float(f(0.5))
            except Exception as error:
                raise ValueError(f"{attr} is not accepted: calling it with x=0.5 raised "
                                 f"{type(error).__name__}: {error}") from None
            if not math.isfinite(value):
                raise ValueError(f"{attr} is not accepted: it returned {value} at x=0.5")

    # -- plain Python views (validation, histogram edges) ----------------------------------
    def G(self, x: float, coupling: str) -> float:
        if coupling == "position":
            return x
        return float((self.noise_shape or self.force)(x))

    def energy_floor(self) -> float:
        """min U (per omega**2), for the histogram's lower edge."""
        if self.E_min is not None:
            return float(self.E_min)
        span = math.pi if self.periodic else 10.0
        grid = np.linspace(-span, span, 20001)
        return float(min(self.potential(float(x)) for x in grid))

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
        return Oscillator(name=self.name, build=functools.partial(_build, self),
                          description=self.description or "user-defined model",
                          periodic=bool(self.periodic), energy_floor=lambda n: self.energy_floor())


def _build(model: Model, real, mathlib) -> OscillatorKernel:
    """The model's device functions: the user's functions, results rounded to ``real``."""
    U = register_jitable(model.potential)
    dU = register_jitable(model.force)
    d2U = register_jitable(model.curvature)
    G = register_jitable(model.noise_shape) if model.noise_shape is not None else dU
    periodic = bool(model.periodic)
    pi = real(math.pi)
    two_pi = real(2.0 * math.pi)

    @register_jitable
    def potential(x, n):
        return real(U(x))

    @register_jitable
    def force(x, n):
        return real(dU(x))

    @register_jitable
    def noise_shape(x, n):
        return real(G(x))

    @register_jitable
    def step_scales(x, Omega, omega2, n):
        return abs(Omega), real(abs(d2U(x)))

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
    _REGISTRY[model.name] = model
    return model


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def get(name: str) -> Model | None:
    return _REGISTRY.get(name)
