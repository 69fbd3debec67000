"""CPU drivers: the integrator's step loop run on threads, and two SIMD drivers.

The drivers only orchestrate: every step is :mod:`stochpend.engine.integrator`'s, specialised for the
run's :class:`~stochpend.engine.integrator.KernelSpec` and compiled once per KernelSpec (cached on disk for the
built-in oscillators and noises). They allocate nothing per step and call no Python; the SIMD
drivers' per-worker scratch is allocated by their Python wrapper (:func:`_with_workers`).

* ``init``: the initial conditions of a range of global paths, one thread per path range;
* ``advance`` one path at a time (:func:`path_kernel`): ranges of paths on threads, each path its
  own step control (``Integrator.advance_path``); the C library's math. Every model without a
  SIMD driver;
* ``advance`` in **lanes** (:func:`_lanes_kernel`, the default: the pendulum with the noise on
  the force, OU or white noise, adaptive or fixed steps): each worker thread takes a range of
  paths and runs ``integrator.build_lanes``' machine on it, ``LANE_COUNT`` paths side by side,
  each with its own time, step, coefficients and Philox counter, refilled as paths finish;
* ``advance`` in **lock-step blocks** (:func:`_lockstep_kernel`, the fixed-step OU pendulum):
  ``BLOCK`` consecutive paths share their time and step count, so the landing, the clock and
  the coefficients are computed once per block (``Integrator.advance_lanes``). A block whose
  paths are not in lock step (a path frozen as non-finite, paths at different times after a
  resumed checkpoint), and the rest of a block where a path turned non-finite, go one path at a
  time through the same KernelSpec's ``advance_path``.
* ``accumulate``: the per-batch power sums and histogram at one output time, each batch summed
  sequentially in path order (so the sums do not depend on the thread count).
* ``joint`` (:func:`joint_kernel`): the joint (x, Omega) histogram's per-batch counts at one
  output time, only for a run that asks for it (``joint_bins``), after ``accumulate``.

The SIMD drivers use the branch-free log/sin/cos/expm1 of :mod:`stochpend.numerics.fastmath`
(``KernelSpec.fast_math``, chosen by :func:`spec_for`), whose loops LLVM vectorizes; their
arithmetic is ``advance_path``'s with that KernelSpec, operation for operation, so a path's numbers
are a function of (seed, path) alone, whatever its lane, block, chunk or thread (tested bit for
bit against ``path_kernel`` of the same KernelSpec). They differ from the C library's by an ulp or so
per call, which the chaotic dynamics amplify: the ensembles agree statistically
(tests/statistical/test_simd_agreement.py).

Every kernel is a plain ``nogil`` Numba function over a range of paths (or batches, or one
worker's pieces), run on one thread per Numba thread (``numba.get_num_threads()``) by its
Python wrapper (:func:`_ranges`, :func:`_with_workers`), not a ``parallel=True`` one: Numba's
parallel lowering compiles such a driver and everything it calls twice over, which made a
first run (a cold kernel cache) spend twice as long compiling. The numbers do not depend on
the threads either way.

Each path's state lives in arrays of length n_paths: ``x`` (the angle theta for the pendulum),
``Omega``, the noise ``xi`` and its auxiliary ``xi_aux``, the time ``t`` and its Kahan
compensation ``t_comp``, the step count ``k`` and a ``status`` (0: finite, 1: non-finite or
escaped, frozen).
"""

from __future__ import annotations

import functools
import math
import os
from types import SimpleNamespace
from typing import Any

import numba
import numpy as np
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic, register_jitable

from stochpend.engine import integrator, layout
from stochpend.engine.integrator import KernelSpec
from stochpend.engine.layout import CHUNK_ARRAYS, path_dtypes
from stochpend.model import dynamics, initial, power_sums, settings
from stochpend.model import observables as observables_
from stochpend.model.observables import N_SUMS, S_COUNT, S_NONFINITE
from stochpend.model.oscillators.pendulum import PENDULUM
from stochpend.model.power_sums import LevelSums
from stochpend.numerics import rng
from stochpend.numerics._jitcache import own_index

#: Paths per lock-step block (the integrator's lane count).
BLOCK = integrator.LANES
#: Paths advanced together (bounded memory: 57 bytes a path in the state arrays).
DEFAULT_CHUNK_PATHS = 1 << 20
#: Path-steps per kernel call, so that progress is reported every fraction of a second.
WORK_PER_CALL = 20_000_000
MIN_STEPS_PER_CALL = 1000

_U64 = np.uint64


def spec_for(config, precision: str = "float64") -> KernelSpec:
    """The KernelSpec the CPU runs ``config`` with.

    The pendulum with the noise on the force, in float64, runs on the SIMD drivers with the
    branch-free math of :mod:`stochpend.numerics.fastmath` (``fast_math``): the fixed-step OU noise in
    lock-step blocks, and every noise with ``draw_keyed`` (OU, white), adaptive or fixed, in
    the lane machine. Every other model (other oscillators, the position coupling, the
    dichotomous and harmonic noises, a user's pieces) runs the C library's functions one path
    at a time.
    """
    spec = KernelSpec.of(config, precision=precision)
    if spec.oscillator is PENDULUM and spec.coupling == "force" and precision == "float64":
        fast = KernelSpec.of(config, precision=precision, fast_math=True)
        if integrator.build(fast).lockstep or integrator.lanes_supported(fast):
            return fast
    return spec


#: The initial angle's Philox counter words (draw rng.N_INIT_THETA) and the constants its
#: vectorized draw in init_kernel uses (the path's words split as rng.draw_words splits them).
_THETA_C0 = np.uint64(rng.N_INIT_THETA & 0xFFFFFFFF)
_THETA_C1 = np.uint64(rng.N_INIT_THETA >> 32)
_MASK32 = rng._MASK32
_SHIFT32 = rng._SHIFT32
_TWO_PI = 2.0 * math.pi


@functools.cache
def init_kernel(spec: KernelSpec):
    """``init(state, key0, key1, path0, theta0, uniform_theta0, Omega0, xi0, stationary_xi0,
    p)``: initial conditions of global paths path0 .. path0 + len(x) - 1 (draws 0 and 1) into
    ``state = (x, Omega, xi, xi_aux, t, t_comp, k, status)``; ``p`` the noise's record
    (``Noise.record``); depends on the noise only. The paths are shared among the threads in
    ranges (:func:`_ranges`)."""
    init_path = integrator.initial_state(spec.noise)
    I_XI, I_XA, I_T, I_TC, I_K, I_ST = integrator.state_positions(False)

    @numba.njit(nogil=True, cache=spec.noise.builtin, error_model="numpy")
    @own_index(spec.noise.name)
    def init(lo, hi, state, key0, key1, path0, theta0, uniform_theta0, Omega0, xi0,
             stationary_xi0, p):  # pragma: no cover
        x = state[0]
        Omega = state[1]
        xi = state[I_XI]
        xi_aux = state[I_XA]
        t = state[I_T]
        t_comp = state[I_TC]
        k = state[I_K]
        status = state[I_ST]
        if uniform_theta0:
            # The uniform angle first, in a loop LLVM vectorizes (Philox with its round keys
            # written out, the uniform from integer operations): init_path's numbers bit for
            # bit (rng.draw_uniforms), at a fraction of the cost of one path at a time (the
            # angle's draw was 42 of a short path's 120 ns: issue 35's level 0).
            rk0, rk1 = rng.round_keys(key0, key1)
            for i in range(lo, hi):
                path = _U64(path0 + i)
                r0, r1, _, _ = rng.philox4x32_10_keyed(_THETA_C0, _THETA_C1, path & _MASK32,
                                                       path >> _SHIFT32, rk0, rk1)
                x[i] = _TWO_PI * rng.uniform_open_bits(r0, r1) - math.pi
        for i in range(lo, hi):
            x[i], Omega[i], xi[i], xi_aux[i] = init_path(
                key0, key1, _U64(path0 + i), x[i] if uniform_theta0 else theta0, False, Omega0, xi0,
                stationary_xi0, p)
            t[i] = 0.0
            t_comp[i] = 0.0
            k[i] = 0
            status[i] = 0

    return _ranges(init)


def _ranges(kernel, items: int = 0, summed: bool = False):
    """A kernel over items ``lo .. hi - 1`` (rows of its argument ``items``) as one over all:
    one contiguous range per Numba thread (``numba.get_num_threads()``), run on threads
    (:func:`_on_workers`). For kernels whose items are independent (paths, batches), so the
    numbers do not depend on the split (a tuple of arrays, the state, counts its first's
    rows). A plain ``nogil`` kernel, not a ``parallel=True`` one:
    Numba's parallel lowering compiles such a kernel and what it calls twice over (about 1 s
    more each on a cold cache). ``summed``: the kernel returns ``(steps, unfinished)``, and so
    does the whole, summed over the ranges."""

    def run(*args):
        rows = args[items]
        n_items = (rows[0] if isinstance(rows, tuple) else rows).shape[0]
        nw = max(1, min(numba.get_num_threads(), n_items))
        size = -(-n_items // nw)
        if nw > 1:
            _compile_here(kernel, (0, n_items, *args))
        done = _on_workers(lambda w: kernel(min(w * size, n_items),
                                            min((w + 1) * size, n_items), *args), nw)
        if summed:  # (steps, unfinished) of each range
            return sum(d[0] for d in done), sum(d[1] for d in done)
        return None

    run.kernel = kernel  # type: ignore[attr-defined]  # the dispatcher, for compiled_kernels
    return run


@functools.cache
def advance_kernel(spec: KernelSpec):
    """``advance(state, t_target, max_steps, key0, key1, path0, p, step_rec) -> (steps_taken,
    paths_unfinished)``: every unfinished path of ``state = (x, Omega, xi, xi_aux, t, t_comp,
    k, status)`` towards ``t_target``, at most ``max_steps`` steps each (the SIMD drivers when
    the KernelSpec allows them; see the module docstring). ``p`` the noise's record
    (``Noise.record``), ``step_rec`` the run's ``(omega2, q, h_max, step_c)``
    (``integrator.step_record``)."""
    if spec.fast_math and integrator.build(spec).lockstep:
        return _with_workers(_lockstep_kernel(spec), (6, BLOCK), (2, BLOCK), (0, BLOCK),
                             items=lambda n_paths: (n_paths + BLOCK - 1) // BLOCK)
    if integrator.lanes_supported(spec):
        return _level_lanes(spec, 1)
    return path_kernel(spec)


def _one_at_a_time(advance_one, index: str | None, cache: bool, levels: int):
    """The driver of the one-at-a-time kernels: ``advance(lo, hi, state, t_target, max_steps,
    key0, key1, path0, p, step_rec) -> (steps, unfinished)`` over paths (or coupled levels) ``lo ..
    hi - 1``, each the integrator's ``advance_one`` (``advance_path``, ``advance_pair`` or
    ``advance_levels[levels]``), on ranges of paths (:func:`_ranges`). ``index``: the kernel's
    name (:func:`own_index`; None: none, a kernel compiled in memory only); ``cache``: whether
    it is cached on disk (built-in pieces). ``levels``: the members in ``state`` (1: a path, 2:
    a coupled pair; :func:`integrator.level_positions`).

    The driver tests each path's status and clock itself and calls the integrator only for a
    path still running. ``advance_one`` tests them too, but reaching that test is a call with
    the whole state tuple (about a hundred words on the stack) and a counted reference per array
    taken from it, and the engine calls the driver until its slowest path lands, so most calls
    are for paths that have landed (466 calls over 10**4 paths in benchmarks/revisions.py
    one-path): that made the one-path kernel about 4 % slower than 5319e81's ``prange`` kernel,
    whose loop had the integrator inlined."""
    _, _, I_T, _, _, I_ST = integrator.level_positions(levels)

    def advance(lo, hi, state, t_target, max_steps, key0, key1, path0, p,
                step_rec):  # pragma: no cover - compiled
        steps_taken = 0
        unfinished = 0
        t = state[I_T]
        status = state[I_ST]
        for i in range(lo, hi):
            if status[i] != 0 or t[i] >= t_target:
                continue
            s, u = advance_one(i, state, t_target, max_steps, key0, key1, path0, p, step_rec)
            steps_taken += s
            unfinished += u
        return steps_taken, unfinished

    if index is not None:
        advance = own_index(index)(advance)
    kernel = numba.njit(nogil=True, cache=cache, error_model="numpy")(advance)
    return _ranges(kernel, summed=True)


@functools.cache
def path_kernel(spec: KernelSpec):
    """``advance`` (the signature of :func:`advance_kernel`) one path at a time: ranges of
    paths, each the integrator's ``advance_path``. The driver of every KernelSpec without a SIMD one;
    for a fast-math KernelSpec, the reference the SIMD drivers agree with bit for bit (tests)."""
    return _one_at_a_time(integrator.build(spec).advance_path, spec.label, spec.cacheable, 1)


@functools.cache
def tracked_kernel(spec: KernelSpec, accs: tuple):
    """``advance`` of a run with per-path accumulators ``accs``
    (:func:`stochpend.observables.track_step`), ``state`` holding the accumulators' slots after
    the path's arrays (:func:`stochpend.engine.layout.state_arrays`): in SIMD lanes, each lane
    carrying its path's slots, when the KernelSpec has them (``integrator.build_level_lanes``
    with the track), else one path at a time (:func:`tracked_path_kernel`). The same
    KernelSpec (fast math included), so every other number of the run is what the run without
    them gives, bit for bit, and the lanes give the one-path numbers, slots included."""
    if integrator.lanes_supported(spec):
        return _tracked_lanes(spec, accs)
    return tracked_path_kernel(spec, accs)


@functools.cache
def _tracked_lanes(spec: KernelSpec, accs: tuple):
    return _with_workers(_lanes_kernel(spec, 1, accs),
                         (integrator.lane_f_rows(1, len(accs)), integrator.LANE_COUNT),
                         (integrator.LANE_U_ROWS, integrator.LANE_COUNT),
                         (integrator.LANE_I_ROWS, integrator.LANE_COUNT))


@functools.cache
def tracked_path_kernel(spec: KernelSpec, accs: tuple):
    """:func:`tracked_kernel` one path at a time: :func:`path_kernel`'s driver over
    ``build(spec, track).advance_path``. Cached on disk when the KernelSpec is and every
    accumulator is built in (``observables.builtin_key``: the displacement), else compiled in
    memory once per process (a user's functions), as the lanes are."""
    from stochpend.model import observables

    builtin = observables.builtin_key(accs)
    cache = spec.cacheable and builtin is not None
    return _one_at_a_time(integrator.build(spec, observables.track_step(accs)).advance_path,
                          f"{spec.label}/track:{builtin}" if cache else None, cache, 1)


#: Pieces of work per worker: the workers take them one after the other, so that a worker that
#: the operating system holds back (a shared machine) does not hold the call back with it.
#: More pieces balance better; each piece ends with its lanes draining (a fraction of a path's
#: steps per lane wasted).
PIECES_PER_WORKER = 4


@numba.njit(cache=True)
@own_index("pieces")
def _pieces(n_items, workers):  # pragma: no cover - compiled
    """(n_pieces, piece size) of n_items shared by ``workers``."""
    n_pieces = min(n_items, workers * PIECES_PER_WORKER)
    size = (n_items + n_pieces - 1) // n_pieces
    return (n_items + size - 1) // size, size


@intrinsic
def _take(typingctx, counter):
    """counter[0] += 1, atomically; returns the value before (a worker's next piece)."""
    if not (isinstance(counter, types.Array) and counter.dtype == types.int64):
        return None

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        pointer = cgutils.get_item_pointer(context, builder, signature.args[0], array,
                                           [context.get_constant(types.intp, 0)])
        return builder.atomic_rmw("add", pointer, context.get_constant(types.int64, 1),
                                  "monotonic")

    return types.int64(counter), codegen


def _lanes_kernel(spec: KernelSpec, levels: int = 1, accs: tuple = ()):
    """One worker of the lane machine of ``levels`` coupled members (``build_level_lanes``; 1:
    the run's paths, 2: the bias estimate's pairs): takes pieces of the paths from the shared
    counter ``next_piece`` until none is left; :func:`_with_workers` runs ``nw`` of them on
    threads. A plain ``nogil`` function, not a ``parallel=True`` one: Numba's parallel lowering
    compiles the driver twice over (about 2 s more on a cold cache) for a loop over the workers
    that Python threads run as well. ``accs``: the run's per-path accumulators (one member),
    carried in the lanes; cached on disk as :func:`tracked_path_kernel` is."""
    index = {1: spec.label, 2: spec.label + "/pairs"}.get(levels, f"{spec.label}/lanes{levels}")
    cache = spec.cacheable
    track = None
    if accs:
        from stochpend.model import observables

        track = observables.track_step(accs)
        builtin = observables.builtin_key(accs)
        cache = cache and builtin is not None
        index = f"{spec.label}/{'lanes' if levels == 1 else 'pairs'}/track:{builtin or observables.user_key(accs)}"
    advance_range = integrator.build_level_lanes(spec, levels, track).advance_range

    @numba.njit(nogil=True, cache=cache, error_model="numpy")
    @own_index(index)
    def advance(state, t_target, max_steps, key0, key1, path0, p, step_rec, scratch, next_piece,
                nw):  # pragma: no cover - compiled
        n_paths = state[0].shape[0]
        n_pieces, size = _pieces(n_paths, nw)
        rk0, rk1 = rng.round_keys(key0, key1)  # the same for every path
        steps_taken = 0
        unfinished = 0
        piece = _take(next_piece)
        while piece < n_pieces:
            s, uf = advance_range(piece * size, min((piece + 1) * size, n_paths), state, t_target,
                                  max_steps, rk0, rk1, path0, p, step_rec, scratch)
            steps_taken += s
            unfinished += uf
            piece = _take(next_piece)
        return steps_taken, unfinished

    return advance


_POOL = None


def _pool():
    """The threads that run the lane workers beside the calling thread (made on first use, and
    again in a forked child, whose copy of the pool has no threads)."""
    global _POOL
    if _POOL is None:
        from concurrent.futures import ThreadPoolExecutor

        _POOL = ThreadPoolExecutor(max_workers=max(1, numba.config.NUMBA_NUM_THREADS - 1),
                                   thread_name_prefix="stochpend-lanes")
    return _POOL


def _forget_pool() -> None:
    global _POOL
    _POOL = None


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _compile_here(kernel, args: tuple) -> None:
    """Compile ``kernel`` for ``args`` (or load it from the cache) on the calling thread, before
    :func:`_on_workers` hands it to the pool. Left to the first worker that calls it, the
    compile could run on a pool thread, which an interrupted caller must wait for: Ctrl-C in a
    cold, busy run (CI's Ctrl-C test: over 60 s) then waited for that compile and the worker's
    share of the call. Here it is the caller's own work, which Ctrl-C ends at once."""
    signature = tuple(kernel.typeof_pyval(a) for a in args)
    if signature not in kernel.overloads:
        kernel.compile(signature)


def _on_workers(call, nw: int, stop=None) -> list:
    """``[call(w) for w in range(nw)]``, worker 0 on this thread and the others on the pool
    (the kernels release the GIL). Returns only when every worker has returned, also on
    Ctrl-C, so no worker is still writing the arrays when the caller goes on (a checkpoint, an
    error). ``stop``: called when the caller's share ends in an exception (Ctrl-C), to tell the
    others to take no more work, so that the wait is for the pieces under way only."""
    if nw == 1:
        return [call(0)]
    from concurrent.futures import wait

    futures = [_pool().submit(call, w) for w in range(1, nw)]
    failed = True
    try:
        first = call(0)
        failed = False
    finally:
        if failed and stop is not None:
            stop()
        interrupted = None
        while True:
            try:
                wait(futures)
                break
            except BaseException as exc:  # noqa: BLE001 - re-raised once the workers are done
                interrupted = exc
        if interrupted is not None:
            raise interrupted
    return [first, *(future.result() for future in futures)]


#: A piece number past any call's last (``_take`` then hands out none): the workers stop.
_NO_MORE_PIECES = 1 << 62


def _with_workers(kernel, f_shape, u_shape, i_shape, items=None):
    """``advance`` with the driver's signature for a lane worker ``kernel``: one worker per Numba
    thread (``numba.get_num_threads()``, which ``threads=`` sets), at most one per path, each
    with its own scratch (a few kB, allocated here so that the kernel allocates nothing), passed
    as one tuple ``(f, u, j)`` after the driver's arguments."""

    def advance(state, *args):
        n_paths = state[0].shape[0]
        n_items = n_paths if items is None else items(n_paths)
        nw = max(1, min(numba.get_num_threads(), n_items))
        fs = np.empty((nw, *f_shape))
        us = np.empty((nw, *u_shape), dtype=np.uint64)
        js = np.empty((nw, *i_shape), dtype=np.int64)
        next_piece = np.zeros(1, dtype=np.int64)
        if nw > 1:
            _compile_here(kernel, (state, *args, (fs[0], us[0], js[0]), next_piece, nw))
        done = _on_workers(lambda w: kernel(state, *args, (fs[w], us[w], js[w]), next_piece, nw),
                           nw, stop=lambda: next_piece.fill(_NO_MORE_PIECES))
        return sum(d[0] for d in done), sum(d[1] for d in done)

    advance.kernel = kernel
    return advance


@functools.cache
def pair_advance_kernel(spec: KernelSpec):
    """``advance(state, t_target, max_steps, key0, key1, path0, p, step_rec) -> (draws_taken,
    pairs_unfinished)``: the coupled pairs ``state = (x, Omega, xf, Omegaf, xi, xi_aux, t,
    t_comp, k, status)`` of the bias estimate (:mod:`stochpend.bias`) towards ``t_target``.

    In SIMD lanes (``integrator.build_pair_lanes``) when the KernelSpec has them, with the run's fast
    math, so the pairs cost what the run's own paths cost per step; else one pair at a time
    (``Integrator.advance_pair``), as the run's paths go one at a time."""
    if integrator.lanes_supported(spec):
        return _level_lanes(spec, 2)
    return _pair_path_kernel(spec)


@functools.cache
def _level_lanes(spec: KernelSpec, levels: int):
    """The lane machine of ``levels`` members on the workers (:func:`_lanes_kernel`): one per
    (KernelSpec, levels), whichever kernel function asks (the compiled kernels' statistics read it)."""
    return _with_workers(_lanes_kernel(spec, levels), (integrator.lane_f_rows(levels), integrator.LANE_COUNT),
                         (integrator.LANE_U_ROWS, integrator.LANE_COUNT),
                         (integrator.LANE_I_ROWS, integrator.LANE_COUNT))


@functools.cache
def _pair_path_kernel(spec: KernelSpec):
    return _one_at_a_time(integrator.build(spec).advance_pair, spec.label + "/pairs",
                          spec.cacheable, 2)


@functools.cache
def _tracked_pair_lanes(spec: KernelSpec, accs: tuple):
    return _with_workers(_wide_alias_checks(_lanes_kernel(spec, 2, accs)),
                         (integrator.lane_f_rows(2, len(accs)), integrator.LANE_COUNT),
                         (integrator.LANE_U_ROWS, integrator.LANE_COUNT),
                         (integrator.LANE_I_ROWS, integrator.LANE_COUNT))


#: LLVM's limit on a vectorized loop's runtime alias checks, ``(option, raised, LLVM's
#: default)``, raised while the tracked pair lanes compile (:func:`_wide_alias_checks`).
#: Their lane loop stores the fine member's state between its half steps into four rows more of
#: the scratch (the tracked step's ``mid``); at the default LLVM gives up on checking that many
#: rows against each other ("too many memory checks needed") and runs the loop one lane at a
#: time: 50 000 OU pendulum pairs to t = 5 took 0.40 to 0.42 s at the default, 0.11 s with the
#: limit raised and 0.29 to 0.33 s one pair at a time (benchmarks/RESULTS_ACCURACY.md).
WIDE_ALIAS_CHECKS = (("vectorize-memory-check-threshold", 1024, 128),)


def _wide_alias_checks(kernel):
    """``kernel`` (a Numba dispatcher) whose compiles run with LLVM's alias-check limit raised
    (:data:`WIDE_ALIAS_CHECKS`) and set back to LLVM's default after, under Numba's compiler
    lock, so that no other compile sees them. The limit changes which loops are vectorized,
    not what a loop computes: a kernel compiled without it gives the same numbers, one lane at
    a time. (Numba's dispatcher calls its
    ``compile`` attribute on a first call too, so the instance's own is the one that runs.)"""
    import llvmlite.binding as llvm
    from numba.core.compiler_lock import global_compiler_lock

    compile_ = kernel.compile

    def compile(signature):
        with global_compiler_lock:
            for option, raised, _ in WIDE_ALIAS_CHECKS:
                llvm.set_option("", f"-{option}={raised}")
            try:
                return compile_(signature)
            finally:
                for option, _, default in WIDE_ALIAS_CHECKS:
                    llvm.set_option("", f"-{option}={default}")

    kernel.compile = compile
    return kernel


@functools.cache
def tracked_levels_kernel(spec: KernelSpec, accs: tuple, levels: int):
    """``levels`` coupled members (:func:`levels_kernel`'s signature) each carrying the per-path
    accumulators ``accs`` in its own slots (``state`` of :func:`stochpend.engine.layout.state_arrays`
    with ``tracked``: ``tracks`` of shape (levels * len(accs), n)), the same KernelSpec: the
    members' states are :func:`levels_kernel`'s, bit for bit. A pair in SIMD lanes when the
    KernelSpec has them (``integrator.build_level_lanes`` with the track, each lane carrying
    both members' slots, compiled with LLVM's alias-check limit raised: :func:`_wide_alias_checks`),
    giving the one-pair loop's numbers, slots included; else, and for 3 or 4 members, one set
    of members at a time (``Integrator.advance_levels`` of the tracked build). Cached on disk as
    :func:`tracked_kernel` is."""
    from stochpend.model import observables

    if levels == 2 and integrator.lanes_supported(spec):
        return _tracked_pair_lanes(spec, accs)
    builtin = observables.builtin_key(accs)
    cache = spec.cacheable and builtin is not None
    return _one_at_a_time(integrator.build(spec, observables.track_step(accs)).advance_levels[levels],
                          f"{spec.label}/levels{levels}/track:{builtin}" if cache else None, cache, levels)


@functools.cache
def levels_kernel(spec: KernelSpec, levels: int):
    """``advance(state, t_target, max_steps, key0, key1, path0, p, step_rec) -> (draws_taken,
    unfinished)``: ``levels`` coupled members (``integrator.build(spec).advance_levels``: steps
    h, h/2, ..., h/2**(levels-1) driven by one noise path), ``state`` of
    :func:`integrator.level_positions` (members 0 .. levels-1, then ``xi, xi_aux, t, t_comp, k,
    status`` and the additive channel's arrays): in SIMD lanes when the KernelSpec has them
    (``integrator.build_level_lanes``, the same numbers), else one path at a time (``levels``
    1 is :func:`path_kernel`, 2 the bias estimate's one-pair kernel)."""
    if integrator.lanes_supported(spec):
        return _level_lanes(spec, levels)
    if levels == 1:
        return path_kernel(spec)
    if levels == 2:
        return _pair_path_kernel(spec)
    return _one_at_a_time(integrator.build(spec).advance_levels[levels], f"{spec.label}/levels{levels}",
                          spec.cacheable, levels)


def _lockstep_kernel(spec: KernelSpec):
    steps = integrator.build(spec)
    advance_path = steps.advance_path
    advance_lanes = steps.advance_lanes
    I_XI, I_XA, I_T, I_TC, I_K, I_ST = integrator.state_positions(False)

    @numba.njit(nogil=True, cache=spec.cacheable, error_model="numpy")
    @own_index(spec.label)
    def advance(state, t_target, max_steps, key0, key1, path0, p, step_rec, scratch, next_piece,
                nw):  # pragma: no cover - compiled
        x = state[0]
        Omega = state[1]
        xi = state[I_XI]
        xi_aux = state[I_XA]
        t = state[I_T]
        t_comp = state[I_TC]
        k = state[I_K]
        status = state[I_ST]
        fw = scratch[0]
        uw = scratch[1]
        n_paths = x.shape[0]
        n_blocks = (n_paths + BLOCK - 1) // BLOCK
        n_pieces, size = _pieces(n_blocks, nw)
        rk0, rk1 = rng.round_keys(key0, key1)  # the same for every path
        steps_taken = 0
        unfinished = 0
        bx = fw[0]
        bO = fw[1]
        bxi = fw[2]
        bxa = fw[3]
        br = fw[4]
        bph = fw[5]
        bc2 = uw[0]
        bc3 = uw[1]
        piece = _take(next_piece)
        b = piece * size
        while piece < n_pieces:
            if b >= min((piece + 1) * size, n_blocks):
                piece = _take(next_piece)
                b = piece * size
                continue
            i0 = b * BLOCK
            b += 1
            m = min(BLOCK, n_paths - i0)
            t0 = t[i0]
            k0 = k[i0]
            tc0 = t_comp[i0]
            lockstep = True
            for lane in range(m):
                if (status[i0 + lane] != 0 or t[i0 + lane] != t0 or k[i0 + lane] != k0
                        or t_comp[i0 + lane] != tc0):
                    lockstep = False
            if not lockstep or t0 >= t_target:
                for lane in range(m):
                    if status[i0 + lane] != 0 or t[i0 + lane] >= t_target:
                        continue  # landed or stopped: no call (as in _one_at_a_time)
                    s, u = advance_path(i0 + lane, state, t_target, max_steps, key0, key1,
                                        path0, p, step_rec)
                    steps_taken += s
                    unfinished += u
                continue
            for lane in range(BLOCK):
                src = i0 + lane if lane < m else i0  # padding lanes repeat the first path
                bx[lane] = x[src]
                bO[lane] = Omega[src]
                bxi[lane] = xi[src]
                bxa[lane] = xi_aux[src]
                path = _U64(path0 + src)
                bc2[lane] = path & rng._MASK32
                bc3[lane] = path >> rng._SHIFT32
            s, tt, tc, kk, finite = advance_lanes((bx, bO, bxi, bxa, bc2, bc3, br, bph), t0,
                                                  tc0, k0, t_target, max_steps, rk0, rk1, p, step_rec)
            for lane in range(m):
                x[i0 + lane] = bx[lane]
                Omega[i0 + lane] = bO[lane]
                xi[i0 + lane] = bxi[lane]
                xi_aux[i0 + lane] = bxa[lane]
                t[i0 + lane] = tt
                t_comp[i0 + lane] = tc
                k[i0 + lane] = kk
            steps_taken += s * m
            if not finite:
                # A path stops at its first non-finite state: freeze those lanes, and let
                # the others go on one by one (the same numbers, one path at a time).
                for lane in range(m):
                    if not (math.isfinite(bx[lane]) and math.isfinite(bO[lane])
                            and math.isfinite(bxi[lane])):
                        status[i0 + lane] = 1
                for lane in range(m):
                    s2, u = advance_path(i0 + lane, state, t_target, max_steps - s, key0, key1,
                                         path0, p, step_rec)
                    steps_taken += s2
                    unfinished += u
            elif tt < t_target:
                unfinished += m
        return steps_taken, unfinished

    return advance


def accumulate_kernel(spec: KernelSpec, observables: tuple[str, ...] = ()):
    """``accumulate(x, Omega, xi, t, status, tracks, omega2, q, batch_size, edges, sums, hist)``:
    per-batch sums of the values of the statistics table (:mod:`stochpend.observables`) and of
    the run's user ``observables`` (a per-path accumulator's columns read from its slot of
    ``tracks``, (n_slots, n_paths) float64; any 2-d float64 array without accumulators), and the
    energy histogram, at one output time (float64 whatever the precision of the state); depends
    on the oscillator, the coupling and the user observables only.

    A path whose summed values or G(x) are not finite is marked non-finite here (status 1):
    the state is finite but its moments overflow, so the path has escaped; it stays excluded
    at every later time. Paths ``[b * batch_size, (b + 1) * batch_size)`` of the chunk form
    batch b, summed sequentially in path order. ``sums``: (n_batches, N_SUMS + len(observables))
    float64, overwritten. ``hist``: (n_batches, n_bins + 2) int64, overwritten; column 0 counts E
    below ``edges[0]``, the last column E at or above ``edges[-1]``.
    """
    return _accumulate_kernel(spec, observables_.objects(observables))


@functools.cache
def _accumulate_kernel(spec: KernelSpec, user: tuple):
    path_values = integrator.statistics(spec.oscillator, spec.coupling)
    user_values = observables_.user_values(user, spec.oscillator)
    n_values = len(observables_.SUMS)
    n_user = observables_.n_user_columns(user)
    first_user = N_SUMS

    # Cached on disk when the oscillator and every user observable are built in (their code is
    # the package's: observables_.builtin_key), else compiled in memory once per process.
    builtin = not user or observables_.builtin_key(user) is not None
    users = observables_.builtin_key(user) or observables_.user_key(user)

    @numba.njit(nogil=True, cache=spec.oscillator.builtin and builtin, error_model="numpy")
    @own_index(f"{spec.oscillator.name}/{spec.coupling}/{observables_.TABLE_KEY}/{users}")
    def accumulate(b_lo, b_hi, x, Omega, xi, t, status, tracks, omega2, q, batch_size, edges, sums,
                   hist):  # pragma: no cover - compiled
        n_paths = x.shape[0]
        n_edges = edges.shape[0]
        for b in range(b_lo, b_hi):
            for c in range(sums.shape[1]):
                sums[b, c] = 0.0
            for c in range(hist.shape[1]):
                hist[b, c] = 0
            start = b * batch_size
            stop = min(start + batch_size, n_paths)
            for i in range(start, stop):
                if status[i] != 0:
                    sums[b, S_NONFINITE] += 1.0
                    continue
                ok, E, values = path_values(np.float64(x[i]), np.float64(Omega[i]), omega2, q)
                mine = user_values(np.float64(x[i]), np.float64(Omega[i]), np.float64(xi[i]), t[i],
                                   tracks, i, omega2, q)
                for c in range(n_user):
                    ok = ok and math.isfinite(mine[c])
                if not ok:
                    status[i] = 1
                    sums[b, S_NONFINITE] += 1.0
                    continue
                sums[b, S_COUNT] += 1.0
                for c in range(n_values):
                    sums[b, 1 + c] += values[c]
                for c in range(n_user):
                    sums[b, first_user + c] += mine[c]
                if E < edges[0]:
                    hist[b, 0] += 1
                elif E >= edges[n_edges - 1]:
                    hist[b, n_edges] += 1
                else:
                    hist[b, np.searchsorted(edges, E, side="right")] += 1

    return _ranges(accumulate, items=10)  # the batches, rows of sums


@register_jitable
def _power(d: float, e: int) -> float:  # pragma: no cover - compiled
    """d**e for a small e >= 0, by multiplication (a product's last bits fixed)."""
    out = 1.0
    for _ in range(e):
        out *= d
    return out


def difference_kernel(spec: KernelSpec, observables: tuple[str, ...] = (), products: bool = False):
    """``differences(x, Omega, xf, Omegaf, xi, t, status, tracks, tracks_f, omega2, q, out)``: over the
    pairs whose ``status`` is 0 (both members finite, after the accumulate kernel marked the
    rest), the raw power sums of each summed value's difference between the fine and the coarse
    member, d = v(xf, Omegaf) - v(x, Omega): ``out[k, c]`` += sum d_c**(k + 1), k = 0..3, for the
    columns c of the run's sums (:func:`accumulate_kernel`'s: the statistics table's
    :data:`stochpend.observables.SUMS` from column 1, then the user ``observables``' from
    N_SUMS, each member's value computed as the accumulate kernel computes it, with the pair's
    shared ``xi`` and ``t`` and each member's accumulators' slots, ``tracks`` the coarse
    member's and ``tracks_f`` the fine one's), and ``out[:, 0]`` += the pairs summed; with
    ``products``, after the run's columns, ``out[k, n_sums + j]`` += the products of the differences of the columns
    :data:`stochpend.model.power_sums.CROSS` of degree k + 1 with the exponents
    ``CROSS_MONOMIALS[k][j]`` (the skewness's and flatness's linearised differences), then for
    each running sum among ``observables`` (in their order) the products of the differences of
    its two columns (S and S^2) with the exponents ``power_sums.SUM_MONOMIALS[k][j]``, from
    ``n_sums + N_CROSS + N_SUM_PRODUCTS * r`` (its variance's and diffusion's). For the
    kurtosis of a multilevel estimator's level differences (Giles' diagnostic,
    :mod:`stochpend.runs.multilevel`). ``out``: (4, n_sums), with ``products`` (4, n_sums +
    ``power_sums.product_columns(observables)``), float64. Float64; depends on the oscillator,
    the coupling and the user observables. The products cost more than the rest (92 ns a pair
    without them, 165 to 313 ns with, one thread, 2e6 pairs, measured before the running sums'
    were added): only a target on the skewness, the flatness or a running sum's variance or
    diffusion asks for them."""
    return _difference_kernel(spec, observables_.objects(observables), bool(products))


@functools.cache
def _difference_kernel(spec: KernelSpec, user: tuple, PRODUCTS: bool):
    path_values = integrator.statistics(spec.oscillator, spec.coupling)
    user_values = observables_.user_values(user, spec.oscillator)
    n_values = len(observables_.SUMS)
    n_user = observables_.n_user_columns(user)
    first_user = N_SUMS
    # Cached on disk as the accumulate kernel is (its reasons: _accumulate_kernel).
    builtin = not user or observables_.builtin_key(user) is not None
    users = observables_.builtin_key(user) or observables_.user_key(user)
    n_sums = N_SUMS + n_user
    cross = np.array([c - 1 for c in power_sums.CROSS], dtype=np.int64)  # indices of the values
    n_products = np.array([len(m) for m in power_sums.CROSS_MONOMIALS], dtype=np.int64)
    exponents = np.zeros((4, power_sums.N_CROSS, 3), dtype=np.int64)
    for k, monomials in enumerate(power_sums.CROSS_MONOMIALS):
        exponents[k, :len(monomials)] = monomials
    # Each running sum's first user column (its sum; its square the next), for its products.
    starts = np.cumsum([0] + [observables_._columns(o) for o in user])
    sum_columns = np.array([starts[j] for j, o in enumerate(user) if isinstance(o, observables_.RunningSum)],
                           dtype=np.int64)
    n_running = len(sum_columns)
    first_sum_product = n_sums + power_sums.N_CROSS

    @numba.njit(nogil=True, cache=spec.oscillator.builtin and builtin, error_model="numpy")
    @own_index(f"differences/{spec.oscillator.name}/{spec.coupling}/{observables_.TABLE_KEY}/{users}"
               f"/{'products' if PRODUCTS else 'powers'}")
    def differences(x, Omega, xf, Omegaf, xi, t, status, tracks, tracks_f, omega2, q, out):  # pragma: no cover
        for i in range(x.shape[0]):
            if status[i] != 0:
                continue
            ok_c, _, vc = path_values(np.float64(x[i]), np.float64(Omega[i]), omega2, q)
            ok_f, _, vf = path_values(np.float64(xf[i]), np.float64(Omegaf[i]), omega2, q)
            if not (ok_c and ok_f):
                continue
            uc = user_values(np.float64(x[i]), np.float64(Omega[i]), np.float64(xi[i]), t[i], tracks, i,
                             omega2, q)
            uf = user_values(np.float64(xf[i]), np.float64(Omegaf[i]), np.float64(xi[i]), t[i], tracks_f, i,
                             omega2, q)
            for k in range(4):
                out[k, 0] += 1.0
            for c in range(n_values):
                d = vf[c] - vc[c]
                d2 = d * d
                out[0, 1 + c] += d
                out[1, 1 + c] += d2
                out[2, 1 + c] += d2 * d
                out[3, 1 + c] += d2 * d2
            for c in range(n_user):
                d = uf[c] - uc[c]
                d2 = d * d
                out[0, first_user + c] += d
                out[1, first_user + c] += d2
                out[2, first_user + c] += d2 * d
                out[3, first_user + c] += d2 * d2
            if PRODUCTS:  # a compile-time constant
                d_a = vf[cross[0]] - vc[cross[0]]
                d_b = vf[cross[1]] - vc[cross[1]]
                d_c = vf[cross[2]] - vc[cross[2]]
                for k in range(4):
                    for m in range(n_products[k]):
                        out[k, n_sums + m] += (_power(d_a, exponents[k, m, 0]) * _power(d_b, exponents[k, m, 1])
                                               * _power(d_c, exponents[k, m, 2]))
                for r in range(n_running):  # a running sum's S and S^2 (SUM_MONOMIALS' order)
                    d_s = uf[sum_columns[r]] - uc[sum_columns[r]]
                    d_q = uf[sum_columns[r] + 1] - uc[sum_columns[r] + 1]
                    first = first_sum_product + power_sums.N_SUM_PRODUCTS * r
                    for k in range(4):
                        for m in range(k + 2):
                            out[k, first + m] += _power(d_s, k + 1 - m) * _power(d_q, m)

    return differences


@functools.cache
def joint_kernel(periodic: bool):
    """``joint(x, Omega, status, batch_size, x_lo, x_hi, nx, O_lo, O_hi, nO, counts)``: the
    joint (x, Omega) histogram of each batch's finite paths (status 0, after ``accumulate``
    marked the escaped ones) at one output time, ``counts`` (n_batches, (nx + 2) (nO + 2))
    int64, overwritten (cells: :mod:`stochpend.engine.joint`); ``periodic``: x is an angle.
    Run only when the run asks for the histogram, after ``accumulate``, which it leaves as it
    was."""
    from stochpend.engine.joint import cell

    @numba.njit(nogil=True, cache=True, error_model="numpy")
    @own_index(f"joint/{periodic}")
    def joint(b_lo, b_hi, x, Omega, status, batch_size, x_lo, x_hi, nx, O_lo, O_hi, nO,
              counts):  # pragma: no cover - compiled
        n_paths = x.shape[0]
        for b in range(b_lo, b_hi):
            for c in range(counts.shape[1]):
                counts[b, c] = 0
            for i in range(b * batch_size, min((b + 1) * batch_size, n_paths)):
                if status[i] == 0:
                    counts[b, cell(np.float64(x[i]), np.float64(Omega[i]), periodic, x_lo, x_hi, nx,
                                   O_lo, O_hi, nO)] += 1

    return _ranges(joint, items=10)  # the batches, rows of counts


def joint_sums(counts: np.ndarray, n_b: np.ndarray, out: np.ndarray) -> None:
    """Into ``out`` (3 * cells,): the per-batch ``counts`` (n_batches, cells) summed, their
    squares summed, and their products with the batches' finite paths ``n_b`` summed (the
    joint histogram's errors: :meth:`stochpend.model.power_sums.EnsembleSums.joint`). Integers: exact."""
    cells = counts.shape[1]
    out[:cells] = counts.sum(axis=0)
    out[cells:2 * cells] = (counts * counts).sum(axis=0)
    out[2 * cells:] = (counts * n_b.astype(np.int64)[:, None]).sum(axis=0)


def compiled_kernels(spec: KernelSpec, *, pairs: bool = True, observables: tuple[str, ...] = ()) -> dict[str, object]:
    """The Numba dispatchers a run of ``spec`` calls, by kind (``resources.COMPILE_S``):
    ``init``, ``advance``, ``accumulate`` and, with ``pairs`` (the bias estimate), ``pairs``;
    ``advance_one_path`` and ``pairs_one_path`` for a KernelSpec without a SIMD driver, and
    ``advance_one_path`` (:func:`tracked_kernel`) for a run with per-path accumulators among its
    ``observables`` (whose ``accumulate`` kernel is theirs too). Nothing is compiled here."""
    accs = observables_.accumulators(observables_.objects(observables))
    one_path = advance_kernel(spec) is path_kernel(spec)  # no SIMD driver: less to compile
    suffix = "_one_path" if one_path else ""
    out = {"init": init_kernel(spec), "accumulate": accumulate_kernel(spec, observables)}
    if accs:  # in lanes when the KernelSpec has them, as advance_kernel is
        out["advance" + suffix] = tracked_kernel(spec, accs)
    else:
        out["advance" + suffix] = advance_kernel(spec)
    if pairs:
        out["pairs" + suffix] = pair_advance_kernel(spec)
    return {kind: getattr(kernel, "kernel", kernel) for kind, kernel in out.items()}


def kernels(spec: KernelSpec) -> SimpleNamespace:
    """``init``, ``advance`` and ``accumulate`` for ``spec`` (compiled on first call)."""
    return SimpleNamespace(init=init_kernel(spec), advance=advance_kernel(spec),
                           accumulate=accumulate_kernel(spec), spec=spec)


class Engine:
    """One chunk of paths in host memory, advanced by the CPU kernels (for ``runner``)."""

    name = "cpu"
    # The chunk's per-path arrays, allocated from layout.path_dtypes (see _allocate).
    x: np.ndarray
    Omega: np.ndarray
    xi: np.ndarray
    xi_aux: np.ndarray
    t: np.ndarray
    t_comp: np.ndarray
    k: np.ndarray
    status: np.ndarray

    def __init__(self, config, spec: KernelSpec, capacity: int, n_chunk_batches: int) -> None:
        self.config = config
        self.spec = spec
        self.kernels = kernels(spec)
        self.kernels.accumulate = accumulate_kernel(spec, config.observables)
        # Per-path accumulators (stochpend.observables): their slots ride with the state, and
        # the paths go one at a time through the integrator's step loop with tracking.
        self.accs = observables_.accumulators(observables_.objects(config.observables))
        if self.accs:
            self.kernels.advance = tracked_kernel(spec, self.accs)
        self.key0, self.key1 = config.keys.main
        self.record = spec.noise.record(config)
        self.step_rec = integrator.step_record(config)
        # The additive channel's per-path arrays (xi_a, aux_a), after the others in the state:
        # only for a run with a coloured additive noise.
        self.additive = dynamics.additive_arrays(config)
        # The kernels' state tuple, by name (stochpend.engine.layout).
        self.layout = layout.state_arrays(1, tracked=bool(self.accs), channel=bool(self.additive))
        self.n_times = len(config.times)
        self.n_e = config.hist_bins + 2  # the energy histogram's columns
        self.n_cols = settings.hist_columns(config)
        self.hist = np.empty((n_chunk_batches, self.n_e), dtype=np.int64)
        # The joint (x, Omega) histogram, when the run asks for it (settings.joint_grid).
        self.joint_grid = settings.joint_grid(config)
        if self.joint_grid is not None:
            self.joint = joint_kernel(spec.oscillator.periodic)
            self.joint_counts = np.empty((n_chunk_batches, settings.joint_cells(config)), dtype=np.int64)
        self.p0 = 0
        self.n = 0
        self._buffers: dict[str, np.ndarray] | None = None

    @staticmethod
    def default_chunk_paths(precision: str) -> int:
        return DEFAULT_CHUNK_PATHS

    def _allocate(self, n: int, nb: int) -> None:
        # The per-path arrays are views of buffers allocated once per engine: a fresh array a
        # chunk is fresh pages from the kernel, and their first touch (in init) cost about
        # 30 ns a path, a quarter of a five-step path's whole cost (issue 35, level 0). A view
        # is only ever read through this chunk: a checkpoint writes the arrays when pulled.
        dtypes = path_dtypes("cpu", "float64")
        if self._buffers is None or self._buffers["x"].shape[0] < n:
            self._buffers = {name: np.empty(n, dtype=dtype) for name, dtype in dtypes.items()}
        for name in dtypes:
            setattr(self, name, self._buffers[name][:n])
        for name in ("xi_a", "aux_a"):  # only for a run with the additive channel's state
            if name not in self.additive:
                setattr(self, name, np.empty(0))
        self.tracks = np.empty((len(self.accs), n))
        self.chunk_sums = np.zeros((nb, self.n_times, observables_.n_sums(self.config)))
        self.chunk_hist = np.zeros((self.n_times, self.n_cols), dtype=np.int64)

    def start(self, p0: int, n: int, nb: int) -> None:
        """Initial conditions of global paths p0 .. p0 + n - 1 (batches: nb)."""
        c = self.config
        self.p0, self.n, self.nb = p0, n, nb
        self._allocate(n, nb)
        # path0 as uint64, as the bias estimate's pairs pass theirs (from 2**63): one compiled
        # init for both (path0 + i is the same uint64 either way).
        self.kernels.init(self.state(), self.key0, self.key1, _U64(p0),
                          0.0 if c.theta0 is None else c.theta0, c.theta0 is None, c.Omega0,
                          0.0 if c.xi0 is None else c.xi0, c.xi0 is None, self.record)
        self.tracks[:] = observables_.track_initial(self.accs)
        if initial.temperature(c) > 0.0:  # the Boltzmann law (stochpend.model.initial), on the host
            self.x[:], self.Omega[:] = initial.boltzmann(c, p0, n)
        # The additive channel's start, its stationary law (stochpend.model.initial).
        for name, value in zip(self.additive, initial.additive_states(c, p0, n), strict=True):
            getattr(self, name)[:] = value

    def load(self, p0: int, arrays: dict[str, np.ndarray]) -> None:
        """Continue a chunk from host arrays (a checkpoint's RunState fields)."""
        self.p0 = p0
        self.n = arrays["x"].shape[0]
        self.nb = arrays["chunk_sums"].shape[0]
        for name, value in arrays.items():
            setattr(self, name, value)
        if arrays.get("tracks") is None:
            self.tracks = np.empty((0, self.n))
        for name in ("xi_a", "aux_a"):
            if arrays.get(name) is None:
                setattr(self, name, np.empty(0))

    def max_steps(self) -> int:
        return max(MIN_STEPS_PER_CALL, WORK_PER_CALL // max(self.n, 1))

    def state(self) -> tuple[np.ndarray, ...]:
        """The chunk's arrays as the kernels take them, in the order of ``self.layout``
        (:func:`stochpend.engine.layout.state_arrays`: x, Omega, xi, xi_aux, t, t_comp, k,
        status, then the accumulators' slots ``tracks`` for a run with accumulators and the
        additive channel's ``xi_a, aux_a`` for a run with it)."""
        return tuple(getattr(self, name) for name in self.layout)

    def advance(self, t_target: float, max_steps: int) -> bool:
        _, unfinished = self.kernels.advance(self.state(), t_target, max_steps, self.key0,
                                             self.key1, self.p0, self.record, self.step_rec)
        return unfinished == 0

    def time_sum(self, t_target: float, done: bool) -> float:
        return float(np.sum(self.t))

    def accumulate(self, j: int, edges_j: np.ndarray) -> None:
        c = self.config
        nb = self.nb
        self.kernels.accumulate(self.x, self.Omega, self.xi, self.t, self.status, self.tracks, c.omega**2, self.step_rec[integrator.STEP_Q],
                                c.batch_size, edges_j, self.chunk_sums[:, j, :], self.hist[:nb])
        self.chunk_hist[j, :self.n_e] = self.hist[:nb].sum(axis=0)
        if self.joint_grid is not None:
            x_edges, O_edges = self.joint_grid
            nx, nO = c.joint_bins
            self.joint(self.x, self.Omega, self.status, c.batch_size, float(x_edges[j, 0]), float(x_edges[j, -1]),
                       nx, float(O_edges[j, 0]), float(O_edges[j, -1]), nO, self.joint_counts[:nb])
            joint_sums(self.joint_counts[:nb], self.chunk_sums[:, j, S_COUNT], self.chunk_hist[j, self.n_e:])

    def steps(self) -> int:
        return int(np.sum(self.k, dtype=np.uint64))

    def arrays(self) -> dict[str, np.ndarray]:
        """The chunk's live arrays (no copy): what a checkpoint holds."""
        return {name: getattr(self, name) for name in CHUNK_ARRAYS}

    def results(self) -> tuple[np.ndarray, np.ndarray]:
        """The finished chunk's per-batch sums and histogram."""
        return self.chunk_sums, self.chunk_hist

    def final_tracks(self) -> tuple[np.ndarray, np.ndarray]:
        """The accumulators' slots (n_slots, n) and the status (n,) of the chunk's paths, copies
        (for each path's final first-passage time: stochpend.model.passage)."""
        return self.tracks.copy(), self.status.copy()


#: The histogram edges a level engine gives the run's accumulate kernel: one bin, every energy.
_NO_EDGES = np.array([np.inf])


class LevelEngine:
    """One chunk of ``levels`` coupled members in host memory (for ``runner.run_batches`` with
    ``levels`` > 1: the bias estimate's pairs, a multilevel target's levels): member m steps
    h / 2**m, all driven by one noise path (:func:`levels_kernel`). Pair ``i`` of the chunk is
    global path ``rng.COUPLED_PATH0 + p0 + i`` of the run's seed, streams disjoint from the
    run's paths; each starts as the run's path would (``init_kernel``, the Boltzmann law, the
    additive channel's law), every member at that start.

    Per output time the members' statistics are summed with the run's own accumulate kernel,
    once per member (a cold cache compiles one statistics kernel, not ``levels``), into
    ``(nb, n_times, levels, n_sums)``; a set of members is counted only when every member is:
    one whose moments overflow marks the set non-finite. ``differences``: with 2 members, the
    raw power sums of their differences (:func:`difference_kernel`; 2: and their products) over
    the whole run, added chunk after chunk into one array (the kurtosis of a level's
    differences). A chunk is never checkpointed. Float64 (:func:`stochpend.bias.pair_spec`).

    ``tracked``: every member carries the run's per-path accumulators, each its own slots
    (``tracks[m * n_slots + slot]``, updated after each of its steps: the multilevel target on
    an accumulator's mean), a pair in SIMD lanes where the KernelSpec has them, else one set of
    members at a time (:func:`tracked_levels_kernel`; on CUDA one set a thread,
    ``cuda.tracked_levels_kernel``); a
    noise with events is not accepted (a member's last step would see the noise before its
    jump). Without it the members carry none: the bias estimate has no Richardson estimate
    of an accumulator's statistics (see ``Statistic.richardson``)."""

    name = "cpu"
    #: The accumulators whose final values the runner reads (first passages): never a level's.
    accs: tuple = ()

    def __init__(self, config, spec: KernelSpec, capacity: int, n_chunk_batches: int, *, levels: int,
                 differences: int = 0, tracked: bool = False) -> None:
        if differences and levels != 2:
            raise ValueError(f"differences of levels={levels!r} are not accepted: only of 2 members")
        self.config = config
        self.spec = spec
        self.levels = levels
        self.track_accs = observables_.accumulators(observables_.objects(config.observables)) if tracked else ()
        if self.track_accs:
            if spec.noise.has_events or (spec.additive is not None and spec.additive.has_events):
                raise ValueError(f"noise={spec.noise.name!r} is not accepted for coupled levels with per-path "
                                 "accumulators: its events would come after a member's last step had seen the "
                                 "noise; the noises without events (white, ou, harmonic) are")
            self.init, self.advance_k = init_kernel(spec), self.tracked_kernel(spec, self.track_accs, levels)
        else:
            self.init, self.advance_k = self.kernels(spec, levels)
        # The CPU's accumulate kernel on every backend: the run's own (compiled once for all).
        self.accumulate_k = accumulate_kernel(spec, config.observables)
        self.difference_k = (difference_kernel(spec, config.observables, products=differences >= 2) if differences
                             else None)
        self.key0, self.key1 = config.keys.main
        self.record = spec.noise.record(config)
        self.step_rec = integrator.step_record(config)
        # The kernels' state tuple, by name (stochpend.engine.layout): the members' arrays, the
        # shared noise, clock and status, then the additive channel's (a run with it).
        self.additive = dynamics.additive_arrays(config)
        self.layout = layout.state_arrays(levels, tracked=bool(self.track_accs), channel=bool(self.additive))
        self.n_times = len(config.times)
        self.n_sums = observables_.n_sums(config)
        self.n_tracks = len(observables_.accumulators(observables_.objects(config.observables)))
        width = self.n_sums + (power_sums.product_columns(config.observables) if differences >= 2 else 0)
        self.differences = np.zeros((self.n_times, 4, width)) if differences else None
        self.p0 = 0
        self.n = 0

    @staticmethod
    def kernels(spec: KernelSpec, levels: int) -> tuple[Any, Any]:
        """The backend's init and levels kernels."""
        return init_kernel(spec), levels_kernel(spec, levels)

    @staticmethod
    def tracked_kernel(spec: KernelSpec, accs: tuple, levels: int) -> Any:
        """The backend's levels kernel with every member's accumulators."""
        return tracked_levels_kernel(spec, accs, levels)

    @staticmethod
    def default_chunk_paths(precision: str) -> int:
        return 1 << 18

    def empty_sums(self) -> LevelSums:
        """The run's zeroed accumulator (``runner.run_batches`` adds each chunk's results)."""
        return LevelSums.empty(self.config.n_batches, self.n_times, self.levels, self.n_sums)

    def start(self, p0: int, n: int, nb: int) -> None:
        """The start of sets ``p0 .. p0 + n - 1`` (batches: nb): every member at its path's."""
        c = self.config
        self.p0, self.n, self.nb = p0, n, nb
        self.path0 = _U64(rng.COUPLED_PATH0 + p0)
        dtypes = path_dtypes("cpu", "float64")
        self.held = {name: np.empty(n, dtype=dtypes.get(name, dtypes["x"])) for name in self.layout}
        if self.track_accs:  # every member's slots, each from the accumulators' start
            self.held["tracks"] = np.tile(observables_.track_initial(self.track_accs), (self.levels, n))
        self.members = [self.held[name] for name in layout.member_arrays(self.levels)]
        x, Omega = self.members[0], self.members[1]
        self.init(tuple(self.held[name] for name in layout.state_arrays(1)), self.key0,
                  self.key1, self.path0, 0.0 if c.theta0 is None else c.theta0, c.theta0 is None, c.Omega0,
                  0.0 if c.xi0 is None else c.xi0, c.xi0 is None, self.record)
        if initial.temperature(c) > 0.0:  # as the run's paths (stochpend.model.initial)
            x[:], Omega[:] = initial.boltzmann(c, int(self.path0), n)
        # The additive channel's state, shared by the members as xi is (a run with it).
        for name, value in zip(self.additive, initial.additive_states(c, int(self.path0), n), strict=True):
            self.held[name][:] = value
        for m in range(1, self.levels):
            self.members[2 * m][:] = x
            self.members[2 * m + 1][:] = Omega
        self.chunk_sums = np.zeros((nb, self.n_times, self.levels, self.n_sums))

    def load(self, p0: int, arrays: dict[str, np.ndarray]) -> None:
        raise NotImplementedError("coupled levels are not checkpointed")

    def max_steps(self) -> int:
        return max(MIN_STEPS_PER_CALL, WORK_PER_CALL // 2 // max(self.n, 1))

    def state(self) -> tuple[np.ndarray, ...]:
        """The kernels' state tuple, in the order of ``self.layout``
        (:func:`stochpend.engine.layout.state_arrays` of the members)."""
        return tuple(self.held[name] for name in self.layout)

    def advance(self, t_target: float, max_steps: int) -> bool:
        _, unfinished = self.advance_k(self.state(), t_target, max_steps, self.key0, self.key1,
                                       self.path0, self.record, self.step_rec)
        return unfinished == 0

    def time_sum(self, t_target: float, done: bool) -> float:
        return float(np.sum(self.held["t"]))

    def host_members(self) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
        """The members' (x, Omega) arrays, xi, t and status, on the host."""
        return self.members, self.held["xi"], self.held["t"], self.held["status"]

    def put_status(self, status: np.ndarray) -> None:
        """The status the accumulate kernel marked, back where the kernels read it."""

    def accumulate(self, j: int, edges_j: np.ndarray) -> None:
        """The members' sums at output time j: member 0 (marking the sets whose member 0
        overflows), each finer member (marking its own), and, only when a finer member marked a
        set, the members before the last again, without it: each sum in path order, as the
        run's are."""
        c = self.config
        members, xi, t, status = self.host_members()
        hist = np.zeros((self.nb, 2), dtype=np.int64)  # the kernel counts energies; not used
        tracks = self.member_tracks()
        q = self.step_rec[integrator.STEP_Q]
        sums = self.chunk_sums[:, j]

        def add(m: int) -> None:
            self.accumulate_k(members[2 * m], members[2 * m + 1], xi, t, status, tracks[m], c.omega**2, q,
                              c.batch_size, _NO_EDGES, sums[:, m], hist)

        add(0)
        marked = np.count_nonzero(status)
        for m in range(1, self.levels):
            add(m)
        if np.count_nonzero(status) != marked:
            for m in range(self.levels - 1):
                add(m)
        self.put_status(status)  # sets whose moments overflowed stay excluded
        if self.difference_k is not None and self.differences is not None:
            self.difference_k(members[0], members[1], members[2], members[3], xi, t, status, tracks[0],
                              tracks[1], c.omega**2, q, self.differences[j])

    def member_tracks(self) -> list[np.ndarray]:
        """Each member's accumulators' slots (n_slots, n), on the host; zeros where the members
        carry none (the accumulate kernel reads them for the run's accumulator columns, which
        then hold 0)."""
        if not self.track_accs:
            return [np.zeros((self.n_tracks, self.n))] * self.levels
        n = len(self.track_accs)
        tracks = self.host_tracks()
        return [tracks[m * n:(m + 1) * n] for m in range(self.levels)]

    def host_tracks(self) -> np.ndarray:
        """Every member's accumulators' slots (levels * n_slots, n), on the host."""
        return self.held["tracks"]

    def steps(self) -> int:
        """The finest member's draws (each of its steps one; member m takes 2**(m + 1 - levels)
        as many steps)."""
        return int(np.sum(self.held["k"], dtype=np.uint64))

    def arrays(self) -> dict[str, np.ndarray]:
        raise NotImplementedError("coupled levels are not checkpointed")

    def results(self) -> tuple[np.ndarray, np.ndarray | None]:
        """The finished chunk's per-batch sums and the run's differences so far."""
        return self.chunk_sums, self.differences

    def final_tracks(self) -> tuple[np.ndarray, np.ndarray]:
        raise NotImplementedError("coupled levels carry no per-path accumulators")
