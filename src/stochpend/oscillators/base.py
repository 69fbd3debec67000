"""What an oscillator is to the integrator.

The oscillator is

    dx/dt = Omega,    dOmega/dt = -omega**2 U'(x) - xi(t) G(x)

(the paper's pendulum: x = theta, U = -cos, G = U' = sin; Eqs. `dynOmega`, `dyntheta`) with
energy E = Omega**2/2 + omega**2 U(x) (Eq. `defenergie`). The noise multiplies the force
(``coupling="force"``, G = the oscillator's ``noise_shape``, U' unless it says otherwise) or
the position (``coupling="position"``, G = x: the random-frequency oscillator). The coupling
is chosen when a kernel is compiled (``integrator.Spec``).

Because the noise multiplies a function of x alone and enters only the Omega equation, the Ito
and Stratonovich readings of the white-noise system coincide.

An :class:`Oscillator` builds, for one precision and math library, an
:class:`OscillatorKernel` of ``register_jitable`` functions of (x, n), n the integer
parameter of the family (the power of x**(2n); ignored by the others):

* ``potential(x, n)``: U(x); ``force(x, n)``: U'(x); ``noise_shape(x, n)``: G(x) for the force
  coupling;
* ``step_scales(x, Omega, omega2, n) -> (speed, curvature)``: what the step control resolves
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

from stochpend.mathlib import LIBM

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
    min U, for the histogram's lower edge (a function of n). ``builtin``: kernels may be cached
    on disk. ``float64_only``: the user functions are plain Python floats (they compute in
    float64 whatever the kernel's precision; their results are rounded to it).
    """

    name: str
    build: Callable[[Any, Any], OscillatorKernel]
    description: str
    periodic: bool = False
    energy_floor: Callable[[int], float] = lambda n: 0.0
    builtin: bool = False

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
    from stochpend._jitcache import name_closures
    from stochpend.mathlib import FAST

    kernel = oscillator.build(real, FAST if mathlib_name == FAST.name else LIBM)
    name_closures(vars(kernel).values(), f"oscillator/{oscillator.name}/{np.dtype(real).name}/{mathlib_name}")
    return kernel
