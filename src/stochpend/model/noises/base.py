"""What a noise is to the integrator: its state, start, exact step and spectral facts.

A noise xi(t) enters the oscillator only through its integral over a step,
I = int_t^{t+h} xi(s) ds, which the kick of the drift-kick-drift step uses (docs/numerics.md).
A :class:`Noise` says

* its **state**: ``xi`` and one auxiliary number ``aux`` per path (OU: unused; harmonic
  noise: dxi/dt; dichotomous: the time of the next flip);
* how it **starts**: ``init``, the stationary law from Philox draw ``rng.N_INIT_XI`` (or a
  given xi0);
* its **exact step**: the joint update of (xi, aux) and the integral I over a step h, from
  coefficients that depend on h only (``coefficients``, cached by the integrator while h does
  not change) and the random numbers of the step (``draw``);
* optional **events**: times at which the noise jumps (the dichotomous flips); the
  integrator cuts a step at the next event and calls ``at_event`` there;
* its **spectral facts** (plain Python): stationary variance, correlation C(t), spectral
  density S(nu), in the conventions of docs/models.md (S(0) = D for every built-in noise).

The device functions are built by ``build(real, mathlib)`` for one precision (``numpy.float64``
or ``numpy.float32``) and one :class:`stochpend.numerics.mathlib.MathLib`; they are ``register_jitable``
closures over constants of that precision, so the same definition compiles into CPU and CUDA
kernels in float64 or float32 with no rewriting. They return a :class:`NoiseKernel`.

Parameters reach the device functions as one **record** ``p``: a tuple of float64, one entry per
name of :attr:`Noise.parameters`, in that order (built by :meth:`Noise.record` from the run's
configuration). Each device function unpacks what it uses (``D = p[0]``); ``coefficients`` and
``at_event`` convert to ``real`` themselves (``real(p[0])``), ``init`` computes in float64.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from stochpend.numerics._jitable import register_jitable

__all__ = ["Noise", "NoiseKernel", "no_event", "at_no_event", "no_scratch"]


# -- defaults for a noise without events or loop-carried draws ----------------------------------
@register_jitable
def no_event(xi, aux):
    """``next_event`` of a noise that never jumps."""
    return math.inf


@register_jitable
def at_no_event(xi, aux, key0, key1, path, k, p):
    """``at_event`` of a noise that never jumps (never called)."""
    return xi, aux


@register_jitable
def no_scratch():
    """``scratch0`` of a noise whose draws carry nothing from one step to the next."""
    return 0


@dataclass(frozen=True)
class NoiseKernel:
    """The device functions of a noise for one precision (all ``register_jitable``).

    ``p`` is the noise's parameter record (:meth:`Noise.record`: a tuple of float64, in the
    order of :attr:`Noise.parameters`).

    * ``init(key0, key1, path, p, xi0, stationary) -> (xi, aux)``, in float64;
    * ``load_aux(a) -> aux``: the in-register aux from its float64 storage (a time stays
      float64; a noise variable becomes ``real``);
    * ``coefficients(h, p) -> C``: everything of the step that depends on h only (``h`` in
      ``real``; the parameters converted to ``real`` here);
    * ``scratch0() -> S``: the per-path loop-carried draw cache at the start of a call;
    * ``draw(key0, key1, path, k, S) -> (z, S)``: the random numbers of step k (a tuple of
      ``real``), keyed by (seed, path, k) only;
    * ``update(xi, aux, C, z) -> (I, xi, aux)``: the exact step;
    * ``next_event(xi, aux) -> t`` (float64; ``inf`` for none) and
      ``at_event(xi, aux, key0, key1, path, k, p) -> (xi, aux)``;
    * optionally ``draw_keyed(rk0, rk1, c2, c3, k) -> z``: ``draw``'s numbers for step k, bit for
      bit, from the seed's Philox round keys (``rng.round_keys``) and the path's counter words,
      with no loop-carried scratch and no branch, so that a loop over lanes, each at its own
      step k, vectorizes (the CPU's SIMD lane driver, ``integrator.build_lanes``). ``None``:
      the noise runs one path at a time. With it, ``coefficients`` must be branch-free too.
    """

    init: Callable
    load_aux: Callable
    coefficients: Callable
    scratch0: Callable
    draw: Callable
    update: Callable
    next_event: Callable
    at_event: Callable
    draw_keyed: Callable | None = None


@dataclass(frozen=True, eq=False)
class Noise:
    """A noise the simulator can run (built-in or a user's: see :func:`stochpend.noises.register`).

    ``name``: what ``noise=`` takes. ``colored``: needs ``tau`` > 0. ``uses_omega_noise``: takes
    ``omega_noise`` (W; ``default_omega_noise(tau)`` when not given). ``has_events``: the
    integrator cuts steps at ``next_event``. ``pair_draws``: each step uses exactly the two
    normals of Philox draw ``N_FIRST_STEP + k`` as ``z = (z1, z2)``, which the CPU lock-step
    driver can compute for many paths at once. ``builtin``: its kernels may be cached on disk.
    ``check_xi0(xi0)``: raise ValueError for an initial value the noise cannot take.

    ``parameters``: the fields, in order, of the noise's kernel record ``p`` (:meth:`record`):
    the name of one of the run's shared settings (``"D"``, ``"tau"``, ``"omega_noise"``) or a
    :class:`stochpend.model.parameters.Parameter` the noise declares for itself (its name, default,
    range and meaning, from which the API, the command line's ``--param``, sweep files, ``list``
    and the result's attributes take it); the default is the triple every noise had before
    records, ``("D", "tau", "omega_noise")``.
    """

    name: str
    build: Callable[[Any, Any], NoiseKernel]
    description: str
    colored: bool = True
    uses_omega_noise: bool = False
    has_events: bool = False
    pair_draws: bool = False
    builtin: bool = False
    default_omega_noise: Callable[[float], float] | None = None
    check_xi0: Callable[[float], None] | None = None
    variance: Callable[..., float] | None = None
    correlation: Callable[..., Any] | None = None
    spectral_density: Callable[..., Any] | None = None
    extra: dict = field(default_factory=dict)
    parameters: tuple[Any, ...] = ("D", "tau", "omega_noise")

    def record(self, config: Any) -> tuple[float, ...]:
        """The kernel record of this noise for a run of ``config`` (a SimulationConfig): for each
        name of :attr:`parameters`, ``getattr(config, name)`` when the config has that field
        (None, e.g. no ``tau``, becomes 0.0), else the value of ``config.noise_params``, a
        sorted tuple of (name, value) pairs. A tuple of float64."""
        own = dict(getattr(config, "noise_params", ()))
        values = []
        for entry in self.parameters:
            name = getattr(entry, "name", entry)  # a Parameter the noise declares, or a config field
            if hasattr(config, name):
                value = getattr(config, name)
            elif name in own:
                value = own[name]
            else:
                raise ValueError(f"noise={self.name!r} needs the parameter {name!r}: give it in "
                                 "noise_params")
            values.append(0.0 if value is None else float(value))
        return tuple(values)

    def kernel(self, real: Any, mathlib: Any) -> NoiseKernel:
        return _kernel(self, real, mathlib.name)


@functools.cache
def _kernel(noise: Noise, real: Any, mathlib_name: str) -> NoiseKernel:
    """Built once per (noise, precision, math library); the cache holds the noise itself."""
    from stochpend.numerics._jitcache import name_closures
    from stochpend.numerics.mathlib import FAST, LIBM

    kernel = noise.build(real, FAST if mathlib_name == FAST.name else LIBM)
    name_closures(vars(kernel).values(), f"noise/{noise.name}/{np.dtype(real).name}/{mathlib_name}")
    return kernel
