"""Coupled levels (issue 33, item 2): L members at steps h, h/2, ..., h/2**(L-1) driven by one
noise path (``integrator.build(spec).advance_levels[L]``; the CPU's ``cpu.levels_kernel``, the
CUDA backend's ``cuda.levels_kernel``).

Each member must be a single run at its own step fed the summed noise increments. The reference
here is that run written plainly: per coarse step it draws the finest member's ``2**(L-1)``
exact noise steps (the integrator's per-draw leaves ``noise_step``, ``additive_step``,
``ou_step``, ``channel_step``) into arrays, and member m takes its ``2**m`` steps of
h/2**m (the integrator's ``verlet`` or ``family_step``) with the increments summed two by two, finest
first: the sum a member uses is the sum of its two halves' sums. Bit for bit: a sequential sum
(((I1 + I2) + I3) + I4) would differ from ((I1 + I2) + (I3 + I4)) in the last bits, and the
sub-steps' start times are composed as the halvings compose them (t + h/2 + h/4), not t + 3h/4
(which can round differently; only the drive's and the parametric term's phases read them).
"""

from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numba
import numpy as np
import pytest

from stochpend.engine import cpu, integrator, layout
from stochpend.engine import cuda as gpu
from stochpend.numerics import rng
from stochpend.numerics.mathlib import LIBM
from tests import _background
from tests.unit import _levels_cudasim as cases

HELPER = Path(__file__).with_name("_levels_cudasim.py")


@numba.njit
def _no_track(tracks, i, m, x0, O0, xi0, x1, O1, xi1, t0, t1):  # pragma: no cover - compiled
    return None


def _reference(spec, track=_no_track):
    """``reference(L, x0, O0, xi0, xa0, xad0, xaa0, t_targets, key0, key1, path0, p, run, tracks)
    -> members (L, 2, n)``: the members of L coupled levels, each advanced as a single run at its
    own step (see the module docstring), from ``state`` (the layout of
    ``integrator.level_positions(L)``). ``track``: each member's accumulators' update after each
    of its steps (``observables.track_step(accs).members``) into ``tracks`` (L * n_slots, n), as
    a single tracked run updates them: from the state, the noise and the time at the step's
    start to those at its end, the noise after the step's last draw, the end the next
    sub-step's start (the clock's time after the coarse step for the last)."""
    b = integrator.build(spec)
    nz = spec.noise.kernel(np.float64, LIBM)
    coefficients = nz.coefficients
    scratch0 = nz.scratch0
    noise_step = b.noise_step
    verlet = b.verlet
    family_step = b.family_step
    step_size = b.step_size
    family_bounds = b.family_bounds
    additive_step = b.additive_step
    additive_sum = b.additive_sum
    channel_step = b.channel_step
    a_coefficients = b.a_coefficients
    a_scratch0 = b.a_scratch0
    ADAPTIVE = spec.adaptive
    FAMILY = bool(spec.terms)
    CHANNEL = "additive_noise" in spec.terms

    @numba.njit
    def reference(L, x0, O0, xi0, xa0, xad0, xaa0, t_targets, key0, key1, path0, p, run, tracks):
        n = x0.shape[0]
        omega2, q, h_max, step_c = run[0], run[1], run[2], run[3]
        d = run[4] if FAMILY else (0.0,)
        if CHANNEL:  # the generic channel's record and key
            pan, kan = run[5], run[6]
        N = 1 << (L - 1)
        out = np.empty((L, 2, n))
        for i in range(n):
            path = np.uint64(path0 + np.uint64(i))
            mx = np.full(L, x0[i])
            mO = np.full(L, O0[i])
            xn, xa, S, xad = xi0[i], xa0[i], scratch0(), xad0[i]
            if CHANNEL:
                xaa, Sa = xaa0[i], a_scratch0()
            tt, tc, kk = 0.0, 0.0, np.uint64(0)
            I = np.empty(N)
            Z = np.empty(N)
            X = np.empty(N)  # the noise after each draw
            for t_target in t_targets:
                last = tt >= t_target
                while not last:
                    h = h_max
                    if ADAPTIVE:
                        h = step_size(mx[0], mO[0], xn, h_max, step_c, omega2, q)
                        if FAMILY:
                            h = family_bounds(h, step_c, d)
                    h_clock, last = integrator.landing_step(tt, h, t_target)
                    t_end, _ = integrator.advance_clock(tt, tc, h_clock, last, t_target)
                    xn_start = xn
                    hf = h_clock / N
                    C = coefficients(hf, p)
                    if CHANNEL:
                        Can = a_coefficients(hf, pan)
                    for j in range(N):  # the finest member's draws, in order
                        n_j = kk + np.uint64(j)
                        I[j], xn, xa, S = noise_step(key0, key1, path, n_j, xn, xa, S, C)
                        X[j] = xn
                        if CHANNEL:
                            Z[j], xad, xaa, Sa = channel_step(kan[0], kan[1], path, n_j, xad, xaa, Sa, Can)
                        else:
                            Z[j], _, _, _ = additive_step(key0, key1, path, n_j, 0.0, 0.0, 0, C)
                    Im, Zm, width = I.copy(), Z.copy(), N
                    for m in range(L - 1, -1, -1):  # finest first; then sum two by two
                        steps = 1 << m
                        hm = h_clock / steps
                        starts = np.empty(steps + 1)
                        starts[steps] = t_end
                        for s_ in range(steps):
                            t0 = tt
                            for bit in range(m):  # t + h/2 + h/4 ... for the bits of s_
                                if (s_ >> (m - 1 - bit)) & 1:
                                    t0 += h_clock / (2 << bit)
                            starts[s_] = t0
                        per = N >> m  # the finest draws in one of member m's steps
                        for s_ in range(steps):
                            t0 = starts[s_]
                            xb, Ob = mx[m], mO[m]
                            if FAMILY:
                                mx[m], mO[m] = family_step(mx[m], mO[m], hm, omega2, Im[s_], q, t0, hm, Zm[s_], d)
                            else:
                                mx[m], mO[m] = verlet(mx[m], mO[m], hm, omega2, Im[s_], q)
                            track(tracks, i, m, xb, Ob, xn_start if s_ == 0 else X[s_ * per - 1], mx[m], mO[m],
                                  X[(s_ + 1) * per - 1], t0, starts[s_ + 1])
                        width //= 2
                        for j in range(width):
                            Zm[j] = additive_sum(Zm[2 * j], Zm[2 * j + 1], hm, d)
                            Im[j] = Im[2 * j] + Im[2 * j + 1]
                    kk += np.uint64(N)
                    tt, tc = integrator.advance_clock(tt, tc, h_clock, last, t_target)
            for m in range(L):
                out[m, 0, i] = mx[m]
                out[m, 1, i] = mO[m]
        return out

    return reference


def _run_cpu(name, levels, kernel=None, state=None):
    cfg = cases.config(name)
    spec = integrator.KernelSpec.of(cfg)
    kernel = kernel or cpu.levels_kernel(spec, levels)
    state = cases.initial_state(cfg, levels) if state is None else state
    key0, key1 = rng.seed_to_key(cfg.seed)
    draws = 0
    for t_target in cases.TIMES:
        while True:
            d, unfinished = kernel(state, t_target, cases.MAX_STEPS, key0, key1, cases.PATH0,
                                   spec.noise.record(cfg), integrator.step_record(cfg))
            draws += d
            if unfinished == 0:
                break
    return state, draws


@pytest.mark.parametrize("name", list(cases.CASES))
def test_each_member_is_a_single_run_at_its_own_step_fed_the_summed_increments(name):
    """L = 2, 3, 4 on the CPU (one path at a time), four Specs (OU with adaptive steps; the
    family's time-dependent terms with the additive white noise, fixed steps; the additive OU
    channel; the generic channel): every member equals the reference to the
    last bit, the noise, clock and draw count too; the members differ (a coupled set, not one
    path L times)."""
    cfg = cases.config(name)
    spec = integrator.KernelSpec.of(cfg)
    reference = _reference(spec)
    key0, key1 = rng.seed_to_key(cfg.seed)
    for levels in cases.LEVELS:
        state, draws = _run_cpu(name, levels)
        start = cases.initial_state(cfg, levels)
        I_XI, _, I_T, _, I_K, I_ST = integrator.level_positions(levels)
        extra = start[I_ST + 1:]  # the additive channel's xi_a (and aux_a)
        xad0 = extra[0] if extra else np.zeros(cases.PATHS)
        xaa0 = extra[1] if len(extra) > 1 else np.zeros(cases.PATHS)
        ref = reference(levels, start[0], start[1], start[I_XI], start[I_XI + 1], xad0, xaa0,
                        np.array(cases.TIMES), key0, key1, cases.PATH0, spec.noise.record(cfg),
                        integrator.step_record(cfg), np.zeros((0, cases.PATHS)))
        for m in range(levels):
            assert np.array_equal(state[2 * m], ref[m, 0]), (name, levels, m)
            assert np.array_equal(state[2 * m + 1], ref[m, 1]), (name, levels, m)
        assert np.all(state[I_T] == cases.TIMES[-1]) and not np.any(state[I_ST])
        assert draws == int(np.sum(state[I_K])) and np.all(state[I_K] % 2 ** (levels - 1) == 0)
        assert not np.array_equal(state[0], state[2 * (levels - 1)])


@pytest.mark.parametrize("name", list(cases.CASES))
def test_each_members_accumulators_are_a_single_tracked_runs_at_its_own_step(name):
    """L = 2 and 3 with per-path accumulators (``cpu.tracked_levels_kernel``, the multilevel
    target on an accumulator's mean): each member's slots are the reference's, the member's
    single run tracked step by step at its own step (its state, the noise after its last draw,
    its sub-steps' times, the landing time at the end), to the last bit; the members' states
    are the untracked kernel's; the members' accumulators differ."""
    from stochpend.model import observables

    cfg = cases.config(name)
    spec = integrator.KernelSpec.of(cfg)
    accs = cases.accumulators()
    ns = len(accs)
    track = observables.track_step(accs)
    reference = _reference(spec, track.members)
    key0, key1 = rng.seed_to_key(cfg.seed)
    for levels in cases.TRACKED_LEVELS:
        plain, _ = _run_cpu(name, levels)
        start = cases.initial_state(cfg, levels)
        I_XI, _, I_T, _, I_K, I_ST = integrator.level_positions(levels)
        initial = np.tile(observables.track_initial(accs), (levels, cases.PATHS))
        state = cases.tracked_state(cfg, levels, accs)  # layout.state_arrays(tracked=True)
        assert layout.state_positions(levels, True, len(start) > I_ST + 2)["tracks"] == I_ST + 1
        state, _ = _run_cpu(name, levels, cpu.tracked_levels_kernel(spec, accs, levels), state)
        extra = start[I_ST + 1:]
        xad0 = extra[0] if extra else np.zeros(cases.PATHS)
        xaa0 = extra[1] if len(extra) > 1 else np.zeros(cases.PATHS)
        ref_tracks = initial.copy()
        ref = reference(levels, start[0], start[1], start[I_XI], start[I_XI + 1], xad0, xaa0,
                        np.array(cases.TIMES), key0, key1, cases.PATH0, spec.noise.record(cfg),
                        integrator.step_record(cfg), ref_tracks)
        for m in range(levels):
            assert np.array_equal(state[2 * m], ref[m, 0]) and np.array_equal(state[2 * m], plain[2 * m])
            assert np.array_equal(state[2 * m + 1], ref[m, 1])
        assert np.array_equal(state[I_ST + 1], ref_tracks), (name, levels)
        assert np.all(np.isfinite(ref_tracks)) and not np.any(state[I_ST])
        assert not np.array_equal(ref_tracks[:ns], ref_tracks[ns:2 * ns])


def _calls(kernel, state, cfg, spec):
    """``state`` advanced through the cases' output times, ``MAX_STEPS`` a call: ``(state, [(draws,
    unfinished) of every call])``."""
    key0, key1 = rng.seed_to_key(cfg.seed)
    calls = []
    for t_target in cases.TIMES:
        while True:
            d, unfinished = kernel(state, t_target, cases.MAX_STEPS, key0, key1, cases.PATH0,
                                   spec.noise.record(cfg), integrator.step_record(cfg))
            calls.append((int(d), int(unfinished)))
            if unfinished == 0:
                break
    return state, calls


@pytest.mark.parametrize("name", list(cases.CASES))
def test_the_simd_lanes_give_every_members_one_path_numbers(name):
    """L = 3, 4 in the CPU's SIMD lanes (``integrator.build_level_lanes``: the step of
    ``the_step`` with keyed draws) against the one-path loop of the same fast-math KernelSpec, bit for
    bit: every array of the state (members, noise, channel, clock, draw count) and the draws
    taken. 40 paths in calls of 7 steps: lanes are refilled, and resumed mid-way. A KernelSpec the
    lanes cannot run (a channel noise without keyed draws) goes one path at a time. (L = 1 and
    2, the run's lanes and the bias pairs', against the one-path loops: test_lanes.py,
    test_bias.py and the family's tests, tests/_lanes.py.) L = 4 for the OU pendulum only: the
    family's and the channel's machines at 4 are those at 3 with one more level of the member
    tree, and each costs about 20 s of compiling (the suite's time, issue 33)."""
    cfg = cases.config(name)
    spec = integrator.KernelSpec.of(cfg, fast_math=True)
    built = integrator.build(spec)
    for levels in ((3, 4) if name == "ou" else (3,)):
        one_path = cpu._one_at_a_time(built.advance_levels[levels], None, False, levels)
        if not integrator.lanes_supported(spec):
            assert name == "channel"  # the harmonic channel noise has no keyed draws
            continue
        lanes_kernel = cpu.levels_kernel(spec, levels)
        assert "_lanes_kernel" in lanes_kernel.kernel.py_func.__qualname__  # the lanes, not a path loop
        (lanes, lane_draws), (one, one_draws) = (_calls(kernel, cases.initial_state(cfg, levels, 40), cfg, spec)
                                                 for kernel in (lanes_kernel, one_path))
        assert lane_draws == one_draws, (name, levels)
        for j, (a, b) in enumerate(zip(lanes, one, strict=True)):
            assert np.array_equal(a, b), (name, levels, j)
        assert not np.array_equal(lanes[0], cases.initial_state(cfg, levels, 40)[0])


@pytest.mark.parametrize("name", ["ou", "family", "additive_ou"])
def test_the_tracked_pair_lanes_give_the_one_path_numbers(name):
    """A pair whose members carry accumulators (the multilevel target on an accumulator's
    mean) in the CPU's SIMD lanes (``cpu.tracked_levels_kernel``: each lane carries both
    members' slots; the fine member's state between its half steps comes out of the lane loop,
    the tracked step's ``mid``) against the tracked one-pair loop of the same fast-math
    KernelSpec, bit for bit: every array of the state, both members' slots, the draws per call.
    40 pairs in calls of 7 steps (lanes refilled and resumed); with step control two escape
    before their first step, and two turn non-finite in it (the one-pair loop has updated their
    slots inside that step, so the lanes do too). The members are the untracked pair lanes'
    members. The OU pendulum, the family's terms with the additive white noise, and the additive
    OU channel (its arrays come after the slots)."""
    from stochpend.model import observables

    cfg = cases.config(name)
    spec = integrator.KernelSpec.of(cfg, fast_math=True)
    accs = cases.accumulators()
    n, at = 40, 2 * 2 + 6  # the slots after the members and xi, xi_aux, t, t_comp, k, status
    escape = [5, 30] if spec.adaptive else []  # a fixed step has no escape

    def start(tracked=True):
        s = list(cases.initial_state(cfg, 2, n))
        s[1][escape] = s[3][escape] = 3e9  # both members escape before their first step
        s[4][[9, 22]] = np.nan  # the noise: the first step is non-finite
        if tracked:
            s.insert(at, np.tile(observables.track_initial(accs), (2, n)))
        return tuple(s)

    lanes_kernel = cpu.tracked_levels_kernel(spec, accs, 2)
    assert "_lanes_kernel" in lanes_kernel.kernel.py_func.__qualname__  # the lanes, not a path loop
    one_pair = cpu._one_at_a_time(integrator.build(spec, observables.track_step(accs)).advance_pair, None,
                                  False, 2)
    (lanes, lane_draws), (one, one_draws) = (_calls(kernel, start(), cfg, spec) for kernel in (lanes_kernel, one_pair))
    assert lane_draws == one_draws and len(lane_draws) > len(cases.TIMES)
    for j, (a, b) in enumerate(zip(lanes, one, strict=True)):
        assert np.array_equal(a, b, equal_nan=True), (name, j)
    tracks = lanes[at]
    good = np.ones(n, dtype=bool)
    good[[*escape, 9, 22]] = False
    np.testing.assert_array_equal(lanes[9], (~good).astype(np.uint8))
    np.testing.assert_array_equal(tracks[:, escape], np.tile(observables.track_initial(accs), (2, len(escape))))
    assert np.all(np.isfinite(tracks[:, good]))
    assert not np.array_equal(tracks[:3, good], tracks[3:, good])  # each member its own slots
    untracked = list(start(tracked=False))
    plain, _ = _run_cpu(name, 2, cpu.levels_kernel(spec, 2), tuple(untracked))
    for j in range(4):  # the members
        assert np.array_equal(lanes[j], plain[j], equal_nan=True), (name, j)


def test_two_levels_are_the_bias_estimates_pair():
    """L = 2 is ``advance_pair`` (the bias estimate's step loop) and its CPU kernel the one-pair
    kernel; 1 is ``advance_path``. (The pair's numbers: the reference above at L = 2, and
    test_bias's SIMD pair lanes against the one-pair kernel.)"""
    spec = integrator.KernelSpec.of(cases.config("ou"))
    built = integrator.build(spec)
    assert built.advance_levels[2] is built.advance_pair and built.advance_levels[1] is built.advance_path
    assert cpu.levels_kernel(spec, 2) is cpu._pair_path_kernel(spec)
    assert cpu.levels_kernel(spec, 1) is cpu.path_kernel(spec)
    assert gpu.levels_kernel(spec, 2) is gpu.pair_advance_kernel(spec)
    assert integrator.level_positions(2) == integrator.state_positions(True)
    assert integrator.level_positions(1) == integrator.state_positions(False)


def test_the_state_is_declared_once_by_name():
    """The kernels' state tuple is stochpend.engine.layout's declaration: the positions every
    loop reads (``_loop_positions``, ``level_positions``) are generated from its names, and
    every engine passes its arrays in that order (a broken engine that put the channel's
    arrays before the tracks, or a member out of place, fails here)."""
    from stochpend.engine import layout

    for levels in (1, 2, 3, 4):
        for tracked in (False, True):
            for channel in (False, True):
                names = layout.state_arrays(levels, tracked, channel)
                at = layout.state_positions(levels, tracked, channel)
                assert len(set(names)) == len(names) == len(at)
                loop = integrator._loop_positions(levels, tracked, channel)
                assert (loop.XI, loop.XA, loop.T, loop.TC, loop.K, loop.ST) == tuple(
                    at[name] for name in layout.AFTER_MEMBERS) == integrator.level_positions(levels)
                for m in range(1, 4):
                    assert (loop.X1, loop.X2, loop.X3)[m - 1] == at.get(f"x{m}", 0)
                    assert (loop.O1, loop.O2, loop.O3)[m - 1] == at.get(f"Omega{m}", 1)
                assert loop.TRK == at.get("tracks", 0) and loop.ADD == at.get("xi_a", 0)
                assert loop.AUXA == at.get("aux_a", 0)
                assert names[:2 * levels] == layout.member_arrays(levels)
    # The engines: a chunk with accumulators and the channel; three coupled members with it.
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import bias

    config = SimulationConfig.build(**cases.CASES["channel"], paths=64, t_max=1.0, n_times=2, seed=1,
                                    observables=("displacement",))
    engine = cpu.Engine(config, integrator.KernelSpec.of(config), 8, 1)
    engine.start(0, 8, 1)
    assert engine.layout == layout.state_arrays(1, True, True)
    assert [a is getattr(engine, name) for a, name in zip(engine.state(), engine.layout, strict=True)] == [True] * 11
    members = cpu.LevelEngine(config, bias.pair_spec(config), 8, 1, levels=3)
    members.start(0, 8, 1)
    assert members.layout == layout.state_arrays(3, False, True)
    held = [a is members.held[name] for a, name in zip(members.state(), members.layout, strict=True)]
    assert held == [True] * 14 and members.members[4] is members.held["x2"]


def test_the_runner_drives_three_levels_whatever_the_chunks():
    """``runner.run_batches(levels=3)``: the host loop of every run drives coupled levels (the
    backend's ``LevelEngine``): per batch and output time each member's sums count every set
    of the batch, the members differ (each its own step), and the numbers do not depend on the
    chunking (three chunks of 2 batches against one of 6)."""
    from stochpend import bias
    from stochpend.engine import runner
    from stochpend.model import power_sums
    from stochpend.model.settings import SimulationConfig

    cfg = SimulationConfig.build(noise="ou", paths=120, n_batches=6, t_max=3.0, n_times=3, seed=7)
    one, steps_one = runner.run_batches(cfg, 0, 6, levels=3)
    chunked, steps_chunked = runner.run_batches(cfg, 0, 6, levels=3, chunk_paths=40)
    assert isinstance(one, power_sums.LevelSums) and one.sums.shape[:3] == (6, 3, 3)
    assert np.array_equal(one.sums, chunked.sums) and steps_one == steps_chunked > 0
    assert np.all(one.sums[..., power_sums.S_COUNT] == cfg.batch_size)
    for m in (1, 2):
        assert not np.array_equal(one.sums[:, :, 0], one.sums[:, :, m])
    assert bias.BIAS_PATH0 == rng.COUPLED_PATH0  # the pairs are the levels' streams


# -- the CUDA simulator ----------------------------------------------------------------------------
def background_run(folder: Path) -> _background.Command:
    """Every case in the CUDA simulator (a subprocess, a few seconds), started with the session."""
    root = Path(__file__).resolve().parents[2]
    return _background.Command([sys.executable, str(HELPER), str(folder / "out.npz")],
                                env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}, cwd=root)


@pytest.mark.gpu
def test_cuda_simulator_levels_equal_the_cpu_bit_for_bit():
    """The CUDA kernel (one path per thread, simulated) gives the CPU kernel's state exactly, for
    every case and L = 2, 3, 4, and with every member's accumulators (L = 2, 3) their slots too."""
    run = _background.start(__name__, background_run)
    done = run.wait(timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    sim = np.load(run.folder / "out.npz")
    accs = cases.accumulators()
    for name in cases.CASES:
        spec = integrator.KernelSpec.of(cases.config(name))
        for levels in cases.LEVELS:
            state, _ = _run_cpu(name, levels)
            for j, a in enumerate(state):
                assert np.array_equal(sim[f"{name}/{levels}/{j}"], a), (name, levels, j)
        for levels in cases.TRACKED_LEVELS:
            state, _ = _run_cpu(name, levels, cpu.tracked_levels_kernel(spec, accs, levels),
                                cases.tracked_state(cases.config(name), levels, accs))
            assert state[2 * levels + 6].shape == (levels * len(accs), cases.PATHS)
            for j, a in enumerate(state):
                assert np.array_equal(sim[f"{name}/tracked{levels}/{j}"], a), (name, levels, j)


# -- the law of each member ------------------------------------------------------------------------
def test_member_l_has_the_law_of_an_ordinary_run_at_step_h_over_2_to_the_l():
    """Fixed steps h = 0.6 (omega h = 1.2, the harmonic oscillator with white noise on the
    force): member l of L = 4 and an independent ordinary run (another seed, ``advance_path``) at
    h/2**l have the same mean energy at t = 2 and 4 (|z| < 4, z the difference in standard
    errors). The test can fail: the coarsest member against the finest step's run is about 10
    standard errors apart (the scheme's energy bias at omega h = 1.2)."""
    from stochpend.model.settings import SimulationConfig

    n, h, L, omega = 4000, 0.6, 4, 2.0
    cfg_kw = dict(noise="white", D=0.5, omega=omega, potential="harmonic", step_c=0.0, paths=n,
                  t_max=4.0, n_times=2)

    def energies(state):
        return [0.5 * state[2 * m + 1] ** 2 + 0.5 * omega**2 * state[2 * m] ** 2
                for m in range(len(state) // 2 - 3)]

    cfg = SimulationConfig.build(**cfg_kw, h_max=h, seed=5)
    spec = integrator.KernelSpec.of(cfg)
    state = cases.initial_state(cfg, L, n)
    key0, key1 = rng.seed_to_key(cfg.seed)
    members = {}
    for t_target in (2.0, 4.0):
        cpu.levels_kernel(spec, L)(state, t_target, 10**6, key0, key1, np.uint64(0), spec.noise.record(cfg),
                                   integrator.step_record(cfg))
        members[t_target] = energies(state)
    ordinary = {}
    for level in range(L):
        c = SimulationConfig.build(**cfg_kw, h_max=h / 2**level, seed=6)
        paths = cases.initial_state(c, 1, n)
        k0, k1 = rng.seed_to_key(c.seed)
        for t_target in (2.0, 4.0):
            cpu.path_kernel(spec)(paths, t_target, 10**6, k0, k1, 0, spec.noise.record(c), integrator.step_record(c))
            ordinary[t_target, level] = energies(paths)[0]

    def z(a, b):
        return (a.mean() - b.mean()) / math.sqrt(a.var() / a.size + b.var() / b.size)

    for t_target in (2.0, 4.0):
        for level in range(L):
            assert abs(z(members[t_target][level], ordinary[t_target, level])) < 4, (t_target, level)
    assert abs(z(members[4.0][0], ordinary[4.0, L - 1])) > 4
