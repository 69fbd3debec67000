"""The CPU's SIMD lane machine (``integrator.build_lanes``, the default CPU path).

Each lane carries one path with its own time, step, coefficients and Philox counter; lanes
are refilled as paths finish. Its arithmetic is ``advance_path``'s with the same fast-math
KernelSpec, so every test here is bit for bit: against the one-path kernel of that KernelSpec
(``cpu.path_kernel``), and against itself across call splits, thread counts, chunks and
neighbours. (The fast-math KernelSpec against the C library's math is statistical:
tests/statistical/test_simd_agreement.py.)
"""

from __future__ import annotations

import types

import numba
import numpy as np
import pytest

from stochpend.engine import cpu, integrator
from tests._kernels import Paths

FIELDS = ("x", "Omega", "xi", "xi_aux", "t", "t_comp", "k", "status")
TIMES = (0.3, 1.0, 2.5)


def _kernels(noise, adaptive, driver):
    spec = integrator.spec(noise, adaptive=adaptive, fast_math=True)
    kern = cpu.kernels(spec)
    if driver == "lanes":
        assert integrator.lanes_supported(spec) and kern.advance is not cpu.path_kernel(spec)
        return kern
    return types.SimpleNamespace(init=kern.init, advance=cpu.path_kernel(spec), spec=spec)


def _run(kern, n, *, seed=11, max_steps=37, path0=0, D=4.0, h_max=0.05, step_c=0.1,
         omega2=1.0, setup=None, threads=None):
    """Paths path0 .. path0 + n - 1 through TIMES, max_steps a call; returns the arrays and
    every call's (steps, unfinished)."""
    p = Paths(n).init(kern, seed, path0=path0, D=D)
    if setup is not None:
        setup(p)
    calls = []
    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    try:
        for t_target in TIMES:
            while True:
                s, u = p.advance(kern, t_target, max_steps, seed, path0=path0, D=D, h_max=h_max,
                                 step_c=step_c, omega2=omega2)
                calls.append((int(s), int(u)))
                if u == 0:
                    break
    finally:
        numba.set_num_threads(previous)
    return {name: getattr(p, name).copy() for name in FIELDS}, calls


def _assert_same(a, b, keep=slice(None)):
    for name in FIELDS:
        np.testing.assert_array_equal(a[name][keep], b[name][keep], err_msg=name)


@pytest.mark.parametrize("noise", ["ou", "white"])
@pytest.mark.parametrize("adaptive", [True, False])
@pytest.mark.parametrize("n", [7, 130])
def test_lanes_are_the_one_path_numbers(noise, adaptive, n):
    """Same states, times, clock compensations, step counts and per-call (steps, unfinished)
    as advance_path one path at a time; 7 paths leave most lanes idle, 130 refill them; the
    calls end mid-segment (max_steps = 37) and land on three output times."""
    a, calls_a = _run(_kernels(noise, adaptive, "lanes"), n)
    b, calls_b = _run(_kernels(noise, adaptive, "paths"), n)
    _assert_same(a, b)
    assert calls_a == calls_b
    assert np.all(a["t"] == TIMES[-1]) and np.all(a["status"] == 0)
    if adaptive:  # the paths took different numbers of steps: the lanes were not in lock step
        assert a["k"].min() < a["k"].max()


def test_lane_numbers_do_not_depend_on_threads_chunks_calls_or_neighbours():
    """A path's numbers are a function of (seed, path): 1 or 2 threads, one chunk or two
    (different lane neighbours), one call per segment or many, frozen neighbours."""
    kern = _kernels("ou", True, "lanes")
    ref, _ = _run(kern, 200, threads=1)
    two, _ = _run(kern, 200, threads=2)
    _assert_same(ref, two)
    whole, _ = _run(kern, 200, max_steps=10**9)
    _assert_same(ref, whole)
    lo, _ = _run(kern, 77)
    hi, _ = _run(kern, 123, path0=77)
    for name in FIELDS:
        np.testing.assert_array_equal(ref[name], np.concatenate([lo[name], hi[name]]), err_msg=name)
    frozen = [3, 40, 41, 150]

    def freeze(p):
        p.status[frozen] = 1

    some, _ = _run(kern, 200, setup=freeze)
    keep = np.ones(200, dtype=bool)
    keep[frozen] = False
    _assert_same(ref, some, keep)
    assert np.all(some["k"][frozen] == 0) and np.all(some["t"][frozen] == 0.0)


def test_escaped_and_nonfinite_lanes_are_frozen_as_one_path():
    """A path whose step control asks for less than ESCAPE_STEP_FRACTION h_max (|Omega| far
    beyond c / h_max), or whose state turns non-finite, gets status 1 and is never advanced
    again, exactly as advance_path does; its neighbours go on."""
    def inject(p):
        p.Omega[[5, 70]] = 3e9  # h = c/|Omega| < 1e-9 h_max: escapes before its first step
        p.Omega[9] = np.inf  # h = 0: escapes
        p.xi[[20, 100]] = np.nan  # the first step gives a non-finite state

    a, calls_a = _run(_kernels("ou", True, "lanes"), 130, setup=inject)
    b, calls_b = _run(_kernels("ou", True, "paths"), 130, setup=inject)
    _assert_same(a, b)
    assert calls_a == calls_b
    bad = np.zeros(130, dtype=bool)
    bad[[5, 9, 20, 70, 100]] = True
    np.testing.assert_array_equal(a["status"], bad.astype(np.uint8))
    assert np.all(a["k"][[5, 9, 70]] == 0) and np.all(a["k"][[20, 100]] == 1)
    assert np.all(a["t"][~bad] == TIMES[-1])


def test_lane_machine_refuses_a_spec_it_cannot_run():
    for spec in (integrator.spec("ou"), integrator.spec("dichotomous", fast_math=True),
                 integrator.spec("harmonic", fast_math=True)):
        assert not integrator.lanes_supported(spec)
        with pytest.raises(ValueError, match="lanes_supported"):
            integrator.build_lanes(spec)


@pytest.mark.parametrize("driver", ["lanes", "paths"])
def test_the_pool_only_runs_kernels_compiled_on_the_calling_thread(monkeypatch, driver):
    """A Ctrl-C while a kernel compiles ends the call at once only if the compile runs on the
    calling thread (the pool's threads cannot be interrupted, and the caller waits for them):
    CI's Ctrl-C test once waited over 60 s for a pool thread's cold compile. Every submission
    to the pool finds the kernel compiled, for the very signature the call dispatches to (one
    overload: no second compile)."""
    spec = integrator.spec("ou", adaptive=True, fast_math=True)
    if driver == "lanes":
        kernel = cpu._lanes_kernel(spec)  # a new dispatcher: nothing compiled in this process
        advance = cpu._with_workers(kernel, (integrator.LANE_F_ROWS, integrator.LANE_COUNT),
                                    (integrator.LANE_U_ROWS, integrator.LANE_COUNT),
                                    (integrator.LANE_I_ROWS, integrator.LANE_COUNT))
    else:
        advance = cpu._one_at_a_time(integrator.build(spec).advance_path, None, False, 1)
        kernel = advance.kernel
    assert not kernel.overloads
    seen = []
    pool = cpu._pool()

    class Watching:
        def submit(self, fn, *args):
            seen.append(len(kernel.overloads))
            return pool.submit(fn, *args)

    kern = types.SimpleNamespace(init=cpu.kernels(spec).init, advance=advance, spec=spec)
    # watched from after the paths' initialisation (a kernel of its own) on
    _run(kern, 130, threads=2, setup=lambda p: monkeypatch.setattr(cpu, "_pool", Watching))
    assert seen and set(seen) == {1}, seen
    assert len(kernel.overloads) == 1


def test_ctrl_c_in_the_callers_share_stops_the_other_workers_taking_pieces():
    """On an exception in worker 0 (the caller's thread: Ctrl-C), ``_on_workers`` calls ``stop``
    before it waits, so the pool's workers finish the piece under way and take no more: the
    wait is for one piece, not for the rest of the call."""
    import time

    next_piece, taken, pieces = np.zeros(1, dtype=np.int64), [], 1000

    def call(w):
        if w == 0:
            time.sleep(0.05)
            raise KeyboardInterrupt
        while True:
            piece = int(next_piece[0])  # the GIL makes this read-and-add atomic enough here
            next_piece[0] += 1
            if piece >= pieces:
                return None
            taken.append(piece)
            time.sleep(0.01)

    with pytest.raises(KeyboardInterrupt):
        cpu._on_workers(call, 2, stop=lambda: next_piece.fill(cpu._NO_MORE_PIECES))
    assert 0 < len(taken) < pieces // 10, len(taken)


def test_lanes_carry_accumulators_with_the_one_path_numbers():
    """A run with per-path accumulators in the lanes (``cpu.tracked_kernel``: each lane carries
    its path's slots, updated after every step taken that stays finite) against one path at a
    time (``cpu.tracked_path_kernel``), bit for bit: the state and every slot (the displacement,
    a time average over a window from an output time, a first passage, a running sum), the
    per-call counts; escaped and non-finite paths keep the slots of their last good step;
    lanes refilled, calls ended mid-segment; the state is the untracked lanes' state."""
    import math

    from stochpend.model import observables
    from stochpend.model.observables import FirstPassage, RunningSum, TimeAverage

    accs = (*observables.objects(("displacement",)),
            TimeAverage("e_late", lambda x, Omega, xi, t: 0.5 * Omega * Omega - math.cos(x), window=(1.0, 2.5)),
            FirstPassage("up", lambda x, Omega, xi, t: Omega, threshold=1.2),
            RunningSum("work", lambda x0, O0, xi0, x1, O1, xi1, t0, t1: 0.5 * (t1 - t0) * (xi0 * O0 + xi1 * O1)))
    spec = integrator.spec("ou", adaptive=True, fast_math=True)
    initial = observables.track_initial(accs)
    runs = []
    for kernel in (cpu.tracked_kernel(spec, accs), cpu.tracked_path_kernel(spec, accs)):
        tracks = np.tile(initial, (1, 130))

        def carry(p, tracks=tracks, kernel=kernel):
            p.Omega[[5, 70]] = 3e9  # escapes before its first step
            p.xi[[20, 100]] = np.nan  # the first step is non-finite
            p.arrays = lambda: (p.x, p.Omega, p.xi, p.xi_aux, p.t, p.t_comp, p.k, p.status, tracks)

        kern = types.SimpleNamespace(init=cpu.init_kernel(spec), advance=kernel, spec=spec)
        state, calls = _run(kern, 130, setup=carry)
        runs.append((state, calls, tracks))
    (a, calls_a, tracks_a), (b, calls_b, tracks_b) = runs
    assert "_lanes_kernel" in cpu.tracked_kernel(spec, accs).kernel.py_func.__qualname__
    _assert_same(a, b)
    assert calls_a == calls_b
    np.testing.assert_array_equal(tracks_a, tracks_b)
    bad = np.zeros(130, dtype=bool)
    bad[[5, 20, 70, 100]] = True
    np.testing.assert_array_equal(tracks_a[:, bad], np.tile(initial, (1, 4)))  # no good step
    assert np.all(np.isfinite(tracks_a[[0, 1, 3]][:, ~bad]))
    passed = tracks_a[2, ~bad] >= 0.0
    assert 0 < passed.sum() < passed.size  # some passed, some not: both branches ran in lanes
    plain, _ = _run(_kernels("ou", True, "lanes"), 130,
                    setup=lambda p: (p.Omega.__setitem__([5, 70], 3e9), p.xi.__setitem__([20, 100], np.nan)))
    _assert_same(a, plain)


def _many_rows(o0, o1, o2, o3, o4, o5, o6, o7, o8, o9, o10, o11, a, b, c, d, e, f, g, h):  # pragma: no cover
    for i in range(a.shape[0]):
        u = a[i] * b[i] + c[i]
        v = d[i] * e[i] - f[i]
        w = g[i] + h[i]
        o0[i] = u
        o1[i] = v
        o2[i] = w
        o3[i] = u * v
        o4[i] = v * w
        o5[i] = u * w
        o6[i] = u + v
        o7[i] = v + w
        o8[i] = u - w
        o9[i] = u * u
        o10[i] = v * v
        o11[i] = w * w


def test_wide_alias_checks_let_llvm_vectorize_a_loop_over_many_rows_and_only_that_compile():
    """``cpu._wide_alias_checks``, around the tracked pair lanes' compile: a loop writing 12
    arrays and reading 8 needs more runtime alias checks than LLVM allows by default, so
    compiled plainly it has no vector of doubles in its LLVM IR; compiled through the wrapper it
    has; and a plain compile after it has none again (the limit set back, not left raised for
    every later compile in the process). The tracked pair lanes compile through it."""
    import re

    rows = [np.zeros(64) for _ in range(20)]
    vector = re.compile(r"<\d+ x double>")

    def ir(dispatcher):
        dispatcher(*rows)
        return "\n".join(dispatcher.inspect_llvm().values())

    assert not vector.search(ir(numba.njit(_many_rows)))
    assert vector.search(ir(cpu._wide_alias_checks(numba.njit(_many_rows))))
    assert not vector.search(ir(numba.njit(_many_rows)))
    from stochpend.model import observables

    spec = integrator.spec("ou", adaptive=True, fast_math=True)
    kernel = cpu.tracked_levels_kernel(spec, observables.objects(("displacement",)), 2).kernel
    assert kernel.compile.__qualname__.startswith("_wide_alias_checks")
