"""What an oscillator is to the integrator.

The oscillator is

    dx/dt = Omega,    dOmega/dt = -omega**2 U'(x) - xi(t) G(x)

(the paper's pendulum: x = theta, U = -cos, G = U' = sin; Eqs. `dynOmega`, `dyntheta`) with
energy E = Omega**2/2 + omega**2 U(x) (Eq. `defenergie`). The noise multiplies the force
(``coupling="force"``, G = the oscillator's ``noise_shape``, U' unless it says otherwise) or
the position (``coupling="position"``, G = x: the random-frequency oscillator). The coupling
is chosen when a kernel is compiled (``integrator.KernelSpec``).

Because the noise multiplies a function of x alone and enters only the Omega equation, the Ito
and Stratonovich readings of the white-noise system coincide.

An :class:`Oscillator` builds, for one precision and math library, an
:class:`OscillatorKernel` of ``register_jitable`` functions of (x, q), q the oscillator's
parameter **record** (:meth:`Oscillator.record`): a tuple of float64, one entry per entry of
:attr:`Oscillator.parameters`, in that order (``(0.0,)`` for an oscillator without parameters,
so that a record is never an empty tuple). The power family reads its integer n back as
``int(q[0])``, so that ``x ** (2 * n)`` stays an integer power (bit for bit what it was):

* ``potential(x, q)``: U(x); ``force(x, q)``: U'(x); ``noise_shape(x, q)``: G(x) for the force
  coupling;
* ``step_scales(x, Omega, omega2, q) -> (speed, curvature)``: what the step control resolves
  (docs/numerics.md): a speed v (x moves by at most c per step) and |U''| (c radians of the
  local oscillation per step);
* ``wrap(x)``: an angle reduced to [-pi, pi) (periodic oscillators); else x.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from stochpend.numerics.mathlib import LIBM

__all__ = ["Oscillator", "OscillatorKernel"]


@dataclass(frozen=True)
class OscillatorKernel:
    potential: Callable
    force: Callable
    noise_shape: Callable
    step_scales: Callable
    wrap: Callable


@dataclass(frozen=True, eq=False)
class Oscillator:
    """An oscillator the simulator can run (built-in, or a user's ``stochpend.models.Model``).

    ``periodic``: x is an angle (then the noise can only multiply the force). ``energy_floor``:
    min U, for the histogram's lower edge (a function of the record q). ``builtin``: kernels may
    be cached on disk.

    ``parameters``: the fields, in order, of the oscillator's kernel record ``q``
    (:meth:`record`): the name of one of the run's shared settings (``"power_n"``) or a
    :class:`stochpend.model.parameters.Parameter` the oscillator declares for itself (a user model's
    ``parameters``), whose value the run's configuration holds in ``osc_params``.
    """

    name: str
    build: Callable[[Any, Any], OscillatorKernel]
    description: str
    periodic: bool = False
    energy_floor: Callable[[tuple[float, ...]], float] = lambda q: 0.0
    builtin: bool = False
    parameters: tuple[Any, ...] = ()

    def record(self, config: Any) -> tuple[float, ...]:
        """The kernel record of this oscillator for a run of ``config`` (a SimulationConfig, or
        anything with its fields): for each entry of :attr:`parameters`, ``getattr(config,
        name)`` when the config has that field, else the value in ``config.osc_params`` (sorted
        (name, value) pairs). Floats, except that an integer setting stays an integer (the power
        family's ``power_n``: ``x ** (2 * n)`` is then an integer power with no conversion in the
        kernel, as before records); ``(0.0,)`` when there are no parameters."""
        own = dict(getattr(config, "osc_params", ()) or ())
        values = []
        for entry in self.parameters:
            name = getattr(entry, "name", entry)  # a Parameter of its own, or a config field
            if hasattr(config, name):
                value = getattr(config, name)
            elif name in own:
                value = own[name]
            else:
                raise ValueError(f"potential={self.name!r} needs the parameter {name!r}: give it in "
                                 "osc_params")
            values.append(value if isinstance(value, int) and not isinstance(value, bool) else float(value))
        return tuple(values) or (0.0,)

    def kernel(self, real: Any, mathlib: Any) -> OscillatorKernel:
        return _kernel(self, real, mathlib.name)

    @property
    def functions(self) -> OscillatorKernel:
        """The float64, C-library functions, callable from Python (validation, tests)."""
        return self.kernel(np.float64, LIBM)


@functools.cache
def _kernel(oscillator: Oscillator, real: Any, mathlib_name: str) -> OscillatorKernel:
    """Built once per (oscillator, precision, math library); the cache holds the oscillator
    itself, so a key never outlives its object (an ``id`` could be reused by another model)."""
    from stochpend.numerics._jitcache import name_closures
    from stochpend.numerics.mathlib import FAST

    kernel = oscillator.build(real, FAST if mathlib_name == FAST.name else LIBM)
    name_closures(vars(kernel).values(), f"oscillator/{oscillator.name}/{np.dtype(real).name}/{mathlib_name}")
    return kernel
