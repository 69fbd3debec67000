"""The integrator, written once, specialised at compile time (derivation: docs/numerics.md).

One step of length h is a symmetric drift-kick-drift (position Stormer-Verlet) splitting

    x_half      = x_n + (h/2) Omega_n
    Omega_{n+1} = Omega_n - (omega**2 h U'(x_half) + I_n G(x_half))
    x_{n+1}     = x_half + (h/2) Omega_{n+1}

where I_n is the exact integral of the noise over the step, drawn jointly with the noise's own
update (:mod:`stochpend.noises`). At D = 0 the step is the symplectic, time-reversible
Stormer-Verlet map; with noise the scheme has weak order 2 (measured in tests/statistical).

The physics of one step -- the noise's exact draws, the additive channel, the coupled members'
kicks -- is written once, :func:`the_step`; every loop below calls it, and keeps only the
loading, the step control, the landing and events, the clock, the finiteness check and the
write-back. :func:`build` assembles it from four bundles, each from its own builder: the
oscillator's pieces, the noise's, the family's terms and the generic additive channel's.

:func:`build` compiles nothing itself: for one :class:`KernelSpec` -- (oscillator, coupling, noise,
precision, adaptive or fixed step, math library) -- it returns the ``register_jitable``
functions that the backends' thin drivers call:

* :func:`Integrator.advance_path`: **the step loop**, for one path between two output times,
  with the step control, the landing rule, the noise's events, the clock, escape detection and
  the random-number bookkeeping; the CPU path-parallel driver and the CUDA thread-per-path
  kernel both call it;
* ``advance_pair`` and ``advance_levels[L]``: the same step loop for L = 2, 3, 4 coupled members
  at steps h, h/2, ..., h/2**(L-1) driven by one noise path (the finest member's steps draw it,
  a coarser member's kick uses the sum of its two halves' integrals); L = 2 is the bias
  estimate's coarse/fine pair, L = 1 ``advance_path``;
* :func:`Integrator.advance_lanes`: the same steps for a block of paths that share their time
  and step count (fixed steps, noises with ``pair_draws``), laid out so that LLVM vectorizes
  them across the lanes (the CPU's lock-step driver);
* :func:`build_lanes` (a separate builder): the same step loop for ``LANE_COUNT`` paths side by
  side, each with its own time, step and step count, refilled as paths finish (the CPU's
  default driver: adaptive steps in SIMD); :func:`build_level_lanes` the same for L = 1 .. 4
  coupled members (:func:`build_pair_lanes`: L = 2, the bias estimate's pairs);
* ``init_path`` (initial conditions) and ``path_values`` (what the statistics sum).

Every choice in the KernelSpec is a Python constant captured by these closures, so each combination
compiles to its own straight-line code: no branch on a noise or model code inside a kernel.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import numba
import numpy as np
from numba.extending import register_jitable

from stochpend.engine import layout
from stochpend.model import dynamics as _dynamics
from stochpend.model import noises as _noises
from stochpend.model import observables
from stochpend.model import oscillators as _oscillators
from stochpend.model import terms as _terms
from stochpend.model.noises.base import Noise
from stochpend.model.oscillators.base import Oscillator
from stochpend.numerics import rng
from stochpend.numerics._jitcache import name_closures
from stochpend.numerics.mathlib import FAST, LIBM

__all__ = ["SCHEME", "KernelSpec", "build", "landing_step", "advance_clock", "step_record"]

#: Integrator metadata, stored in every result's attrs.
SCHEME = {
    "name": "strang-verlet-exact-noise",
    "description": "position Stormer-Verlet (drift-kick-drift) with the exact noise integral",
    "weak_order": 2,
    "strong_order": 1,
    "interpretation": "stratonovich (= ito for this model)",
}

PRECISIONS = ("float64", "float32")

#: A path whose step control asks for a step below this fraction of h_max has escaped: it is
#: running away (|Omega| or its frequency beyond 1e9 c/h_max, e.g. a finite-time blow-up that
#: the shrinking steps would otherwise follow forever). It is frozen and counted with the
#: non-finite paths, never averaged.
ESCAPE_STEP_FRACTION = 1e-9

#: A step that would stop within this fraction of h before the target is stretched to it.
LANDING_SLACK = 1e-6

#: Paths advanced in lock step by ``advance_lanes`` (a multiple of the 8 float64 lanes of
#: AVX-512); a compile-time trip count lets LLVM vectorize the lane loops without remainders.
LANES = 64

_U64 = np.uint64


#: Members of the coupled levels :func:`build` compiles: ``advance_levels[L]`` for L = 1 (a
#: path, ``advance_path``), 2 (the bias estimate's pair, ``advance_pair``), 3 and 4.
LEVELS = (1, 2, 3, 4)


def level_positions(levels: int) -> tuple[int, int, int, int, int, int]:
    """Where the state tuple of ``levels`` coupled members keeps ``(xi, xi_aux, t, t_comp, k,
    status)`` (:data:`stochpend.engine.layout.AFTER_MEMBERS`): after the members' ``x, Omega``
    pairs, member m (0 the coarsest, step h; m the step h/2**m) at positions ``2 m``,
    ``2 m + 1`` (:func:`stochpend.engine.layout.state_arrays`)."""
    at = layout.state_positions(levels)
    XI, XA, T, TC, K, ST = (at[name] for name in layout.AFTER_MEMBERS)
    return XI, XA, T, TC, K, ST


def state_positions(pair: bool) -> tuple[int, int, int, int, int, int]:
    """Where a path's state tuple keeps ``(xi, xi_aux, t, t_comp, k, status)``: after ``x,
    Omega`` for one path, after ``x, Omega, xf, Omegaf`` for a coupled pair (``pair``)
    (:func:`level_positions` of 1 or 2 members)."""
    return level_positions(2 if pair else 1)


# -- time bookkeeping (float64 in every precision) --------------------------------------------
@register_jitable
def landing_step(t, h, t_target):
    """The step to take from time t: h, or the rest of the way when it lands on ``t_target``.

    A step that would stop within ``LANDING_SLACK * h`` of the target is stretched to it, so
    that round-off in t never leaves a sliver step. Returns ``(h, last)``.
    """
    if t + h * (1.0 + LANDING_SLACK) >= t_target:
        return t_target - t, True
    return h, False


@register_jitable
def landing_or_event(t, h, t_target, t_event):
    """The step from t towards ``t_target`` (:func:`landing_step`), cut at the noise's next
    event ``t_event`` when that comes first or at the same time.

    Returns ``(h, last, event, t_land)``: ``last`` the step lands on ``t_target``, ``event`` it
    lands on the event, ``t_land`` the time it lands on when either holds.
    """
    if t_event <= t_target:
        h, event = landing_step(t, h, t_event)
        return h, event and t_event == t_target, event, t_event
    h, last = landing_step(t, h, t_target)
    return h, last, False, t_target


@register_jitable
def advance_clock(t, t_comp, h, last, t_target):
    """The time after a step of h: exactly ``t_target`` on landing (compensation reset), else a
    Kahan-compensated ``t + h``. ``t_comp`` is part of the path's state, so a run's numbers do
    not depend on how a segment is split into calls. Returns (t, t_comp)."""
    if last:
        return t_target, 0.0
    y = h - t_comp
    t_new = t + y
    return t_new, (t_new - t) - y


#: The step record's fields (:func:`step_record`), in order: declared once, read by name (the
#: ``STEP_*`` positions below) in every kernel.
STEP_RECORD = ("omega2", "q", "h_max", "step_c", "d", "channel_record", "channel_key")
STEP_OMEGA2, STEP_Q, STEP_H_MAX, STEP_STEP_C, STEP_D, STEP_CHANNEL_RECORD, STEP_CHANNEL_KEY = range(len(STEP_RECORD))


def step_record(config: Any) -> tuple[Any, ...]:
    """The run's scalars as the kernels take them, one record ``(omega2, q, h_max, step_c)``
    (and, for a run with the family's terms on, their record ``d`` fifth; with the generic
    additive channel, its noise's record ``pa`` (:func:`stochpend.model.dynamics.channel_record`) and
    its Philox key ``(ka0, ka1)`` (:func:`stochpend.numerics.rng.additive_key`, uint64) sixth and seventh):
    omega**2, the oscillator's parameter record q (:meth:`stochpend.oscillators.Oscillator.record`:
    ``(power_n,)`` for the power family, a model's own parameters in declared order, ``(0.0,)``
    for none), the largest step and the step control's constant (0: fixed steps) of a
    :class:`stochpend.model.settings.SimulationConfig`. With the noise's record (``Noise.record``) it is
    everything of the configuration a step reads."""
    oscillator = _oscillators.get(config.potential)
    assert oscillator is not None, config.potential  # validated when the config was built
    head = (float(config.omega**2), oscillator.record(config), float(config.h_max), float(config.step_c))
    terms = _dynamics.terms_of_config(config)
    if "additive_noise" in terms:  # the generic additive channel: its noise's record, its key
        return (*head, _dynamics.record(config), _dynamics.channel_record(config),
                rng.run_keys(config.seed).additive)
    if terms:  # terms on: their record d
        return (*head, _dynamics.record(config))
    return head


# -- what a kernel is specialised for ------------------------------------------------------------
@dataclass(frozen=True)
class KernelSpec:
    """Everything a compiled kernel is specialised for.

    ``adaptive``: the step control h = min(h_max, c/v, c/sqrt(k)) (``step_c > 0``), else the
    fixed step h_max. ``fast_math``: the branch-free fdlibm log/sin/cos of
    :mod:`stochpend.numerics.fastmath` (the CPU SIMD driver) instead of the C library's.
    """

    oscillator: Oscillator
    coupling: str
    noise: Noise
    precision: str = "float64"
    adaptive: bool = True
    fast_math: bool = False
    #: The family's terms that are on (:mod:`stochpend.model.dynamics`: "damping", "torque", "drive",
    #: "parametric", "additive", "additive_noise"); empty: the paper's model,
    #: today's kernels.
    terms: frozenset = frozenset()
    #: The generic additive channel's noise (term "additive_noise"; :mod:`stochpend.model.dynamics`):
    #: the kernel calls its device functions, so each channel noise compiles its own kernel.
    additive: Noise | None = None

    def __post_init__(self) -> None:
        if self.coupling not in _oscillators.COUPLINGS:
            raise ValueError(f"coupling={self.coupling!r} is not accepted: one of "
                             f"{', '.join(_oscillators.COUPLINGS)}")
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision={self.precision!r} is not accepted: one of "
                             f"{', '.join(PRECISIONS)}")
        if ("additive_noise" in self.terms) != (self.additive is not None):
            raise ValueError(f"additive={self.additive!r} is not accepted with terms={sorted(self.terms)}: the "
                             "term 'additive_noise' and its noise go together")

    @classmethod
    def of(cls, config: Any, *, precision: str = "float64", fast_math: bool = False) -> KernelSpec:
        """The KernelSpec of a validated :class:`stochpend.model.settings.SimulationConfig`."""
        oscillator = _oscillators.get(config.potential)
        noise = _noises.get(config.noise)
        if oscillator is None or noise is None:  # validated configs never get here
            raise ValueError(f"potential={config.potential!r}, noise={config.noise!r}: not registered "
                             "in this process")
        return cls(oscillator, config.coupling, noise, precision, config.step_c > 0.0, fast_math,
                   _dynamics.terms_of_config(config), _dynamics.channel(config))

    @property
    def cacheable(self) -> bool:
        """Built-in pieces only: a user's functions live in memory, so their kernels too."""
        return self.oscillator.builtin and self.noise.builtin and (self.additive is None or self.additive.builtin)

    @property
    def label(self) -> str:
        step = "adaptive" if self.adaptive else "fixed"
        math_name = "fast" if self.fast_math else "libm"
        terms = "".join(f"+{t}" + (f"={self.additive.name}" if t == "additive_noise" and self.additive else "")
                        for t in sorted(self.terms))
        return (f"{self.oscillator.name}/{self.coupling}/{self.noise.name}/{self.precision}/"
                f"{step}/{math_name}{terms}")


# -- the integrator ------------------------------------------------------------------------------
def _copy(function: Any, name: str) -> Any:
    """A second function object with ``function``'s code and closure (so that Numba can compile
    it with other options), named ``name``."""
    import types

    copy = types.FunctionType(function.__code__, function.__globals__, name, function.__defaults__,
                              function.__closure__)
    copy.__qualname__ = function.__qualname__.replace(function.__name__, name)
    return copy


def _inline(function: Any) -> Any:
    """``function`` inlined by Numba into its callers' IR before typing (``numba.njit(inline=
    "always")``), for the CPU's step loops, where a call left to LLVM stayed a call (and stopped
    the lane loop's vectorization). Not ``register_jitable(inline="always")``: an overload is
    inlined after typing, and a tree of them typed its lower levels again at every level (the
    lane machine of two members with the family's terms took 30 s to compile, four members over
    2 minutes). numba-cuda cannot type a Numba-inlined function, so the CUDA kernels take the
    plain pieces (NVVM inlines them)."""
    return numba.njit(inline="always")(function)


@register_jitable
def _no_dyn(step_rec):
    return (0.0,)


@register_jitable
def _dyn_of(step_rec):
    return step_rec[STEP_D]


#: Where the kernels read the family's record d (:data:`stochpend.model.dynamics.RECORD`).
_AT = _dynamics.POSITION
_GAMMA, _SIGMA_A = _AT["gamma"], _AT["sigma_a"]
_TORQUE, _A, _NU, _PHI = _AT["torque"], _AT["drive_amplitude"], _AT["drive_frequency"], _AT["drive_phase"]
_EPS, _NU_P = _AT["parametric_amplitude"], _AT["parametric_frequency"]


@register_jitable
def _channel_of(step_rec):
    """The generic additive channel's noise record and Philox key from the step record."""
    return step_rec[STEP_CHANNEL_RECORD], step_rec[STEP_CHANNEL_KEY]


@register_jitable
def _no_channel(step_rec):
    return (0.0,), (_U64(0), _U64(0))


@register_jitable
def _first(z1, z2, hc, d):
    """The member tree's ``combine`` without the family's terms (no additive draw to combine)."""
    return z1


@register_jitable
def _track_nothing(tracks, i, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1):
    return None


@register_jitable
def _track_member_nothing(tracks, i, member, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1):
    return None


def _named(function: Any, name: str) -> Any:
    """``function`` renamed ``name`` (its qualname's last part too): the level trees make one
    closure per depth and piece, and :func:`stochpend.numerics._jitcache.name_closures` needs one name
    per code."""
    function.__qualname__ = function.__qualname__.replace(function.__name__, name)
    function.__name__ = name
    return function


@functools.cache
def _draw_tree(depth: int, leaf: Any, inline: bool = False) -> Any:
    """The draws of one coarse step for ``depth`` halvings: ``leaf(key0, key1, path, n, a, b, S,
    coef) -> (I, a, b, S)`` (a noise's or a channel's exact step with draw n: its integral over
    the step and its state ``a, b`` and scratch ``S`` after it) taken ``2**depth`` times, draws
    ``n .. n + 2**depth - 1`` in order. Returns the integrals as a binary tree of nested pairs
    (depth 0: the scalar, 1: ``(I1, I2)``, 2: ``((I1, I2), (I3, I4))``), the state threaded
    through; ``coef`` the finest step's coefficients. The state goes as separate scalars.

    ``inline``: the nodes inlined by Numba (the CPU's step loops). Left to LLVM, a node with its
    two inlined draws stayed a call per coarse step, its returned tuple in memory: the CPU's
    one-pair kernel was 5 % slower than the loop with its draws written out. numba-cuda cannot
    type a Numba-inlined function ("add(omitted, omitted)", as ``family_step_inline``), so the
    CUDA kernels take the plain nodes (NVVM inlines them)."""
    if depth == 0:
        return leaf
    half_tree = _draw_tree(depth - 1, leaf, inline)
    SPAN = _U64(2 ** (depth - 1))

    def draws(key0, key1, path, n, a, b, S, coef):
        I1, a, b, S = half_tree(key0, key1, path, n, a, b, S, coef)
        I2, a, b, S = half_tree(key0, key1, path, n + SPAN, a, b, S, coef)
        return (I1, I2), a, b, S

    if inline:
        return _inline(_named(draws, f"{leaf.__name__}_tree{depth}_inline"))
    return register_jitable(_named(draws, f"{leaf.__name__}_tree{depth}"))


@functools.cache
def _member_tree(depth: int, step: Any, combine: Any, half: Any, inline: bool = False) -> Any:
    """``members(mem, h, h_clock, t0, It, zt, omega2, q, d) -> (mem, I, z)``: ``depth + 1``
    coupled members over one step of the coarsest, ``mem = (x, Omega)`` (depth 0) or ``(x,
    Omega, finer)``, ``finer`` the next ``depth`` members' ``mem``.

    The finer members take the step as two halves (h/2, clock ``h_clock``/2, the second from
    ``t0 + h_clock/2``), each with one half of the draw trees ``It`` (the noise's integrals,
    :func:`_draw_tree`) and ``zt`` (the additive channel's); then the coarsest member takes
    ``step(x, Omega, h, omega2, I, q, t0, h_clock, z, d)`` (``verlet`` or ``family_step``) with
    ``I`` the sum of its two halves' integrals (the exact integral over its step) and ``z`` their
    additive draws combined (``combine(z1, z2, h_clock/2, d)``). Returns the members after the
    step, with the coarsest member's ``I`` and ``z`` (its parent's halves).

    ``inline``: the nodes inlined by Numba (the lane machine's: a call left in its lane loop
    stops the loop's vectorization), as :func:`_draw_tree`'s."""
    jit = _inline if inline else register_jitable
    tail = "_inline" if inline else ""
    if depth == 0:
        def one(mem, h, h_clock, t0, It, zt, omega2, q, d):
            x, Om = step(mem[0], mem[1], h, omega2, It, q, t0, h_clock, zt, d)
            return (x, Om), It, zt

        return jit(_named(one, f"{step.__name__}_members1{tail}"))
    finer = _member_tree(depth - 1, step, combine, half, inline)

    def members(mem, h, h_clock, t0, It, zt, omega2, q, d):
        hh = half * h
        hc = 0.5 * h_clock
        rest, I1, z1 = finer(mem[2], hh, hc, t0, It[0], zt[0], omega2, q, d)
        rest, I2, z2 = finer(rest, hh, hc, t0 + hc, It[1], zt[1], omega2, q, d)
        I = I1 + I2
        z = combine(z1, z2, hc, d)
        x, Om = step(mem[0], mem[1], h, omega2, I, q, t0, h_clock, z, d)
        return (x, Om, rest), I, z

    return jit(_named(members, f"{step.__name__}_members{depth + 1}{tail}"))


@functools.cache
def _draw_tree_states(depth: int, leaf: Any, inline: bool = False) -> Any:
    """:func:`_draw_tree` that also returns the noise's value after each draw, as a tree ``Xt`` of
    the integrals' shape: ``(It, Xt, a, b, S)``. The same draws in the same order (the same
    numbers); for the per-member accumulators (:func:`_tracked_member_tree`), which see the
    noise at each member's step ends."""
    if depth == 0:
        def draws(key0, key1, path, n, a, b, S, coef):
            I, a, b, S = leaf(key0, key1, path, n, a, b, S, coef)
            return I, a, a, b, S
    else:
        half_tree = _draw_tree_states(depth - 1, leaf, inline)
        SPAN = _U64(2 ** (depth - 1))

        def draws(key0, key1, path, n, a, b, S, coef):  # noqa: F811 - one per depth
            I1, X1, a, b, S = half_tree(key0, key1, path, n, a, b, S, coef)
            I2, X2, a, b, S = half_tree(key0, key1, path, n + SPAN, a, b, S, coef)
            return (I1, I2), (X1, X2), a, b, S

    name = f"{leaf.__name__}_states{depth}" + ("_inline" if inline else "")
    return _inline(_named(draws, name)) if inline else register_jitable(_named(draws, name))


@functools.cache
def _tracked_member_tree(depth: int, step: Any, combine: Any, half: Any, track: Any, member: int = 0,
                         inline: bool = False) -> Any:
    """:func:`_member_tree` with each member's per-path accumulators: ``members(mem, h, h_clock,
    t0, t1, It, zt, omega2, q, d, Xt, xi0, tracks, i) -> (mem, I, z, xi1, mid)``, the same steps
    in the same order (the same members), and after each step of member m (``member`` the
    coarsest of this subtree) ``track(tracks, i, m, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1)``
    (:func:`stochpend.model.observables.track_step`'s ``members``: member m's slots), in float64,
    as :func:`advance_path` tracks a path. ``Xt`` the noise's values after each draw
    (:func:`_draw_tree_states`), ``xi0`` its value at t0; ``t1`` the step's end on the clock
    (the landing time on a landing step, so that a window ending at an output time keeps its
    last step); a step's first half ends at t0 + h_clock/2, as the members take it. ``xi1``:
    the noise after the subtree's last draw. ``mid = (x, Omega, xi, t)``: the next finer
    member's state, the noise and the time between its two half steps (a single member: its
    state at t1), for the CPU's tracked pair lanes (``_lane_tracking``), which update the
    slots after the step, outside their vector loop, with ``track`` doing nothing inside it."""
    jit = _inline if inline else register_jitable
    tail = "_inline" if inline else ""
    M = member
    if depth == 0:
        def one(mem, h, h_clock, t0, t1, It, zt, omega2, q, d, Xt, xi0, tracks, i):
            x, Om = step(mem[0], mem[1], h, omega2, It, q, t0, h_clock, zt, d)
            track(tracks, i, M, np.float64(mem[0]), np.float64(mem[1]), np.float64(xi0), np.float64(x),
                  np.float64(Om), np.float64(Xt), t0, t1)
            return (x, Om), It, zt, Xt, (np.float64(x), np.float64(Om), np.float64(Xt), t1)

        return jit(_named(one, f"{step.__name__}_tracked{M}_members1{tail}"))
    finer = _tracked_member_tree(depth - 1, step, combine, half, track, member + 1, inline)

    def members(mem, h, h_clock, t0, t1, It, zt, omega2, q, d, Xt, xi0, tracks, i):
        hh = half * h
        hc = 0.5 * h_clock
        t_mid = t0 + hc
        rest, I1, z1, xi_mid, _ = finer(mem[2], hh, hc, t0, t_mid, It[0], zt[0], omega2, q, d, Xt[0], xi0,
                                        tracks, i)
        mid = (np.float64(rest[0]), np.float64(rest[1]), np.float64(xi_mid), t_mid)
        rest, I2, z2, xi1, _ = finer(rest, hh, hc, t_mid, t1, It[1], zt[1], omega2, q, d, Xt[1], xi_mid,
                                     tracks, i)
        I = I1 + I2
        z = combine(z1, z2, hc, d)
        x, Om = step(mem[0], mem[1], h, omega2, I, q, t0, h_clock, z, d)
        track(tracks, i, M, np.float64(mem[0]), np.float64(mem[1]), np.float64(xi0), np.float64(x),
              np.float64(Om), np.float64(xi1), t0, t1)
        return (x, Om, rest), I, z, xi1, mid

    return jit(_named(members, f"{step.__name__}_tracked{M}_members{depth + 1}{tail}"))


@register_jitable
def _no_bound(h, c, d):
    return h


def _bound_link(R: int, rest: Any, name: str) -> Any:
    """One link of :func:`_term_bounds`: h <= c/d[R], then the ``rest`` of the chain."""
    def bound(h, c, d):
        if d[R] * h > c:
            h = c / d[R]
        return rest(h, c, d)

    return register_jitable(_named(bound, name))


def _term_bounds(terms: tuple) -> Any:
    """``bounds(h, c, d) -> h``: the step control's bounds of the ``terms``' rates, h <= c/rate
    (:attr:`stochpend.terms.Term.rate`), each on the step the previous left, in the table's
    order, as a chain of one function per term with a rate."""
    chain = _no_bound
    for term in reversed([term for term in terms if term.rate is not None]):
        chain = _bound_link(_AT[term.rate], chain, f"{term.name}_bounds")
    return chain


#: The most members a step loop carries (:data:`LEVELS`): the arrays it takes from the state.
_MAX_LEVELS = 4


def _member_tuples(levels: int) -> tuple[Any, Any]:
    """``nest(x0, Omega0, ..., x3, Omega3) -> mem`` and ``flat(mem) -> (x0, Omega0, ..., x3,
    Omega3)`` of ``levels`` members (the nested ``mem`` of
    :func:`_member_tree`), on scalars only: the step loop takes the arrays from its state tuple
    itself (a function taking the tuple costs a counted reference per array). The scalars of
    members beyond ``levels`` are not read (``nest``) or are repeats (``flat``)."""
    if levels == 1:
        def nest(x0, O0, x1, O1, x2, O2, x3, O3):
            return (x0, O0)

        def flat(mem):
            return (mem[0], mem[1], mem[0], mem[1], mem[0], mem[1], mem[0], mem[1])
    else:
        nest_f, flat_f = _member_tuples(levels - 1)

        def nest(x0, O0, x1, O1, x2, O2, x3, O3):  # noqa: F811 - one per number of members
            return (x0, O0, nest_f(x1, O1, x2, O2, x3, O3, x3, O3))

        def flat(mem):  # noqa: F811
            rest = flat_f(mem[2])
            return (mem[0], mem[1], rest[0], rest[1], rest[2], rest[3], rest[4], rest[5])

    return register_jitable(_named(nest, f"nest_members{levels}")), register_jitable(_named(flat, f"flat_members{levels}"))


def the_step(LEVELS: int, draws: SimpleNamespace, members: Any, family: SimpleNamespace,
             channel: SimpleNamespace, *, inline: bool = False, tracked: bool = False) -> Any:
    """**The step**, written once for every loop (the one-path and coupled-level loops of
    :func:`_step_loop`, the CPU's SIMD lanes of :func:`_lane_machine`, the CUDA thread):
    ``step(mem, noise_state, channel_state, keys, path, n, h, h_clock, t0, coef, omega2, q, d)
    -> (mem, noise_state, channel_state)`` advances ``LEVELS`` coupled members ``mem``
    (:func:`_member_tree`) over one step of the coarsest, of length h (``h_clock`` in float64,
    from time ``t0``), with draws ``n .. n + 2**(LEVELS-1) - 1``.

    The finest member's steps draw the noise (``draws.noise``, a leaf of :func:`_draw_tree`;
    ``noise_state = (xi, aux, S)``) and the additive channel (``channel_state = (xi_a, aux_a,
    S_a)``: a coloured noise's channel ``draws.channel`` under its own keys, else the white
    channel's normals ``draws.white``); each coarser member uses its
    halves' integrals summed (``members``). ``keys = (k0, k1, ka0, ka1)`` the noise's and the
    generic channel's keys and ``path`` the path, in the form the leaves take them (the
    one-path loops: Philox keys and the path number; the lanes: round keys and the path's
    counter words); ``coef = (C, C_channel)`` the noise's and the additive
    channel's coefficients at the finest member's step. What stays in the loops: loading,
    the step control, the landing and the events, the clock, the finiteness check, masking and
    write-back. ``inline``: the draw trees and this function inlined by Numba (the CPU's).

    ``tracked``: the members carry per-path accumulators (``members`` a
    :func:`_tracked_member_tree`); the step then takes ``(..., d, t1, tracks, i)``, t1 the step's
    end on the clock, draws the noise with its values (:func:`_draw_tree_states`): the same
    draws, the same members, and returns the members' ``mid`` after the channel's state."""
    if tracked:
        return _tracked_step(LEVELS, draws, members, family, channel, inline)
    DEPTH = LEVELS - 1
    FAMILY = family.FAMILY
    CHANNEL = channel.CHANNEL
    noise_path = _draw_tree(DEPTH, draws.noise, inline)
    white_path = _draw_tree(DEPTH, draws.white, inline)
    channel_path = _draw_tree(DEPTH, draws.channel, inline)

    def step(mem, noise_state, channel_state, keys, path, n, h, h_clock, t0, coef, omega2, q, d):
        xn = noise_state[0]
        xa = noise_state[1]
        S = noise_state[2]
        xc = channel_state[0]
        xca = channel_state[1]
        Sa = channel_state[2]
        It, xn, xa, S = noise_path(keys[0], keys[1], path, n, xn, xa, S, coef[0])
        if FAMILY:
            # The additive noise likewise: the finest member's steps draw it, a coarser member's
            # step uses its halves' integrals summed (the OU and the generic channel) or the
            # normal of the exact composition of their two O flows (white).
            if CHANNEL:  # the channel's noise under its own key
                zt, xc, xca, Sa = channel_path(keys[2], keys[3], path, n, xc, xca, Sa, coef[1])
            else:
                zt, _, _, _ = white_path(keys[0], keys[1], path, n, xc, xc, Sa, coef[1])
        else:
            zt = It  # not read: Stormer-Verlet has no additive noise
        mem, _, _ = members(mem, h, h_clock, t0, It, zt, omega2, q, d)
        return mem, (xn, xa, S), (xc, xca, Sa)

    name = f"{draws.noise.__name__}_step{LEVELS}" + ("_inline" if inline else "")
    if inline:
        return _inline(_named(step, name))
    return register_jitable(_named(step, name))


def _tracked_step(LEVELS: int, draws: SimpleNamespace, members: Any, family: SimpleNamespace,
                  channel: SimpleNamespace, inline: bool) -> Any:
    """:func:`the_step` with ``tracked``: its draws, with the noise's values after each
    (:func:`_draw_tree_states`), and the tracked members; returns ``(mem, noise_state,
    channel_state, mid)``, ``mid`` the members' (:func:`_tracked_member_tree`). A function of
    its own, so that the untracked step every other kernel compiles stays as it is."""
    DEPTH = LEVELS - 1
    FAMILY = family.FAMILY
    CHANNEL = channel.CHANNEL
    noise_path = _draw_tree_states(DEPTH, draws.noise, inline)
    white_path = _draw_tree(DEPTH, draws.white, inline)
    channel_path = _draw_tree(DEPTH, draws.channel, inline)

    def step(mem, noise_state, channel_state, keys, path, n, h, h_clock, t0, coef, omega2, q, d, t1, tracks, i):
        xi0 = noise_state[0]
        xc = channel_state[0]
        xca = channel_state[1]
        Sa = channel_state[2]
        It, Xt, xn, xa, S = noise_path(keys[0], keys[1], path, n, xi0, noise_state[1], noise_state[2], coef[0])
        if FAMILY:  # the additive noise as the_step draws it
            if CHANNEL:
                zt, xc, xca, Sa = channel_path(keys[2], keys[3], path, n, xc, xca, Sa, coef[1])
            else:
                zt, _, _, _ = white_path(keys[0], keys[1], path, n, xc, xc, Sa, coef[1])
        else:
            zt = It
        mem, _, _, _, mid = members(mem, h, h_clock, t0, t1, It, zt, omega2, q, d, Xt, xi0, tracks, i)
        return mem, (xn, xa, S), (xc, xca, Sa), mid

    name = f"{draws.noise.__name__}_tracked_step{LEVELS}" + ("_inline" if inline else "")
    return _inline(_named(step, name)) if inline else register_jitable(_named(step, name))


def _finest(LEVELS: int, real: Any) -> Any:
    """``finest(h)``: the finest of ``LEVELS`` members' step, h/2**(LEVELS - 1) (exact: a power
    of two), for the noise's coefficients; chosen here, so that one member's loop has no
    branch for it."""
    FINEST = real(0.5 ** (LEVELS - 1))
    if LEVELS == 1:
        def finest(h):
            return h
    else:
        def finest(h):
            return FINEST * h
    return register_jitable(_named(finest, f"finest_of{LEVELS}"))


def _loop_positions(LEVELS: int, TRACKED: bool, CHANNEL: bool) -> SimpleNamespace:
    """Where a step loop's state tuple keeps each array (:func:`stochpend.engine.layout.state_positions`,
    the one declaration of the state by name), as the loop's constants: member m's x and Omega at
    ``X<m>``, ``O<m>`` (x's and Omega's, read and never written, for a member beyond ``LEVELS``:
    ``HAS<m>`` false), ``XI, XA, T, TC, K, ST`` (xi, xi_aux, t, t_comp, k, status), then the
    accumulators' slots ``TRK`` and the additive channel's xi_a ``ADD`` and aux_a ``AUXA``, each
    only when the KernelSpec has it (``TRACKED``, ``CHANNEL``: the generic channel); 0 (x's, never
    read) otherwise.

    Constant indices, like every array of the loop: not a function returning ``state[8]``,
    which numba-cuda refuses ("Only accept returning of array passed into the function as
    argument"), so the tracked kernels did not compile for a real GPU (the CPU and the
    simulator accept it)."""
    at = layout.state_positions(LEVELS, TRACKED, CHANNEL)  # the one declaration, by name
    XI, XA, T, TC, K, ST = (at[name] for name in layout.AFTER_MEMBERS)
    # x's and Omega's positions (read, never written) stand in for the members beyond LEVELS
    X1, X2, X3 = (at.get(f"x{m}", 0) for m in range(1, _MAX_LEVELS))
    O1, O2, O3 = (at.get(f"Omega{m}", 1) for m in range(1, _MAX_LEVELS))
    HAS1, HAS2, HAS3 = (m < LEVELS for m in range(1, _MAX_LEVELS))
    return SimpleNamespace(X1=X1, X2=X2, X3=X3, O1=O1, O2=O2, O3=O3, HAS1=HAS1, HAS2=HAS2, HAS3=HAS3,
                           XI=XI, XA=XA, T=T, TC=TC, K=K, ST=ST, TRK=at.get("tracks", 0),
                           ADD=at.get("xi_a", 0), AUXA=at.get("aux_a", 0), CHANNEL=CHANNEL)


def _path_io(LEVELS: int, at: SimpleNamespace, real: Any, a_load_aux: Any, flat: Any) -> tuple[Any, Any]:
    """``load_channel(i, state) -> (xc, xca)`` and ``write_back(i, state, mem, xn, xa, xc, xca,
    tt, tc, kk, bad)``: a step loop's reads of the additive channel's state of path i and its
    write-back of the path, at the positions ``at`` (:func:`_loop_positions`)."""
    I_X1, I_X2, I_X3, I_O1, I_O2, I_O3 = at.X1, at.X2, at.X3, at.O1, at.O2, at.O3
    HAS_1, HAS_2, HAS_3 = at.HAS1, at.HAS2, at.HAS3
    I_XI, I_XA, I_T, I_TC, I_K, I_ST = at.XI, at.XA, at.T, at.TC, at.K, at.ST
    I_ADD, I_AUXA, CHANNEL = at.ADD, at.AUXA, at.CHANNEL

    def load_channel(i, state):
        """The additive channel's state of path i, (xi_a, aux_a); zeros without it (no array
        read)."""
        if CHANNEL:
            return real(state[I_ADD][i]), a_load_aux(state[I_AUXA][i])
        return real(0.0), real(0.0)

    def write_back(i, state, mem, xn, xa, xc, xca, tt, tc, kk, bad):
        """Path i's members, noise, channel, clock and draw counter back into ``state``."""
        out = flat(mem)
        state[0][i] = out[0]
        state[1][i] = out[1]
        if HAS_1:
            state[I_X1][i] = out[2]
            state[I_O1][i] = out[3]
        if HAS_2:
            state[I_X2][i] = out[4]
            state[I_O2][i] = out[5]
        if HAS_3:
            state[I_X3][i] = out[6]
            state[I_O3][i] = out[7]
        state[I_XI][i] = xn
        state[I_XA][i] = xa
        if CHANNEL:
            state[I_ADD][i] = xc
            state[I_AUXA][i] = xca
        state[I_T][i] = tt
        state[I_TC][i] = tc
        state[I_K][i] = kk
        if bad:
            state[I_ST][i] = 1

    load_channel = register_jitable(_named(load_channel, f"load_channel{LEVELS}"))
    write_back = register_jitable(_named(write_back, f"write_back{LEVELS}"))
    return load_channel, write_back


def _step_bound(oscillator: SimpleNamespace, family: SimpleNamespace, control: SimpleNamespace, *,
                inline: bool = False) -> Any:
    """``bound(mem, xn, h_max_r, c_r, omega2_r, q, d) -> (h, escaped)``: the step control's step
    from the members ``mem`` and the noise ``xn`` (the oscillator's bound, then the family's
    terms'; h_max for a fixed step), and whether it fell below ``escape * h_max`` (a path running
    away: ESCAPE_STEP_FRACTION). Written once for the step loops and the lanes (``inline``: the
    lanes', inlined by Numba, :func:`_inline`)."""
    step_size = oscillator.step_size
    family_bounds = family.family_bounds
    ADAPTIVE = control.ADAPTIVE
    FAMILY = family.FAMILY
    escape = control.escape

    def bound(mem, xn, h_max_r, c_r, omega2_r, q, d):
        esc = False
        if ADAPTIVE:
            h = step_size(mem[0], mem[1], xn, h_max_r, c_r, omega2_r, q)
            if FAMILY:
                h = family_bounds(h, c_r, d)
            esc = h < escape * h_max_r
        else:
            h = h_max_r
        return h, esc

    return _inline(_named(bound, "step_bound_inline")) if inline else register_jitable(bound)


def _step_choice(LEVELS: int, noise: SimpleNamespace, oscillator: SimpleNamespace, family: SimpleNamespace,
                 channel: SimpleNamespace, control: SimpleNamespace) -> Any:
    """``choose_step(mem, xn, xa, xc, xca, tt, t_target, h_max, h_max_r, c_r, omega2_r, q, d)``
    and ``at_events(xn, xa, xc, xca, t_land, t_ev, t_ev_a, keys, path, kk, p, p_channel)`` of a step
    loop (:func:`_step_loop`'s bundles): the step control and the landing, and the noises'
    events where a step landed on one."""
    bound = _step_bound(oscillator, family, control)
    HAS_EVENTS = noise.HAS_EVENTS
    next_event = noise.next_event
    CHANNEL_EVENTS = channel.CHANNEL_EVENTS
    a_next_event = channel.a_next_event
    at_event = noise.at_event
    a_at_event = channel.a_at_event

    def choose_step(mem, xn, xa, xc, xca, tt, t_target, h_max, h_max_r, c_r, omega2_r, q, d):
        """The step from tt: the step control's (or h_max), landing on t_target or cut at the
        noises' next events. Returns ``(h_clock, last, event, t_land, t_ev, t_ev_a, bad)``,
        ``bad`` when the path is running away (see ESCAPE_STEP_FRACTION: the caller stops it)."""
        t_ev = math.inf
        t_ev_a = math.inf
        # No early return for an escaped path (the caller stops it): with one, ptxas gave 16 of
        # the 84 kernels of the offline table 2-6 more registers (and 21 fewer: a toss-up).
        h, esc = bound(mem, xn, h_max_r, c_r, omega2_r, q, d)
        h_clock = h_max if h == h_max_r else np.float64(h)
        if CHANNEL_EVENTS:  # cut at the earlier of the two channels' next events
            t_ev = next_event(xn, xa)
            t_ev_a = a_next_event(xc, xca)
            h_clock, last, event, t_land = landing_or_event(tt, h_clock, t_target, min(t_ev, t_ev_a))
        elif HAS_EVENTS:
            h_clock, last, event, t_land = landing_or_event(tt, h_clock, t_target, next_event(xn, xa))
        else:
            h_clock, last = landing_step(tt, h_clock, t_target)
            event = False
            t_land = t_target
        return h_clock, last, event, t_land, t_ev, t_ev_a, esc

    def at_events(xn, xa, xc, xca, t_land, t_ev, t_ev_a, keys, path, kk, p, p_channel):
        """After a step that landed on an event: the noise's (``t_land == t_ev``) and the
        generic channel's (``t_land == t_ev_a``) jumps (a noise without events: none)."""
        if CHANNEL_EVENTS:
            if HAS_EVENTS and t_land == t_ev:
                xn, xa = at_event(xn, xa, keys[0], keys[1], path, kk, p)
            if t_land == t_ev_a:
                xc, xca = a_at_event(xc, xca, keys[2], keys[3], path, kk, p_channel)
        elif HAS_EVENTS:
            xn, xa = at_event(xn, xa, keys[0], keys[1], path, kk, p)
        return xn, xa, xc, xca

    return (register_jitable(_named(choose_step, f"choose_step{LEVELS}")),
            register_jitable(_named(at_events, f"at_events{LEVELS}")))

def _step_loop(LEVELS: int, noise: SimpleNamespace, oscillator: SimpleNamespace, family: SimpleNamespace,
               channel: SimpleNamespace, control: SimpleNamespace, *, inline: bool = False) -> Any:
    """The step loop of ``LEVELS`` coupled members (1: one path, :func:`advance_path`; 2: the
    bias estimate's coarse/fine pair, :func:`advance_pair`; 3, 4: ``advance_levels``), written
    once: the step control, the escape rule, the landing, the noise's events, the clock, the
    finiteness check and the bookkeeping are shared; a step draws the noise ``2**(LEVELS-1)``
    times (:func:`_draw_tree`) and advances the members (:func:`_member_tree`). ``LEVELS`` is
    a compile-time constant: each variant compiles to its own straight-line code.

    The bundles are :func:`build`'s pieces for the KernelSpec, by name: ``noise`` (the noise's device
    functions and its exact step ``step``), ``oscillator`` (``real``, ``half``, ``verlet``,
    ``step_size``), ``family`` (the family's terms: ``FAMILY``, ``family_step``, the additive
    white channel), ``channel`` (the additive channel of a coloured noise, ``CHANNEL``) and ``control``
    (``ADAPTIVE``, ``escape``, the accumulators' ``TRACK``, ``track_step``, ``member_track``). The step loop's
    closure captures each piece as it did when it was written inside :func:`build`."""
    real = oscillator.real
    half = oscillator.half
    TRACK = control.TRACK
    track_step = control.track_step
    load_aux = noise.load_aux
    scratch0 = noise.scratch0
    coefficients = noise.coefficients
    FAMILY = family.FAMILY
    dyn_of = family.dyn_of
    CHANNEL = channel.CHANNEL
    channel_of = channel.channel_of
    a_scratch0 = channel.a_scratch0
    a_coefficients = channel.a_coefficients

    DEPTH = LEVELS - 1
    DRAWS = 2 ** DEPTH
    finest = _finest(LEVELS, real)
    # Accumulators: one path tracks its steps here; coupled members each track their own steps
    # inside the step (_tracked_member_tree), with their own slots.
    TRACKED = TRACK
    PATH_TRACKED = TRACK and LEVELS == 1
    MEMBERS_TRACKED = TRACK and LEVELS > 1
    kick, combine = ((family.family_step, family.additive_sum) if FAMILY else (oscillator.verlet_step, _first))
    if MEMBERS_TRACKED:
        members_step = _tracked_member_tree(DEPTH, kick, combine, half, control.member_track)
    else:
        members_step = _member_tree(DEPTH, kick, combine, half)
    draws = SimpleNamespace(noise=noise.step, white=family.additive_step, channel=channel.step)
    step = the_step(LEVELS, draws, members_step, family, channel, inline=inline, tracked=MEMBERS_TRACKED)
    nest, flat = _member_tuples(LEVELS)
    assert LEVELS <= _MAX_LEVELS
    at = _loop_positions(LEVELS, TRACKED, CHANNEL)
    I_X1, I_X2, I_X3, I_O1, I_O2, I_O3 = at.X1, at.X2, at.X3, at.O1, at.O2, at.O3
    HAS_1, HAS_2, HAS_3 = at.HAS1, at.HAS2, at.HAS3
    I_XI, I_XA, I_T, I_TC, I_K, I_ST, I_TRK = at.XI, at.XA, at.T, at.TC, at.K, at.ST, at.TRK
    load_channel, write_back = _path_io(LEVELS, at, real, channel.a_load_aux, flat)
    choose_step, at_events = _step_choice(LEVELS, noise, oscillator, family, channel, control)

    def advance(i, state, t_target, max_steps, key0, key1, path0, p, step_rec):
        # The arrays of a tuple are taken by index, never unpacked (``x, Omega, ... =
        # state``): with an unpacked tuple, Numba (0.68) dropped the stores into the arrays
        # once it had inlined an ``inline="always"`` function (the fast-math OU
        # coefficients) into this function's IR. The same in every function here that
        # takes a tuple of arrays.
        if state[I_ST][i] != 0 or state[I_T][i] >= t_target:
            return 0, 0
        omega2 = step_rec[STEP_OMEGA2]
        q = step_rec[STEP_Q]
        h_max = step_rec[STEP_H_MAX]
        d = dyn_of(step_rec)
        omega2_r = real(omega2)
        h_max_r = real(h_max)
        c_r = real(step_rec[STEP_STEP_C])
        path = _U64(path0 + i)
        mem = nest(state[0][i], state[1][i], state[I_X1][i], state[I_O1][i], state[I_X2][i],
                   state[I_O2][i], state[I_X3][i], state[I_O3][i])
        xn = state[I_XI][i]
        xa = load_aux(state[I_XA][i])
        tt = state[I_T][i]
        tc = state[I_TC][i]
        kk = state[I_K][i]
        if TRACKED:  # a compile-time constant: an untracked kernel reads no array for it
            tracks = state[I_TRK]
        else:
            tracks = 0
        # The additive channel's state, record and key; t_ev, t_ev_a the noise's and the
        # channel's next events.
        xc, xca = load_channel(i, state)
        p_channel, keys_channel = channel_of(step_rec)
        keys = (key0, key1, keys_channel[0], keys_channel[1])
        Sa = a_scratch0()
        # Everything of the noise's step that depends on h only (with several members, on the
        # finest member's step), cached while h is unchanged (h = h_max most of the time).
        h_cached = h_max_r
        hf = finest(h_max_r)
        C = coefficients(hf, p)
        C_channel = a_coefficients(hf, p_channel)
        S = scratch0()
        steps = 0
        bad = False
        while steps < max_steps:
            h_clock, last, event, t_land, t_ev, t_ev_a, bad = choose_step(
                mem, xn, xa, xc, xca, tt, t_target, h_max, h_max_r, c_r, omega2_r, q, d)
            if bad:  # running away
                break
            h = real(h_clock)
            if h != h_cached:
                hf = finest(h)
                C = coefficients(hf, p)
                if CHANNEL:
                    C_channel = a_coefficients(hf, p_channel)
                h_cached = h
            if PATH_TRACKED:
                x_before = mem[0]
                Om_before = mem[1]
                xn_before = xn
                t_before = tt
            # The finest member's steps draw the noise (draws kk .. kk + DRAWS - 1); each
            # coarser member's kick uses the sum of its two halves' integrals, the exact
            # integral over its step (one member: one draw, its own step).
            if MEMBERS_TRACKED:  # each member's accumulators, to the step's end on the clock
                t_end, _ = advance_clock(tt, tc, h_clock, event or last, t_land)
                mem, ns, cs, _ = step(mem, (xn, xa, S), (xc, xca, Sa), keys, path, kk, h, h_clock, tt,
                                      (C, C_channel), omega2_r, q, d, t_end, tracks, i)
            else:
                mem, ns, cs = step(mem, (xn, xa, S), (xc, xca, Sa), keys, path, kk, h, h_clock, tt,
                                   (C, C_channel), omega2_r, q, d)
            xn, xa, S = ns
            xc, xca, Sa = cs
            # The accumulators see the step's own end: the noise before a jump at t1 (its left
            # limit), as the coupled members do; the next step starts after the jump. So a
            # trapezoid over the step is exact for a piecewise-constant noise, and a crossing
            # made by the jump is found at the jump's time by the next step.
            xn_end = xn
            if event:  # the event of the noise(s) whose time the step landed on
                xn, xa, xc, xca = at_events(xn, xa, xc, xca, t_land, t_ev, t_ev_a, keys, path, kk, p, p_channel)
            kk += _U64(DRAWS)
            steps += 1
            tt, tc = advance_clock(tt, tc, h_clock, event or last, t_land)
            # One short-circuit chain, as the step loop had it written out (a helper returning a
            # bool made ptxas allocate more registers); the members beyond LEVELS fold away.
            m = flat(mem)
            finite = (math.isfinite(m[0]) and math.isfinite(m[1])
                      and (not HAS_1 or (math.isfinite(m[2]) and math.isfinite(m[3])))
                      and (not HAS_2 or (math.isfinite(m[4]) and math.isfinite(m[5])))
                      and (not HAS_3 or (math.isfinite(m[6]) and math.isfinite(m[7])))
                      and math.isfinite(xn) and math.isfinite(xa))
            if not finite:
                bad = True
                break
            if PATH_TRACKED:
                track_step(tracks, i, np.float64(x_before), np.float64(Om_before),
                           np.float64(xn_before), np.float64(mem[0]), np.float64(mem[1]),
                           np.float64(xn_end), t_before, tt)
            if last:
                break
        write_back(i, state, mem, xn, xa, xc, xca, tt, tc, kk, bad)
        return DRAWS * steps, (1 if (not bad and tt < t_target) else 0)

    name = {1: "advance_path", 2: "advance_pair"}.get(LEVELS, f"advance_levels{LEVELS}")
    return register_jitable(_named(advance, name + ("_inline" if inline and LEVELS > 1 else "")))



def _lockstep_lanes(*, real, coefficients, update, verlet, mathlib_log, mathlib_sincos) -> Any:
    """``advance_lanes`` of a KernelSpec from :func:`build`'s pieces of the same names (see
    :func:`_step_loop`)."""

    @register_jitable
    def advance_lanes(block, t0, tc0, k0, t_target, max_steps, rk0, rk1, p, step_rec):
        """The steps of :func:`advance_path` for ``LANES`` lanes in lock step (fixed step, a noise
        with ``pair_draws``): every lane has the time ``t0``, compensation ``tc0`` and step
        count ``k0``, so the landing, the clock and the noise coefficients are computed once,
        and each step is two loops over the lanes with no branch, which LLVM vectorizes:

        1. Philox of draw ``N_FIRST_STEP + k`` for each lane (the round keys ``rk0``, ``rk1``
           of :func:`stochpend.numerics.rng.round_keys`; ``bc2``/``bc3`` the lanes' path words), the
           Box-Muller radius and phase into ``br``, ``bph``;
        2. the normals, the noise's update and the drift-kick-drift step.

        The arithmetic is advance_path's, operation for operation. ``block``: the lanes' arrays
        ``(bx, bO, bxi, bxa, bc2, bc3, br, bph)``; the state arrays (``bx``, ``bO``, ``bxi``,
        ``bxa``) are updated in place. ``p``, ``step_rec`` as for :func:`advance_path` (``step_c``
        unused). Returns ``(steps, t, t_comp, k, finite)``; on a non-finite lane the block stops
        after that step (``finite`` False) and the caller finishes its paths one by one.
        """
        lanes = LANES
        bx = block[0]
        bO = block[1]
        bxi = block[2]
        bxa = block[3]
        bc2 = block[4]
        bc3 = block[5]
        br = block[6]
        bph = block[7]
        omega2 = step_rec[STEP_OMEGA2]
        q = step_rec[STEP_Q]
        h_max = step_rec[STEP_H_MAX]
        omega2_r = real(omega2)
        h_max_r = real(h_max)
        tt = t0
        tc = tc0
        kk = k0
        h_cached = h_max_r
        C = coefficients(h_max_r, p)
        steps = 0
        finite = True
        while steps < max_steps:
            h_clock, last = landing_step(tt, h_max, t_target)
            h = real(h_clock)
            if h != h_cached:
                C = coefficients(h, p)
                h_cached = h
            d = _U64(rng.N_FIRST_STEP) + kk
            d0 = d & rng._MASK32
            d1 = d >> rng._SHIFT32
            for lane in range(lanes):
                c0, c1, c2, c3 = rng.philox4x32_10_keyed(d0, d1, bc2[lane], bc3[lane], rk0, rk1)
                br[lane] = math.sqrt(-2.0 * mathlib_log(rng.uniform_open(c0, c1)))
                bph[lane] = rng._TWO_PI * rng.uniform_open(c2, c3)
            for lane in range(lanes):
                sn, cs = mathlib_sincos(bph[lane])
                z = (real(br[lane] * cs), real(br[lane] * sn))
                noise_integral, xn, xa = update(bxi[lane], bxa[lane], C, z)
                bxi[lane] = xn
                bxa[lane] = xa
                bx[lane], bO[lane] = verlet(bx[lane], bO[lane], h, omega2_r, noise_integral, q)
            kk += _U64(1)
            steps += 1
            tt, tc = advance_clock(tt, tc, h_clock, last, t_target)
            for lane in range(lanes):
                if not math.isfinite(bx[lane] + bO[lane] + bxi[lane]):
                    finite = False
            if not finite or last:
                break
        return steps, tt, tc, kk, finite

    return advance_lanes




def _oscillator_pieces(spec: KernelSpec, real: Any, mathlib: Any) -> SimpleNamespace:
    """The oscillator's pieces of ``spec`` in precision ``real`` with ``mathlib``: ``G`` (what the
    noise multiplies), ``step_size`` (the step control), ``verlet`` (one drift-kick-drift step)
    and ``verlet_step`` (``verlet`` under the member tree's arguments), with ``force``, ``wrap``
    and ``half`` for the family's step."""
    osc = spec.oscillator.kernel(real, mathlib)
    POSITION = spec.coupling == "position"
    half = real(0.5)
    force = osc.force
    noise_shape = osc.noise_shape
    step_scales = osc.step_scales
    wrap = osc.wrap

    @register_jitable
    def G(x, q):
        """What the noise multiplies in dOmega/dt (Eq. `dynOmega`: sin x)."""
        if POSITION:
            return x
        return noise_shape(x, q)

    @register_jitable
    def step_size(x, Omega, xi, h_max, c, omega2, q):
        """h = min(h_max, c/v, c/sqrt(k)), v a speed and k a stiffness (docs/numerics.md).

        The first bound resolves the motion (x moves by at most c per step), the second the
        oscillation (c radians of phase per step): k = |omega**2 + xi| |U''| when the noise
        multiplies the force, |omega**2 U'' + xi| when it multiplies x. v and U'' are the
        oscillator's ``step_scales``. Only the state at the start of the step is used, so the
        choice does not look into the future of the noise.
        """
        h = h_max
        speed, curv = step_scales(x, Omega, omega2, q)
        if speed * h > c:
            h = c / speed
        if POSITION:
            stiff = abs(omega2 * curv + xi)
        else:
            stiff = abs(omega2 + xi) * curv
        if stiff * h * h > c * c:
            h = c / math.sqrt(stiff)
        return h

    @register_jitable
    def verlet(x, Omega, h, omega2, noise_integral, q):
        """One drift-kick-drift step; the kick uses the noise integral over the whole step.
        Returns (x_{n+1}, Omega_{n+1}), a periodic coordinate reduced to [-pi, pi)."""
        x_half = x + half * h * Omega
        kick = omega2 * h * force(x_half, q)
        kick += noise_integral * G(x_half, q)
        Omega_new = Omega - kick
        x_new = x_half + half * h * Omega_new
        return wrap(x_new), Omega_new

    @register_jitable
    def verlet_step(x, Omega, h, omega2, noise_integral, q, t0, h_clock, za, d):
        """:func:`verlet` under ``family_step``'s arguments (the member tree's step without the
        family's terms: ``t0``, ``h_clock``, ``za``, ``d`` unused)."""
        return verlet(x, Omega, h, omega2, noise_integral, q)

    return SimpleNamespace(real=real, half=half, force=force, wrap=wrap, G=G, step_size=step_size,
                           verlet=verlet, verlet_step=verlet_step)


def _noise_pieces(spec: KernelSpec, real: Any, mathlib: Any) -> SimpleNamespace:
    """The noise's pieces of ``spec`` (:class:`stochpend.noises.base.NoiseKernel`'s functions in
    precision ``real`` with ``mathlib``), with ``step``: its exact step as a leaf of the draw
    tree (:func:`_draw_tree`)."""
    nz = spec.noise.kernel(real, mathlib)
    draw = nz.draw
    update = nz.update

    @register_jitable
    def noise_step(key0, key1, path, n, xn, xa, S, C):
        """The noise's exact step with draw n as a leaf of the draw tree (:func:`_draw_tree`):
        returns (its integral over the step, xi, aux and the scratch S after it)."""
        z, S = draw(key0, key1, path, n, S)
        I, xn, xa = update(xn, xa, C, z)
        return I, xn, xa, S

    return SimpleNamespace(HAS_EVENTS=spec.noise.has_events, load_aux=nz.load_aux, scratch0=nz.scratch0,
                           coefficients=nz.coefficients, draw=draw, update=update, next_event=nz.next_event,
                           at_event=nz.at_event, step=noise_step)


def _family_pieces(spec: KernelSpec, real: Any, mathlib: Any, oscillator: SimpleNamespace) -> SimpleNamespace:
    """The family's terms of ``spec`` (:mod:`stochpend.model.dynamics`): their flags, the step with
    them (``family_step``, and ``family_step_inline`` for the lane machines), their step bounds,
    the additive white channel's leaf of the draw tree and the coarse members' combination of
    their halves' additive draws (``additive_sum``). Without terms, pieces that are never
    called (every use is under a compile-time ``if FAMILY``)."""
    half = oscillator.half
    G = oscillator.G
    force = oscillator.force
    wrap = oscillator.wrap
    mathlib_sincos = mathlib.sincos
    mathlib_expm1 = mathlib.expm1
    additive_normals = rng.normals_with(mathlib, real)
    CHANNEL = "additive_noise" in spec.terms
    FAMILY = bool(spec.terms)
    # The table's terms (stochpend.terms): their bounds are composed from it (family_bounds);
    # their kicks are written in family_step, under compile-time flags, because a kick composed
    # from per-term functions stays a call in the lane loop and stops its vectorization
    # (stochpend.terms). The damping and the additive channel are the Ornstein-Uhlenbeck flow of
    # Omega, not kicks: they stay special in any case.
    DAMPED = "damping" in spec.terms
    TORQUE = "torque" in spec.terms
    DRIVE = "drive" in spec.terms
    PARAMETRIC = "parametric" in spec.terms
    ADDITIVE = "additive" in spec.terms
    O_STEP = DAMPED or ADDITIVE
    dyn_of = _dyn_of if FAMILY else _no_dyn
    # The step control's bounds of the table's terms that are on (h <= c/gamma, c/nu, c/nu_p).
    family_bounds = _term_bounds(tuple(term for term in _terms.TABLE if term.name in spec.terms))

    def family_step(x, Omega, h, omega2, noise_integral, q, t0, h_clock, za, d):
        """One step with the family's terms (``d``: ``stochpend.model.dynamics.record``): drift h/2,
        half the kick, the exact Ornstein-Uhlenbeck flow of Omega over h (damping and the
        additive white noise, normal ``za``), the other half of the kick, drift h/2. The kick
        holds the force, the parametric noise's exact integral and the drives' exact integrals
        over the step (``t0``: its start, float64), and with the additive OU noise its exact
        integral over the step (then ``za`` is that integral, not a normal), as the parametric
        noise's. With the O flow in the middle the harmonic
        oscillator's stationary x is Boltzmann's exactly for every gamma h, and Omega's has the
        O(h^2) error of Stormer-Verlet, independent of gamma (docs/numerics.md); half-step
        damping factors around the kick would not (their error grows with gamma h)."""
        x_half = x + half * h * Omega
        g = G(x_half, q)
        kick = omega2 * h * force(x_half, q)
        kick += noise_integral * g
        if PARAMETRIC:  # eps int cos(nu_p s) ds over [t0, t0 + h], without cancellation
            nu_p = d[_NU_P]
            s_half, _ = mathlib_sincos(0.5 * nu_p * h_clock)
            _, c_mid = mathlib_sincos(nu_p * (t0 + 0.5 * h_clock))
            kick += real(2.0 * d[_EPS] / nu_p * c_mid * s_half) * g
        if TORQUE:
            kick -= real(d[_TORQUE] * h_clock)
        if DRIVE:  # A int cos(nu s + phi) ds
            nu = d[_NU]
            s_half, _ = mathlib_sincos(0.5 * nu * h_clock)
            _, c_mid = mathlib_sincos(nu * (t0 + 0.5 * h_clock) + d[_PHI])
            kick -= real(2.0 * d[_A] / nu * c_mid * s_half)
        if CHANNEL:  # za: the exact integral of xi_a over the step (its noise's update)
            kick -= za
        if O_STEP:
            Omega_mid = Omega - half * kick
            if DAMPED:
                # One expm1: 1 - e^2 = -m (2 + m), m = e - 1, without cancellation.
                m = mathlib_expm1(-d[_GAMMA] * h_clock)
                e = 1.0 + m
                spread = d[_SIGMA_A] * math.sqrt(-m * (2.0 + m))
            else:
                e = 1.0
                spread = d[_SIGMA_A] * math.sqrt(h_clock)
            if ADDITIVE:
                Omega_mid = real(e * Omega_mid + spread * za)
            else:
                Omega_mid = real(e * Omega_mid)
            Omega_new = Omega_mid - half * kick
        else:
            Omega_new = Omega - kick
        x_new = x_half + half * h * Omega_new
        return wrap(x_new), Omega_new

    # Two compilations of the one step: the lane machine's inlined into its IR (as a call, with
    # the damping's expm1 polynomial, the function is too large for LLVM to inline into the lane
    # loop, and a call in that loop stops its vectorization: damped lanes were 4-7x slower per
    # step), the others' a plain device function (numba-cuda cannot type the inlined IR of its
    # compile-time branches: "mul(omitted, omitted)").
    family_step_inline = _inline(_copy(family_step, "family_step_inline"))
    family_step = register_jitable(family_step)

    @register_jitable
    def additive_normal(key0, key1, path, n):
        """The additive noise's normal of draw n (its own Philox draws, ``rng.N_ADDITIVE + n``),
        with the KernelSpec's math (the lane machine's keyed draw gives the same number)."""
        if ADDITIVE:
            z, _ = additive_normals(key0, key1, path, _U64(rng.N_ADDITIVE) + n)
            return z
        return real(0.0)

    @register_jitable
    def additive_step(key0, key1, path, n, a, b, S, coef):
        """The additive white noise as a leaf of the draw tree (:func:`_draw_tree`): the normal of
        draw n; no state (``a, b, S`` passed through) and no coefficients."""
        return additive_normal(key0, key1, path, n), a, b, S

    def additive_sum(z1, z2, hc, d):
        """A coarser member's additive draw from its two halves' (each of clock length ``hc``):
        the OU and the generic channel's integrals summed (the exact integral over the step), the
        white noise's normals as the normal of the exact composition of the two half-step O
        flows, (e z1 + z2)/sqrt(1 + e^2), e = exp(-gamma hc)."""
        if CHANNEL:
            return z1 + z2
        e1 = 1.0 + mathlib_expm1(-d[_GAMMA] * hc) if DAMPED else 1.0
        return real((e1 * z1 + z2) / math.sqrt(1.0 + e1 * e1))

    # Inlined by Numba for the lane machines, as family_step_inline (the expm1 polynomial).
    additive_sum_inline = _inline(_copy(additive_sum, "additive_sum_inline"))
    additive_sum = register_jitable(additive_sum)

    return SimpleNamespace(
        FAMILY=FAMILY, dyn_of=dyn_of, family_bounds=family_bounds,
        family_step=family_step, family_step_inline=family_step_inline,
        additive_step=additive_step, additive_sum=additive_sum,
        additive_sum_inline=additive_sum_inline)


def _channel_pieces(spec: KernelSpec, real: Any, mathlib: Any, noise: SimpleNamespace,
                    family: SimpleNamespace) -> SimpleNamespace:
    """The generic additive channel of ``spec`` (term "additive_noise"): its noise's functions,
    with ``step`` its exact step as a leaf of the draw tree under the channel's own key."""
    load_aux = noise.load_aux
    scratch0 = noise.scratch0
    draw = noise.draw
    update = noise.update
    next_event = noise.next_event
    at_event = noise.at_event
    noise_step = noise.step
    zeros5 = (real(0.0),) * 5

    @register_jitable
    def no_coefficients(h, p):
        return zeros5

    # The generic additive channel (additive_noise): its noise's device functions, in the KernelSpec's
    # precision and math, called with the channel's own Philox key (step record, _channel_of);
    # without it, stubs that are never called (every use is under a compile-time ``if CHANNEL``).
    CHANNEL = "additive_noise" in spec.terms
    channel_of = _channel_of if CHANNEL else _no_channel
    if CHANNEL:
        assert spec.additive is not None
        nza = spec.additive.kernel(real, mathlib)
        CHANNEL_EVENTS = spec.additive.has_events
        a_load_aux = nza.load_aux
        a_coefficients = nza.coefficients
        a_scratch0 = nza.scratch0
        a_draw = nza.draw
        a_update = nza.update
        a_next_event = nza.next_event
        a_at_event = nza.at_event
    else:
        CHANNEL_EVENTS = False
        a_load_aux = load_aux
        a_coefficients = no_coefficients
        a_scratch0 = scratch0
        a_draw = draw
        a_update = update
        a_next_event = next_event
        a_at_event = at_event

    if CHANNEL:
        @register_jitable
        def channel_step(key0, key1, path, n, xn, xa, S, C):
            """The generic channel's exact step with draw n under its own key, as
            :func:`noise_step`: its xi_a, aux_a and scratch."""
            z, S = a_draw(key0, key1, path, n, S)
            I, xn, xa = a_update(xn, xa, C, z)
            return I, xn, xa, S
    else:
        channel_step = noise_step  # never called (every use is under a compile-time ``if CHANNEL``)

    return SimpleNamespace(CHANNEL=CHANNEL, CHANNEL_EVENTS=CHANNEL_EVENTS, channel_of=channel_of,
                           a_load_aux=a_load_aux, a_scratch0=a_scratch0, a_coefficients=a_coefficients,
                           a_next_event=a_next_event, a_at_event=a_at_event, step=channel_step)


@functools.cache
def build(spec: KernelSpec, track: Any = None) -> SimpleNamespace:
    """The device functions of ``spec`` (see the module docstring); cached per KernelSpec.

    ``track``: the per-path accumulators' step update
    (:func:`stochpend.observables.track_step`), called by ``advance_path`` after each step of a
    path that stays finite, with the state before and after it; their slots are ``state[8]``,
    a float64 array (n_slots, n_paths). Its ``members`` update is the coupled levels' loops'
    (``advance_levels``, ``device_levels``): each member its own slots, after each of its own
    steps (:func:`_tracked_member_tree`), the slots after ``status``. ``None`` (every run
    without accumulators): no tracking is compiled, and the kernels are those of the KernelSpec
    alone.
    """
    real = np.float32 if spec.precision == "float32" else np.float64
    mathlib = FAST if spec.fast_math else LIBM
    oscillator = _oscillator_pieces(spec, real, mathlib)
    noise = _noise_pieces(spec, real, mathlib)
    family = _family_pieces(spec, real, mathlib, oscillator)
    channel = _channel_pieces(spec, real, mathlib, noise, family)
    control = SimpleNamespace(ADAPTIVE=spec.adaptive, escape=real(ESCAPE_STEP_FRACTION), TRACK=track is not None,
                              track_step=_track_nothing if track is None else track,
                              member_track=getattr(track, "members", _track_member_nothing))
    # The step loop's pieces, in bundles (_step_loop).
    pieces: dict[str, Any] = dict(noise=noise, oscillator=oscillator, family=family, channel=channel,
                                  control=control)

    #: ``advance_path(i, state, t_target, max_steps, key0, key1, path0, p, step_rec)``: advance path
    #: i of the arrays towards ``t_target``, at most ``max_steps`` steps.
    #:
    #: ``state``: the arrays ``(x, Omega, xi, xi_aux, t, t_comp, k, status)`` (with per-path
    #: accumulators, their slots ``tracks`` last); ``p``: the noise's record
    #: (``Noise.record``); ``step_rec``: ``(omega2, q, h_max, step_c)`` (:func:`step_record`).
    #:
    #: The last step is shortened to land exactly on ``t_target`` (and, for a noise with events,
    #: a step is cut at each event). A path whose state becomes non-finite, or whose step
    #: control asks for less than ``ESCAPE_STEP_FRACTION * h_max``, gets status 1 and is never
    #: advanced again. The step, the noise and the dynamics run in the KernelSpec's precision; the
    #: clock, the landing rule and the step counter in float64/uint64, with the float64 h_max
    #: whenever the step is the largest one, so float32 takes the same steps and draws as
    #: float64. Returns ``(steps_taken, unfinished)`` (1 if the path stopped short of
    #: ``t_target``).
    advance_path = _step_loop(1, **pieces)

    #: ``advance_pair(i, state, t_target, max_steps, key0, key1, path0, p, step_rec)``: advance a
    #: *coupled pair* of path i towards ``t_target`` (the bias estimate, :mod:`stochpend.bias`).
    #:
    #: The coarse member (``x``, ``Omega``) takes exactly :func:`advance_path`'s steps: the step
    #: control on its own state, the landing, the noise's events. The fine member (``xf``,
    #: ``Omegaf``) takes each of those steps as two half steps. Both see one realization of the
    #: noise: the half steps draw it (draws ``2m`` and ``2m + 1`` for coarse step m; the noise
    #: state ``xi``, ``xi_aux`` is shared) and the coarse kick uses the sum of the two half-step
    #: integrals, which is the exact integral over the whole step. So the coarse member has the
    #: law of an ordinary path of this KernelSpec, the fine one that of the same scheme at half the
    #: step, and their difference is small path by path (strong order 1), which is what makes
    #: the bias estimate cheap.
    #:
    #: ``state``: the arrays ``(x, Omega, xf, Omegaf, xi, xi_aux, t, t_comp, k, status)``;
    #: ``p``, ``step_rec`` as for ``advance_path``. ``k`` counts draws (two per coarse step). Returns
    #: ``(draws_taken, unfinished)``; a pair with either member non-finite or escaped gets
    #: status 1.
    advance_pair = _step_loop(2, **pieces, inline=True)

    #: ``advance_levels[L]``: the step loop of L coupled members (L = 1: ``advance_path``, 2:
    #: ``advance_pair``, 3, 4), with ``advance_pair``'s signature. Member m (0 the coarsest)
    #: takes each of ``advance_path``'s steps h (the step control on member 0's state, the
    #: landing, the noise's events) as 2**m steps h/2**m: the finest member's steps draw the
    #: noise (draws ``2**(L-1) n .. 2**(L-1) (n + 1) - 1`` for coarse step n; the noise state
    #: is shared), and each coarser member's kick uses the sum of its two halves' integrals
    #: (:func:`_member_tree`), so member m has the law of an ordinary run at step h/2**m.
    #: ``state``: ``(x_0, Omega_0, ..., x_{L-1}, Omega_{L-1}, xi, xi_aux, t, t_comp, k,
    #: status)`` (:func:`level_positions`), then the additive channel's arrays as for a path;
    #: ``k`` counts draws. Returns ``(draws_taken, unfinished)``. These are the CPU's (the draw
    #: trees inlined by Numba, :func:`_draw_tree`); ``device_levels[L]`` the same loops for the
    #: CUDA kernels (the same numbers: the same operations in the same order).
    advance_levels = {1: advance_path, 2: advance_pair}
    device_levels = {1: advance_path}
    for levels in LEVELS[1:]:
        if levels > 2:
            advance_levels[levels] = _step_loop(levels, **pieces, inline=True)
        device_levels[levels] = _step_loop(levels, **pieces)

    advance_lanes = _lockstep_lanes(real=real, coefficients=noise.coefficients, update=noise.update,
                                    verlet=oscillator.verlet, mathlib_log=mathlib.log,
                                    mathlib_sincos=mathlib.sincos)

    # family_step_inline too: only the lane machines call it, and whichever of them was built
    # first in a process would otherwise name it, so the pair kernel compiled by the compile
    # helper (pairs alone) and the one this process looks up (lanes first) would differ in name
    # and never share a cache entry.
    name_closures([oscillator.G, oscillator.step_size, oscillator.verlet, *advance_levels.values(),
                   *device_levels.values(), advance_lanes, family.family_step_inline, family.additive_sum_inline],
                  # A tracked build is named by its track's name, which names its accumulators
                  # (observables.track_step: the same in every process for built-in ones, whose
                  # kernel is then cached on disk; an object's identity for a user's).
                  spec.label if track is None else f"{spec.label}/track/{track.__qualname__}")
    return SimpleNamespace(
        spec=spec, real=real, G=oscillator.G, step_size=oscillator.step_size, verlet=oscillator.verlet,
        family_step=family.family_step, family_step_inline=family.family_step_inline,
        family_bounds=family.family_bounds, noise_step=noise.step, additive_step=family.additive_step,
        additive_sum=family.additive_sum, additive_sum_inline=family.additive_sum_inline,
        channel_step=channel.step, a_coefficients=channel.a_coefficients, a_scratch0=channel.a_scratch0,
        pieces=pieces, init_path=initial_state(spec.noise), advance_path=advance_path, advance_pair=advance_pair,
        advance_levels=advance_levels, device_levels=device_levels, advance_lanes=advance_lanes,
        path_values=statistics(spec.oscillator, spec.coupling),
        lockstep=(not spec.adaptive) and spec.noise.pair_draws and not spec.noise.has_events and not family.FAMILY,
    )


@functools.cache
def initial_state(noise: Noise):
    """``init_path`` of ``noise`` (it depends on nothing else), computed in float64."""
    noise_init = noise.kernel(np.float64, LIBM).init
    two_pi = 2.0 * math.pi

    @register_jitable
    def init_path(key0, key1, path, theta0, uniform_theta0, Omega0, xi0, stationary_xi0, p):
        """(x, Omega, xi, aux) of global path ``path`` (uint64) at t = 0, in float64: x uniform
        on [-pi, pi) from draw ``N_INIT_THETA`` (or ``theta0``), Omega0, and the noise's
        stationary law from draw ``N_INIT_XI`` (or xi0); ``p`` the noise's record."""
        if uniform_theta0:
            u, _ = rng.draw_uniforms(key0, key1, path, np.uint64(rng.N_INIT_THETA))
            x = two_pi * u - math.pi
        else:
            x = theta0
        xi, aux = noise_init(key0, key1, path, p, xi0, stationary_xi0)
        return x, Omega0, xi, aux

    name_closures([init_path], f"init/{noise.name}")
    return init_path


@functools.cache
def statistics(oscillator: Oscillator, coupling: str):
    """``path_values(x, Omega, omega2, q) -> (ok, E, values)`` of (oscillator, coupling), q the
    oscillator's record (the generated source names it ``n``), in
    float64 whatever the kernel's precision: the summed values of :data:`stochpend.observables.SUMS`,
    generated from that table (:func:`stochpend.observables.path_values_source`)."""
    osc64 = oscillator.kernel(np.float64, LIBM)
    potential64 = osc64.potential
    noise_shape64 = osc64.noise_shape

    @register_jitable
    def position(x, q):
        return x

    namespace = {"potential": potential64, "shape": position if coupling == "position" else noise_shape64,
                 "isfinite": math.isfinite}
    exec(compile(observables.path_values_source(), f"<stochpend.observables {observables.TABLE_KEY}>", "exec"),
         namespace)
    function = namespace["path_values"]
    # Named as a closure of this builder, so that name_closures tags it like every other piece.
    function.__module__, function.__qualname__ = __name__, "statistics.<locals>.path_values"
    path_values = register_jitable(function)
    name_closures([path_values, position], f"statistics/{oscillator.name}/{coupling}/{observables.TABLE_KEY}")
    return path_values


def spec(noise: str = "ou", potential: str = "pendulum", coupling: str = "force", *,
         precision: str = "float64", adaptive: bool = True, fast_math: bool = False,
         terms: frozenset = frozenset(), additive: str | None = None) -> KernelSpec:
    """A KernelSpec from names (for tests and benchmarks): ``spec("white", "harmonic", adaptive=False)``;
    ``terms``: the family's terms that are on (``frozenset({"damping", "additive"})``);
    ``additive``: the generic additive channel's noise (with the term "additive_noise")."""
    oscillator = _oscillators.get(potential)
    noise_piece = _noises.get(noise)
    if oscillator is None:
        raise ValueError(f"potential={potential!r} is not accepted: not registered")
    if noise_piece is None:
        raise ValueError(f"noise={noise!r} is not accepted: not registered")
    channel = None if additive is None else _noises.get(additive)
    if additive is not None and channel is None:
        raise ValueError(f"additive={additive!r} is not accepted: not registered")
    return KernelSpec(oscillator, coupling, noise_piece, precision, adaptive, fast_math, frozenset(terms), channel)


# -- the SIMD lane machine (CPU) -----------------------------------------------------------------
#: Lanes of :func:`build_lanes`' machine: paths advanced side by side, each with its own time,
#: step and step count (4 float64 lanes of AVX2, 8 of AVX-512, a few vectors deep).
LANE_COUNT = 16

#: Rows of the lane machine's scratch arrays (per thread, preallocated by the driver):
#: ``fs`` float64 (x, Omega, xi, aux, t, t_comp, the additive channel's xi_a and aux_a), ``us``
#: uint64 (k, the path's two counter words), ``js`` int64 (path index or -1, steps in this call,
#: active, escaped/non-finite).
LANE_F_ROWS = 8
LANE_U_ROWS = 3
LANE_I_ROWS = 4


def lanes_supported(spec: KernelSpec) -> bool:
    """Whether :func:`build_lanes` runs ``spec``: float64, a noise without events whose fast-math
    kernel has ``draw_keyed``, the fast math library; with the generic additive channel, its
    noise likewise (else the run goes one path at a time: ``cpu.spec_for`` then picks the C
    library's KernelSpec and ``advance_path``)."""
    if not spec.fast_math or spec.precision != "float64" or spec.noise.has_events:
        return False
    if spec.additive is not None and (spec.additive.has_events
                                      or spec.additive.kernel(np.float64, FAST).draw_keyed is None):
        return False
    return spec.noise.kernel(np.float64, FAST).draw_keyed is not None


@functools.cache
def build_lanes(spec: KernelSpec) -> SimpleNamespace:
    """The step loop of :func:`build`'s ``advance_path`` for ``LANE_COUNT`` paths side by side.

    Each lane carries one path with its own time, clock compensation, step count, step size
    (the step control of ``step_size``), landing, noise coefficients and Philox counter, so
    adaptive steps run in SIMD. Every iteration advances every lane by one step in one loop
    over the lanes without a branch (the conditions are selects), which LLVM vectorizes; a
    lane whose path has landed on ``t_target``, used up ``max_steps``, escaped or become
    non-finite is masked (its state is not changed), written back, and refilled with the next
    path of the range. The step is :func:`the_step`, with keyed draws of the same numbers, so a
    path's numbers are the same in any lane, at any time, next to any other paths: a function
    of (seed, path) alone, as for every driver. Needs :func:`lanes_supported`.

    ``advance_range(lo, hi, state, t_target, max_steps, rk0, rk1, path0, p, step_rec, scratch) ->
    (steps_taken, unfinished)``: advance_path for paths lo .. hi - 1 of the arrays ``state``
    (``p``, ``step_rec`` as for ``advance_path``); ``rk0``, ``rk1`` the seed's round keys
    (``rng.round_keys``); ``scratch = (fs, us, js)`` the thread's scratch, shapes
    (``LANE_F_ROWS``, ``LANE_COUNT``), (``LANE_U_ROWS``, ...), (``LANE_I_ROWS``, ...).
    """
    return build_level_lanes(spec, 1)


def lane_f_rows(levels: int, n_slots: int = 0) -> int:
    """Rows of the float64 scratch of the lane machine of ``levels`` members: the one-path
    machine's ``LANE_F_ROWS``, then members 1 .. levels - 1's x and Omega; with ``n_slots``
    per-path accumulators (each member's), every member's slots, then the rows of each lane's
    last step (``LANE_TRACK_ROWS``, or ``LANE_PAIR_TRACK_ROWS`` for a pair)."""
    track_rows = LANE_TRACK_ROWS if levels == 1 else LANE_PAIR_TRACK_ROWS
    return LANE_F_ROWS + 2 * (levels - 1) + (levels * n_slots + track_rows if n_slots else 0)


#: The tracked lane machine's rows of a lane's last step, after its slots: x, Omega, xi, t and
#: the lane's step count before the step.
LANE_TRACK_ROWS = 5

#: The tracked pair machine's rows of a lane's last step, after its slots: both members' x and
#: Omega, xi, t and the step count before the step (7), then the fine member's x, Omega, the
#: noise and the time between its two half steps (4, written by the lane loop: the tracked
#: step's ``mid``, :func:`_tracked_member_tree`).
LANE_PAIR_TRACK_ROWS = 11


@functools.cache
def build_pair_lanes(spec: KernelSpec) -> SimpleNamespace:
    """:func:`build`'s ``advance_pair`` (the coupled coarse/fine pairs of the bias estimate)
    for ``LANE_COUNT`` pairs side by side, as :func:`build_lanes` runs ``advance_path``
    (:func:`build_level_lanes` of 2 members). ``k`` counts draws (two per coarse step)."""
    return build_level_lanes(spec, 2)


@functools.cache
def build_level_lanes(spec: KernelSpec, levels: int, track: Any = None) -> SimpleNamespace:
    """:func:`build`'s ``advance_levels[levels]`` (``levels`` coupled members at steps h, h/2,
    ..., h/2**(levels-1) driven by one noise path) for ``LANE_COUNT`` paths side by side, as
    :func:`build_lanes` runs ``advance_path``: the same numbers, operation for operation, so a
    member's numbers do not depend on its lane or its neighbours, and member 0 has the law of
    the run's own paths. Needs :func:`lanes_supported`.

    ``advance_range(lo, hi, state, t_target, max_steps, rk0, rk1, path0, p, step_rec, scratch) ->
    (draws_taken, unfinished)``, ``state`` the arrays of ``advance_levels[levels]``
    (:func:`level_positions`); ``scratch = (fs, us, js)``, ``fs`` of shape
    (:func:`lane_f_rows` ``(levels)``, ``LANE_COUNT``), ``us`` and ``js`` as for
    :func:`build_lanes`.

    ``track``: per-path accumulators (:func:`stochpend.observables.track_step`; one member or a
    pair): ``state`` holds their slots ``tracks`` (:func:`level_positions` with them, each
    member's), each lane carries its path's slots in ``fs`` (``lane_f_rows(levels,
    track.n_slots)`` rows), and after each vector step every lane whose step was taken updates
    them, from its state, noise and time before and after the step (and a pair's fine member
    from its state between its two half steps), as ``advance_path`` (one member: a step that
    stayed finite) and ``advance_pair`` of ``build(spec, track)`` do.
    """
    if track is not None and levels not in (1, 2):
        raise ValueError(f"levels={levels!r} is not accepted with per-path accumulators in lanes: 1 or 2")
    if levels not in LEVELS:
        raise ValueError(f"levels={levels!r} is not accepted: one of {', '.join(map(str, LEVELS))}")
    if not lanes_supported(spec):
        raise ValueError(f"spec {spec.label} is not accepted: the lane machine needs "
                         "integrator.lanes_supported(spec)")
    return _lane_machine(spec, levels, track)


def _keyed_draws(spec: KernelSpec, steps: SimpleNamespace) -> SimpleNamespace:
    """The lane machine's leaves of the draw trees (:func:`_draw_tree`): :func:`build`'s
    ``noise_step``, ``additive_step`` and ``channel_step`` with the same numbers,
    drawn by ``draw_keyed`` and ``rng.normals_keyed_with`` from the seed's round keys and the
    path's counter words ``cw = (c2, c3)``, with no loop-carried scratch (``S`` passes through),
    inlined by Numba (a call left in the lane loop stops its vectorization)."""
    real = steps.real
    nz = spec.noise.kernel(real, FAST)
    draw_keyed = nz.draw_keyed
    update = nz.update
    normals_keyed = rng.normals_keyed_with(FAST)
    ADDITIVE = "additive" in spec.terms
    zero_r = real(0.0)
    nza = nz if spec.additive is None else spec.additive.kernel(real, FAST)
    a_draw_keyed = nza.draw_keyed
    a_update = nza.update

    @_inline
    def noise_keyed(rk0, rk1, cw, n, xn, xa, S, C):
        I, xn, xa = update(xn, xa, C, draw_keyed(rk0, rk1, cw[0], cw[1], n))
        return I, xn, xa, S

    @_inline
    def white_keyed(rk0, rk1, cw, n, a, b, S, coef):
        if ADDITIVE:
            z, _ = normals_keyed(rk0, rk1, cw[0], cw[1], _U64(rng.N_ADDITIVE) + n)
            return z, a, b, S
        return zero_r, a, b, S

    @_inline
    def channel_keyed(rk0, rk1, cw, n, xc, xca, S, C):
        I, xc, xca = a_update(xc, xca, C, a_draw_keyed(rk0, rk1, cw[0], cw[1], n))
        return I, xc, xca, S

    return SimpleNamespace(noise=noise_keyed, white=white_keyed, channel=channel_keyed)


def _lane_load_store(spec: KernelSpec, LEVELS: int, steps: SimpleNamespace, N_SLOTS: int = 0) -> SimpleNamespace:
    """The lane machine's scalar part: ``fill(lane, nxt, hi, state, t_target, path0, scratch)
    -> (nxt, loaded)`` loads the next path of ``nxt .. hi - 1`` that is neither frozen nor
    finished into ``lane``; ``store(lane, state, scratch, t_target) -> (draws, unfinished)``
    writes the lane's path back; ``idle(scratch, t_target)`` sets every lane idle (harmless
    numbers that are never written back); ``refill`` and ``store_and_refill`` do the first
    two over every lane. The scratch's rows: ``fs`` x, Omega, xi, aux, t,
    t_comp, xi_a, aux_a, then members 1.. 's x and Omega; ``us`` k and the path's counter
    words; ``js`` the path's index (-1: none), steps in this call, active, escaped or
    non-finite. ``N_SLOTS`` slots of per-path accumulators (every member's): they ride in ``fs``
    from row ``lane_f_rows(LEVELS)``, loaded and stored with the path."""
    load_aux = spec.noise.kernel(steps.real, FAST).load_aux
    channel = steps.pieces["channel"]
    a_load_aux = channel.a_load_aux
    CHANNEL = channel.CHANNEL
    TRACKED = N_SLOTS > 0
    at = _loop_positions(LEVELS, TRACKED, CHANNEL)  # the state's arrays, by name
    I_XI, I_XA, I_T, I_TC, I_K, I_ST, I_ADD, I_AUXA = at.XI, at.XA, at.T, at.TC, at.K, at.ST, at.ADD, at.AUXA
    I_TRK = at.TRK
    X1, X2, X3, O1, O2, O3 = at.X1, at.X2, at.X3, at.O1, at.O2, at.O3
    HAS_1, HAS_2, HAS_3 = at.HAS1, at.HAS2, at.HAS3
    F_ROWS = lane_f_rows(LEVELS, N_SLOTS // LEVELS)
    T0 = lane_f_rows(LEVELS)  # the first slot's row
    DRAWS = 2 ** (LEVELS - 1)
    # Member m's x in fs (row R_m; Omega the next); members beyond LEVELS take member 0's, never
    # touched (every use is under HAS_m).
    R1, R2, R3 = (LANE_F_ROWS + 2 * (m - 1) if m < LEVELS else 0 for m in range(1, _MAX_LEVELS))

    @register_jitable
    def load(lane, i, state, path0, scratch):
        fs = scratch[0]
        us = scratch[1]
        js = scratch[2]
        # The state's arrays by constant index (a tuple of arrays of several types).
        fs[0, lane] = state[0][i]
        fs[1, lane] = state[1][i]
        if HAS_1:
            fs[R1, lane] = state[X1][i]
            fs[R1 + 1, lane] = state[O1][i]
        if HAS_2:
            fs[R2, lane] = state[X2][i]
            fs[R2 + 1, lane] = state[O2][i]
        if HAS_3:
            fs[R3, lane] = state[X3][i]
            fs[R3 + 1, lane] = state[O3][i]
        fs[2, lane] = state[I_XI][i]
        fs[3, lane] = load_aux(state[I_XA][i])
        fs[4, lane] = state[I_T][i]
        fs[5, lane] = state[I_TC][i]
        if CHANNEL:
            fs[6, lane] = state[I_ADD][i]
            fs[7, lane] = a_load_aux(state[I_AUXA][i])
        if TRACKED:  # a compile-time constant: an untracked machine reads no slot
            tracks = state[I_TRK]
            for s in range(N_SLOTS):
                fs[T0 + s, lane] = tracks[s, i]
        path = _U64(path0 + i)
        us[0, lane] = state[I_K][i]
        us[1, lane] = path & rng._MASK32
        us[2, lane] = path >> rng._SHIFT32
        js[0, lane] = i
        js[1, lane] = 0
        js[2, lane] = 1
        js[3, lane] = 0

    @register_jitable
    def fill(lane, nxt, hi, state, t_target, path0, scratch):
        t = state[I_T]
        status = state[I_ST]
        while nxt < hi and (status[nxt] != 0 or t[nxt] >= t_target):
            nxt += 1
        if nxt < hi:
            load(lane, nxt, state, path0, scratch)
            return nxt + 1, 1
        return nxt, 0

    @register_jitable
    def store(lane, state, scratch, t_target):
        fs = scratch[0]
        us = scratch[1]
        js = scratch[2]
        i = js[0, lane]
        state[0][i] = fs[0, lane]
        state[1][i] = fs[1, lane]
        if HAS_1:
            state[X1][i] = fs[R1, lane]
            state[O1][i] = fs[R1 + 1, lane]
        if HAS_2:
            state[X2][i] = fs[R2, lane]
            state[O2][i] = fs[R2 + 1, lane]
        if HAS_3:
            state[X3][i] = fs[R3, lane]
            state[O3][i] = fs[R3 + 1, lane]
        state[I_XI][i] = fs[2, lane]
        state[I_XA][i] = fs[3, lane]
        state[I_T][i] = fs[4, lane]
        state[I_TC][i] = fs[5, lane]
        if CHANNEL:
            state[I_ADD][i] = fs[6, lane]
            state[I_AUXA][i] = fs[7, lane]
        if TRACKED:
            tracks = state[I_TRK]
            for s in range(N_SLOTS):
                tracks[s, i] = fs[T0 + s, lane]
        state[I_K][i] = us[0, lane]
        js[0, lane] = -1
        if js[3, lane] != 0:
            state[I_ST][i] = 1
            return DRAWS * js[1, lane], 0
        return DRAWS * js[1, lane], (1 if fs[4, lane] < t_target else 0)

    @register_jitable
    def idle(scratch, t_target):
        fs = scratch[0]
        us = scratch[1]
        js = scratch[2]
        for lane in range(LANE_COUNT):
            for r in range(F_ROWS):
                fs[r, lane] = 0.0
            fs[4, lane] = t_target
            for r in range(LANE_U_ROWS):
                us[r, lane] = 0
            for r in range(LANE_I_ROWS):
                js[r, lane] = 0
            js[0, lane] = -1

    @register_jitable
    def refill(nxt, hi, state, t_target, path0, scratch):
        """Every lane loaded (:func:`fill`): ``(nxt, lanes loaded)``."""
        n_active = 0
        for lane in range(LANE_COUNT):
            nxt, loaded = fill(lane, nxt, hi, state, t_target, path0, scratch)
            n_active += loaded
        return nxt, n_active

    @register_jitable
    def store_and_refill(nxt, hi, state, t_target, path0, scratch, n_active):
        """Each finished lane written back (:func:`store`) and loaded again (:func:`fill`):
        ``(nxt, draws, unfinished, n_active)``."""
        js = scratch[2]
        draws = 0
        unfinished = 0
        for lane in range(LANE_COUNT):
            if js[0, lane] < 0 or js[2, lane] != 0:
                continue
            s, u = store(lane, state, scratch, t_target)
            draws += s
            unfinished += u
            n_active -= 1
            nxt, loaded = fill(lane, nxt, hi, state, t_target, path0, scratch)
            n_active += loaded
        return nxt, draws, unfinished, n_active

    return SimpleNamespace(fill=fill, store=store, idle=idle, refill=refill, store_and_refill=store_and_refill)


def _lane_scalars(spec: KernelSpec, LEVELS: int, steps: SimpleNamespace) -> tuple[Any, Any, Any, Any]:
    """The lane machine's scalar pieces, inlined into its lane loop (:func:`_inline`):
    ``lane_step(mem, xn, tt, t_target, h_max, h_max_r, c_r, omega2_r, q, d) -> (h, h_clock,
    last, escaped)``, the step control's step (or h_max) landing on t_target, without a branch;
    ``lane_clock(tt, tc, h_clock, last, t_target) -> (t, t_comp)``, :func:`advance_clock`'s
    compensated sum written branch-free; ``lane_finite(m, ns)``, whether the members (``flat``)
    and the noise after the step are finite (bitwise ands: no short-circuit branch);
    ``lane_records(step_rec, rk0, rk1) -> (p_channel, keys)``: the additive channel's record and the round
    keys of the noise and the channel."""
    real = steps.real
    bound = _step_bound(steps.pieces["oscillator"], steps.pieces["family"], steps.pieces["control"], inline=True)
    slack = 1.0 + LANDING_SLACK
    HAS_1, HAS_2, HAS_3 = (m < LEVELS for m in range(1, _MAX_LEVELS))
    channel_of = steps.pieces["channel"].channel_of

    def lane_step(mem, xn, tt, t_target, h_max, h_max_r, c_r, omega2_r, q, d):
        h, esc = bound(mem, xn, h_max_r, c_r, omega2_r, q, d)
        h_clock = h_max if h == h_max_r else np.float64(h)
        last = tt + h_clock * slack >= t_target
        h_clock = t_target - tt if last else h_clock
        return real(h_clock), h_clock, last, esc

    def lane_clock(tt, tc, h_clock, last, t_target):
        y = h_clock - tc
        t_sum = tt + y
        tc_new = (t_sum - tt) - y
        return (t_target if last else t_sum), (0.0 if last else tc_new)

    def lane_finite(m, ns):
        finite = (math.isfinite(m[0]) & math.isfinite(m[1])
                  & math.isfinite(ns[0]) & math.isfinite(ns[1]))
        if HAS_1:
            finite = finite & math.isfinite(m[2]) & math.isfinite(m[3])
        if HAS_2:
            finite = finite & math.isfinite(m[4]) & math.isfinite(m[5])
        if HAS_3:
            finite = finite & math.isfinite(m[6]) & math.isfinite(m[7])
        return finite

    def lane_records(step_rec, rk0, rk1):
        p_channel, keys_channel = channel_of(step_rec)
        rka0, rka1 = rng.round_keys(keys_channel[0], keys_channel[1])  # the channel's, the same for every path
        return p_channel, (rk0, rk1, rka0, rka1)

    return (_inline(_named(lane_step, f"lane_step{LEVELS}")), _inline(_named(lane_clock, "lane_clock")),
            _inline(_named(lane_finite, f"lane_finite{LEVELS}")), _inline(lane_records))


def _lane_tracking(track: Any, LEVELS: int) -> tuple[Any, Any, int]:
    """The tracked lane machine's two loops over the lanes, around its vector lane loop (in
    loops of their own: more stores or the accumulators' calls in the lane loop stop LLVM
    vectorizing it). ``keep_before(fs, js)``: each lane's members' x and Omega, xi, t (``fs``
    rows 0, 1, [members 1's], 2, 4) and step count (``js`` row 1) before its step, into the rows
    after its slots; ``track_lanes(fs, js)``: the update of the slots (``track``, rows ``T0 ..``)
    after a step taken.

    One member: ``advance_path``'s update, after a step taken that stayed finite (the lane's
    step count moved and it is not marked bad; an active lane never is before its step). A pair
    (``track.members``): ``advance_pair``'s, after a step taken, finite or not (its tracked
    members update inside the step, before the finiteness check): the fine member's two half
    steps through its state between them (the rows ``MID`` .. ``MID + 3``, which the lane loop
    writes: the tracked step's ``mid``), then the coarse member's step. ``track`` None:
    functions never called. Returns ``(keep_before, track_lanes, MID)``."""
    N_SLOTS = 0 if track is None else LEVELS * track.n_slots
    T0 = lane_f_rows(LEVELS)
    B0 = T0 + N_SLOTS
    R1 = LANE_F_ROWS  # a pair's fine member's x (Omega the next)
    MID = B0 + 7
    if track is None:
        track_step = _track_nothing
    else:
        track_step = track if LEVELS == 1 else track.members

    # Inlined by Numba into the machine, rows taken as 1-d views, as the lane loop takes them:
    # as calls indexing (row, lane), the copy did not vectorize and a run with the
    # displacement took 25 % longer.
    if LEVELS == 1:
        @_inline
        def keep_before(fs, js):
            x, Omega, xi, t, steps = fs[0], fs[1], fs[2], fs[4], js[1]
            b_x, b_Omega, b_xi, b_t, b_steps = fs[B0], fs[B0 + 1], fs[B0 + 2], fs[B0 + 3], fs[B0 + 4]
            for lane in range(LANE_COUNT):
                b_x[lane] = x[lane]
                b_Omega[lane] = Omega[lane]
                b_xi[lane] = xi[lane]
                b_t[lane] = t[lane]
                b_steps[lane] = steps[lane]

        @_inline
        def track_lanes(fs, js):
            x, Omega, xi, t, steps, bad = fs[0], fs[1], fs[2], fs[4], js[1], js[3]
            b_x, b_Omega, b_xi, b_t, b_steps = fs[B0], fs[B0 + 1], fs[B0 + 2], fs[B0 + 3], fs[B0 + 4]
            slots = fs[T0:B0]
            for lane in range(LANE_COUNT):
                if steps[lane] != b_steps[lane] and bad[lane] == 0:
                    track_step(slots, lane, b_x[lane], b_Omega[lane], b_xi[lane], x[lane], Omega[lane], xi[lane],
                               b_t[lane], t[lane])

        return keep_before, track_lanes, MID

    @_inline
    def keep_pair(fs, js):
        x, Omega, xf, Omf, xi, t, steps = fs[0], fs[1], fs[R1], fs[R1 + 1], fs[2], fs[4], js[1]
        b_x, b_Omega, b_xf, b_Omf = fs[B0], fs[B0 + 1], fs[B0 + 2], fs[B0 + 3]
        b_xi, b_t, b_steps = fs[B0 + 4], fs[B0 + 5], fs[B0 + 6]
        for lane in range(LANE_COUNT):
            b_x[lane] = x[lane]
            b_Omega[lane] = Omega[lane]
            b_xf[lane] = xf[lane]
            b_Omf[lane] = Omf[lane]
            b_xi[lane] = xi[lane]
            b_t[lane] = t[lane]
            b_steps[lane] = steps[lane]

    @_inline
    def track_pair(fs, js):
        x, Omega, xf, Omf, xi, t, steps = fs[0], fs[1], fs[R1], fs[R1 + 1], fs[2], fs[4], js[1]
        b_x, b_Omega, b_xf, b_Omf = fs[B0], fs[B0 + 1], fs[B0 + 2], fs[B0 + 3]
        b_xi, b_t, b_steps = fs[B0 + 4], fs[B0 + 5], fs[B0 + 6]
        m_x, m_Om, m_xi, m_t = fs[MID], fs[MID + 1], fs[MID + 2], fs[MID + 3]
        slots = fs[T0:B0]
        for lane in range(LANE_COUNT):
            if steps[lane] != b_steps[lane]:
                track_step(slots, lane, 1, b_xf[lane], b_Omf[lane], b_xi[lane], m_x[lane], m_Om[lane], m_xi[lane],
                           b_t[lane], m_t[lane])
                track_step(slots, lane, 1, m_x[lane], m_Om[lane], m_xi[lane], xf[lane], Omf[lane], xi[lane],
                           m_t[lane], t[lane])
                track_step(slots, lane, 0, b_x[lane], b_Omega[lane], b_xi[lane], x[lane], Omega[lane], xi[lane],
                           b_t[lane], t[lane])

    return keep_pair, track_pair, MID


def _lane_steps(spec: KernelSpec, steps: SimpleNamespace, LEVELS: int, pair_tracked: bool) -> tuple[Any, Any]:
    """The lane machine's ``(step, pair_step)``: :func:`the_step` of ``LEVELS`` members with keyed
    draws (:func:`_keyed_draws`), inlined by Numba; with ``pair_tracked``, the tracked pair's
    step (:func:`the_step` with ``tracked``, the same members, whose ``track`` does nothing and
    whose ``mid`` the machine keeps for its slots' update after the lane loop), else ``step``."""
    oscillator = steps.pieces["oscillator"]
    family = steps.pieces["family"]
    channel = steps.pieces["channel"]
    if family.FAMILY:
        member_step, combine = steps.family_step_inline, steps.additive_sum_inline
    else:
        member_step, combine = oscillator.verlet_step, _first
    members = _member_tree(LEVELS - 1, member_step, combine, oscillator.half, True)
    # The member trees are shared between the machines of one KernelSpec (a tree of L members holds
    # that of L - 1): named for the KernelSpec, not for the machine built first in a process (else the
    # pair machine a compile helper builds alone and the one built after the run's would differ
    # in name and never share a cache entry).
    name_closures([members], f"lane-members/{spec.label}")
    keyed = _keyed_draws(spec, steps)
    step = the_step(LEVELS, keyed, members, family, channel, inline=True)
    if not pair_tracked:
        return step, step
    kept = _tracked_member_tree(1, member_step, combine, oscillator.half, _track_member_nothing, 0, True)
    name_closures([kept], f"lane-tracked-members/{spec.label}")
    return step, the_step(2, keyed, kept, family, channel, inline=True, tracked=True)


def _lane_machine(spec: KernelSpec, LEVELS: int, track: Any = None) -> SimpleNamespace:
    """The lane machine of :func:`build_level_lanes`: the lanes' loading, masking, step control,
    landing, clock, write-back and refill around :func:`the_step` of ``LEVELS`` members with
    keyed draws (:func:`_keyed_draws`). ``LEVELS`` is a compile-time constant, so each machine
    compiles to its own branch-free lane loop.

    ``track`` (one member or a pair): a loop before the lane loop keeps each lane's state, time
    and step count in ``fs``, and one after it updates the slots of the lanes whose step was
    taken (:func:`_lane_tracking`); one member's lane loop stays as it is. A pair's takes the
    tracked step (:func:`the_step` with ``tracked``, its ``track`` doing nothing) and stores the
    fine member's state between its half steps (its ``mid``) in ``fs`` with the other stores:
    four stores more in the lane loop, which LLVM vectorizes only with more runtime alias checks
    than it allows by default (``cpu.WIDE_ALIAS_CHECKS``, set around this machine's compile)."""
    steps = build(spec)
    TRACKED = track is not None
    PAIR_TRACKED = TRACKED and LEVELS == 2
    N_SLOTS = LEVELS * track.n_slots if TRACKED else 0
    keep_before, track_lanes, MID = _lane_tracking(track, LEVELS)
    real = steps.real
    family = steps.pieces["family"]
    channel = steps.pieces["channel"]
    coefficients = spec.noise.kernel(real, FAST).coefficients
    a_coefficients = steps.a_coefficients
    dyn_of = family.dyn_of
    CHANNEL = channel.CHANNEL
    lanes = LANE_COUNT
    zero_r = real(0.0)
    DRAWS = 2 ** (LEVELS - 1)
    FINEST = real(0.5 ** (LEVELS - 1))
    step, pair_step = _lane_steps(spec, steps, LEVELS, PAIR_TRACKED)
    nest, flat = _member_tuples(LEVELS)
    scalar = _lane_load_store(spec, LEVELS, steps, N_SLOTS)
    refill, store_and_refill, idle = scalar.refill, scalar.store_and_refill, scalar.idle
    # Member m's rows in fs (row 0 for members beyond LEVELS: read by nest, never written).
    R1, R2, R3 = (LANE_F_ROWS + 2 * (m - 1) if m < LEVELS else 0 for m in range(1, _MAX_LEVELS))
    HAS_1, HAS_2, HAS_3 = (m < LEVELS for m in range(1, _MAX_LEVELS))
    lane_step, lane_clock, lane_finite, lane_records = _lane_scalars(spec, LEVELS, steps)

    @register_jitable
    def advance_range(lo, hi, state, t_target, max_steps, rk0, rk1, path0, p, step_rec, scratch):
        fs = scratch[0]
        us = scratch[1]
        js = scratch[2]
        q = step_rec[STEP_Q]
        h_max = step_rec[STEP_H_MAX]
        d = dyn_of(step_rec)
        omega2_r = real(step_rec[STEP_OMEGA2])
        h_max_r = real(h_max)
        c_r = real(step_rec[STEP_STEP_C])
        bx0 = fs[0]
        bO0 = fs[1]
        bx1 = fs[R1]
        bO1 = fs[R1 + 1]
        bx2 = fs[R2]
        bO2 = fs[R2 + 1]
        bx3 = fs[R3]
        bO3 = fs[R3 + 1]
        bxi = fs[2]
        bxa = fs[3]
        bt = fs[4]
        btc = fs[5]
        bxc = fs[6]
        bxca = fs[7]
        bk = us[0]
        bc2 = us[1]
        bc3 = us[2]
        bs = js[1]
        ba = js[2]
        bbad = js[3]
        if PAIR_TRACKED:  # a compile-time constant: rows that only the tracked pair machine has
            bmx, bmO, bmxi, bmt = fs[MID], fs[MID + 1], fs[MID + 2], fs[MID + 3]
        else:
            bmx = bmO = bmxi = bmt = bx0
        p_channel, keys = lane_records(step_rec, rk0, rk1)
        idle(scratch, t_target)
        steps_taken = 0
        unfinished = 0
        nxt = lo
        n_active = 0
        if max_steps > 0:
            nxt, n_active = refill(nxt, hi, state, t_target, path0, scratch)
        while n_active > 0:
            n_done = 0
            if TRACKED:  # a compile-time constant: the untracked machine has none of this
                keep_before(fs, js)
            for lane in range(lanes):
                # Every load first and every store last, unconditionally: a conditional store,
                # or a load after a store, makes LLVM's alias checks fail and the scalar loop run.
                active = ba[lane]
                bad_before = bbad[lane]
                steps_before = bs[lane]
                mem = nest(bx0[lane], bO0[lane], bx1[lane], bO1[lane], bx2[lane], bO2[lane], bx3[lane],
                           bO3[lane])
                xn = bxi[lane]
                xa = bxa[lane]
                xc = bxc[lane]
                xca = bxca[lane]
                tt = bt[lane]
                tc = btc[lane]
                kk = bk[lane]
                h, h_clock, last, esc = lane_step(mem, xn, tt, t_target, h_max, h_max_r, c_r, omega2_r, q, d)
                hf = FINEST * h if LEVELS > 1 else h
                coef = (coefficients(hf, p), a_coefficients(hf, p_channel))
                if PAIR_TRACKED:  # the fine member's mid, for the step's end on the clock
                    t_new, tc_new = lane_clock(tt, tc, h_clock, last, t_target)
                    new, ns, cs, mid = pair_step(mem, (xn, xa, zero_r), (xc, xca, zero_r), keys,
                                                 (bc2[lane], bc3[lane]), kk, h, h_clock, tt, coef, omega2_r, q,
                                                 d, t_new, 0, lane)
                else:
                    new, ns, cs = step(mem, (xn, xa, zero_r), (xc, xca, zero_r), keys, (bc2[lane], bc3[lane]),
                                       kk, h, h_clock, tt, coef, omega2_r, q, d)
                    t_new, tc_new = lane_clock(tt, tc, h_clock, last, t_target)
                m = flat(new)
                o = flat(mem)
                finite = lane_finite(m, ns)
                act = active != 0
                go = act & (not esc)
                steps_after = steps_before + (1 if go else 0)
                bad = act & (esc | (go & (not finite)))
                done = act & (esc | (go & (last | (not finite) | (steps_after >= max_steps))))
                bx0[lane] = m[0] if go else o[0]
                bO0[lane] = m[1] if go else o[1]
                if HAS_1:
                    bx1[lane] = m[2] if go else o[2]
                    bO1[lane] = m[3] if go else o[3]
                if HAS_2:
                    bx2[lane] = m[4] if go else o[4]
                    bO2[lane] = m[5] if go else o[5]
                if HAS_3:
                    bx3[lane] = m[6] if go else o[6]
                    bO3[lane] = m[7] if go else o[7]
                bxi[lane] = ns[0] if go else xn
                bxa[lane] = ns[1] if go else xa
                if CHANNEL:
                    bxc[lane] = cs[0] if go else xc
                    bxca[lane] = cs[1] if go else xca
                bt[lane] = t_new if go else tt
                btc[lane] = tc_new if go else tc
                bk[lane] = kk + _U64(DRAWS) if go else kk
                bs[lane] = steps_after
                bbad[lane] = 1 if bad else bad_before
                ba[lane] = 0 if done else active
                if PAIR_TRACKED:  # read after the loop for the lanes whose step was taken
                    bmx[lane] = mid[0]
                    bmO[lane] = mid[1]
                    bmxi[lane] = mid[2]
                    bmt[lane] = mid[3]
                n_done += 1 if done else 0
            if TRACKED:
                track_lanes(fs, js)
            if n_done == 0:
                continue
            # Write the finished lanes back and refill them (scalar, rare).
            nxt, s, u, n_active = store_and_refill(nxt, hi, state, t_target, path0, scratch, n_active)
            steps_taken += s
            unfinished += u
        return steps_taken, unfinished

    name_closures([advance_range, lanes, keep_before, track_lanes], f"lanes{LEVELS}/{spec.label}"
                  + (f"/track:{track.key}" if TRACKED else ""))
    return SimpleNamespace(spec=spec, advance_range=advance_range, lanes=lanes)


def linear_step_maps(h: float, d: tuple, terms: Any) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(B0, B1, a)`` of one fixed step ``h`` of the harmonic oscillator (omega = 1) with white
    noise on the force (G = x) and the family terms ``terms`` (record ``d``), read off the
    kernel's own step function: z' = (B0 + I B1) z + za a for the state z = (x, Omega), the
    noise integral I and the additive draw za. The scheme is linear in the state, so these
    give its exact second-moment map (tests/statistical/test_family_dynamics.py, the oracle of
    benchmarks/gpu_check.py). Shapes (2, 2), (2, 2), (2,)."""
    step = build(spec("white", "harmonic", "force", adaptive=False, terms=frozenset(terms))).family_step

    def apply(z, noise_integral, za):
        return np.array(step(z[0], z[1], h, 1.0, noise_integral, (0.0,), 0.0, h, za, d))

    e = np.eye(2)
    B0 = np.column_stack([apply(e[0], 0.0, 0.0), apply(e[1], 0.0, 0.0)])
    B1 = np.column_stack([apply(e[0], 1.0, 0.0), apply(e[1], 1.0, 0.0)]) - B0
    a = apply(np.zeros(2), 0.0, 1.0)
    return B0, B1, a
