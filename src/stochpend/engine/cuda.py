"""CUDA backend: the integrator's step loop, one GPU thread per path (design: docs/gpu.md).

The kernels only orchestrate, exactly like the CPU drivers: every step is
:mod:`stochpend.engine.integrator`'s ``advance_path``, specialised for the run's
:class:`~stochpend.engine.integrator.KernelSpec` (oscillator, coupling, noise, precision, step mode), so
each model compiles to its own kernel with no branch on a model code. Everything a path needs
is a pure function of (seed, global path index, step number), so a path takes the same Philox
draws on both backends (the same steps, up to the floating-point differences of a real GPU:
docs/gpu.md), and the results do not depend on the chunking or the launch configuration.

* ``init`` kernel: one thread per path, the initial conditions (``Integrator.init_path``).
* ``advance`` kernel: one thread per path; the path's state stays in registers for a whole
  segment between two output times (or a bounded step budget, relaunched until every path
  has landed on the output time).
* ``accumulate`` kernel: one block per batch. The block's threads evaluate E, E**2, ... for a
  tile of consecutive paths in parallel into shared memory, then thread 0 adds the tile in path
  order, so every batch is summed sequentially in path order with the CPU's exact operations:
  given the same states the float64 sums are bit-identical to the CPU's. Histogram counts use
  atomics (integers: order-independent).
* ``joint`` kernel (a run with ``joint_bins`` only): one block per batch, the joint (x, Omega)
  histogram's counts of the batch (atomics), reduced into the chunk's histogram columns.

The host side is :class:`Engine`, driven by :mod:`stochpend.engine.runner` like the CPU's: the
per-path state stays on the device for a whole chunk; per output time the host reads one flag
(did every path land?), per chunk it copies back the batch sums and the histogram, and only a
checkpoint copies the paths' state to the host. So checkpoints, resume, sweeps and
``reproduce`` run on the GPU exactly as on the CPU.

``precision="float32"`` keeps x, Omega and xi in float32 and runs the step in float32
arithmetic: the pieces are built for ``numpy.float32`` by the same factories (no rewriting).
The time, the step counter, the dichotomous noise's flip times and the statistics stay float64.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import math
import warnings
from typing import Any

import numpy as np
from numba import types as nbtypes
from numba.core.errors import NumbaPerformanceWarning
from numba.extending import register_jitable
from numba.np import numpy_support

from stochpend.engine import cpu, integrator, layout
from stochpend.engine.integrator import KernelSpec
from stochpend.engine.layout import path_dtypes
from stochpend.model import dynamics, initial, observables
from stochpend.model.observables import N_SUMS, S_COUNT, S_NONFINITE
from stochpend.model.settings import SimulationConfig
from stochpend.model.terms import TABLE
from stochpend.numerics import rng
from stochpend.numerics._jitcache import own_index

try:  # a module global: the CUDA simulator swaps it in the kernels' globals
    from numba import cuda
except Exception as _error:  # pragma: no cover - numba without its CUDA target
    cuda = None
    _IMPORT_ERROR: BaseException | None = _error
else:
    _IMPORT_ERROR = None

# The kernels of built-in pieces are cached on disk (``cuda.jit(cache=True)``, next to this file
# like the CPU's), under names that carry the code digest (see _jitcache).

__all__ = ["PERFORMANCE_WARNINGS", "PRECISIONS", "Engine", "availability", "fill_note", "kernel_variants",
           "path_states"]

PRECISIONS = integrator.PRECISIONS


def _simulator_enabled() -> bool:
    from numba.core import config as numba_config

    return bool(numba_config.ENABLE_CUDASIM)


#: Under Numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1: the test suite's GPU checks without a
#: GPU) every CUDA thread of a launch is a Python thread, started and joined per block: a launch
#: of 128-thread blocks over the tests' 8 to 48 paths started 49 000 threads in one toy
#: ``reproduce`` (70 s, most of it waiting for thread starts). The simulator runs one warp per
#: block instead. No number depends on the block size: a thread advances its own path (keyed
#: by its global index), and the statistics kernel's thread 0 adds the values in path order.
_BLOCK = 32 if _simulator_enabled() else 128
#: Threads per block of the init and advance kernels (one thread per path).
THREADS_PER_BLOCK = _BLOCK
#: Threads per block of the statistics kernel, and paths per shared-memory tile.
STATS_THREADS = _BLOCK
#: Histograms with at most this many columns (bins + 2) are counted in shared memory per block.
SHARED_HIST_MAX = 1024
#: Default paths per chunk (57 bytes a path in float64, 45 in float32); capped at half the
#: free device memory.
DEFAULT_CHUNK_PATHS = 1 << 26
#: Path-steps per launch of the advance kernel (a fraction of a second on a recent GPU), and
#: the fewest steps a launch may take. Neither changes any number, only the launch count.
_WORK_PER_LAUNCH = 1 << 31
_MIN_STEPS_PER_LAUNCH = 1000

_U64 = np.uint64
_N_VALUES = len(observables.SUMS)  # the summed values of a path (stochpend.observables)


# -- availability -----------------------------------------------------------------------------
def _one_line(error: BaseException | None) -> str:
    text = " ".join(str(error).split()).rstrip(" :")
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def availability() -> tuple[bool, str]:
    """Whether kernels can run here, and why (never raises).

    Returns ``(True, description of the device)`` or ``(False, one-line reason)``: numba.cuda
    missing, no CUDA driver, no device, or a device that cannot be opened. Under Numba's CUDA
    simulator (``NUMBA_ENABLE_CUDASIM=1``) it returns True: correct results, very slowly.
    """
    if cuda is None:
        return False, f"numba.cuda cannot be imported ({_one_line(_IMPORT_ERROR)}); install the 'cuda' extra"
    try:
        if _simulator_enabled():
            return True, "Numba CUDA simulator (NUMBA_ENABLE_CUDASIM=1): exact but very slow"
        try:
            n_devices = _device_count()
        except Exception as error:
            return False, f"no usable CUDA driver ({_one_line(error)})"
        if n_devices < 1:
            return False, "the CUDA driver reports no GPU"
        try:
            device = cuda.get_current_device()
            name = device.name.decode() if isinstance(device.name, bytes) else str(device.name)
            cc = ".".join(str(c) for c in device.compute_capability)
        except Exception as error:
            return False, f"the GPU cannot be opened ({_one_line(error)})"
        return True, f"{name} (compute capability {cc})"
    except Exception as error:  # anything unforeseen: report, never raise
        return False, f"CUDA check failed ({_one_line(error)})"


def _device_count() -> int:
    """GPUs the CUDA driver sees; raises if the driver cannot be loaded or initialised."""
    from numba.cuda.cudadrv.driver import driver

    return int(driver.get_device_count())


def _require(precision: str) -> None:
    if precision not in PRECISIONS:
        raise ValueError(f"precision={precision!r} is not accepted: one of {', '.join(PRECISIONS)}")
    ok, why = availability()
    if not ok:
        raise RuntimeError(f"backend='cuda' is not usable here: {why}")


# -- Philox on 32-bit words ------------------------------------------------------------------
def _register_mulhilo() -> bool:
    """Give :func:`stochpend.numerics.rng.mulhilo` its CUDA implementation: one ``mul.wide.u32`` (32 x 32
    -> 64-bit product of two 32-bit registers), whose halves are the CPU's 64-bit product's.

    Numba's CPU code keeps the 64-bit product, which the GPU would otherwise run as 64-bit
    integer arithmetic on zero-extended words (``mul.lo.s64``); with this, LLVM sees the words
    as 32-bit values and the whole Philox round runs on 32-bit registers. Registered for
    NVIDIA's numba-cuda only (not under the simulator, whose kernels call the Python function,
    nor Numba's deprecated built-in target); returns whether it was registered.
    """
    if cuda is None or getattr(cuda, "implementation", None) != "NVIDIA" or _simulator_enabled():
        return False
    try:
        from llvmlite import ir
        from numba.cuda.extending import intrinsic, overload
    except ImportError:  # pragma: no cover - another numba-cuda layout: the 64-bit product stays
        return False

    @intrinsic
    def mul_wide_u32(typingctx, a, b):
        if not (isinstance(a, nbtypes.Integer) and isinstance(b, nbtypes.Integer)):
            return None
        sig = nbtypes.UniTuple(nbtypes.uint64, 2)(a, b)

        def codegen(context, builder, signature, args):
            i32, i64 = ir.IntType(32), ir.IntType(64)
            words = [builder.trunc(context.cast(builder, v, t, nbtypes.uint64), i32)
                     for v, t in zip(args, signature.args, strict=True)]
            asm = ir.InlineAsm(ir.FunctionType(i64, [i32, i32]), "mul.wide.u32 $0, $1, $2;", "=l,r,r")
            product = builder.call(asm, words)
            hi = builder.lshr(product, ir.Constant(i64, 32))
            lo = builder.zext(builder.trunc(product, i32), i64)
            return context.make_tuple(builder, signature.return_type, [hi, lo])

        return sig, codegen

    @overload(rng.mulhilo, target="cuda")
    def _mulhilo_cuda(a, b):  # pragma: no cover - compiled
        def impl(a, b):
            return mul_wide_u32(a, b)

        return impl

    return True


#: Whether the CUDA kernels compute Philox with ``mul.wide.u32`` (see :func:`_register_mulhilo`).
PHILOX_MUL_WIDE_U32 = _register_mulhilo()


def spec_for(config: SimulationConfig, precision: str = "float64") -> KernelSpec:
    """The KernelSpec the GPU runs ``config`` with (the C library's math, every model)."""
    return KernelSpec.of(config, precision=precision)


# -- device helpers ---------------------------------------------------------------------------
@register_jitable
def hist_column(edges, j, E):
    """Histogram column of E at output time j: 0 below ``edges[j, 0]``, ``n_edges`` at or
    above the last edge, else ``np.searchsorted(edges[j], E, side="right")`` (binary search)."""
    n_edges = edges.shape[1]
    if E < edges[j, 0]:
        return 0
    if E >= edges[j, n_edges - 1]:
        return n_edges
    lo = 0
    hi = n_edges
    while lo < hi:
        mid = (lo + hi) // 2
        if edges[j, mid] > E:
            hi = mid
        else:
            lo = mid + 1
    return lo


# -- the kernels of a KernelSpec ----------------------------------------------------------------------
@functools.cache
def init_kernel(spec: KernelSpec):
    """``init[blocks, threads](state, key0, key1, path0, theta0, uniform_theta0, Omega0, xi0,
    stationary_xi0, p)``: one path per thread of ``state = (x, Omega, xi, xi_aux, t, t_comp,
    k, status)``, the initial values computed in float64 (they depend on the noise only); ``p``
    the noise's record (``Noise.record``)."""
    init_path = integrator.initial_state(spec.noise)
    I_XI, I_XA, I_T, I_TC, I_K, I_ST = integrator.state_positions(False)

    @cuda.jit(cache=spec.noise.builtin)
    @own_index(spec.noise.name)
    def init(state, key0, key1, path0, theta0, uniform_theta0, Omega0, xi0, stationary_xi0,
             p):  # pragma: no cover
        x = state[0]
        Omega = state[1]
        xi = state[I_XI]
        xi_aux = state[I_XA]
        t = state[I_T]
        t_comp = state[I_TC]
        k = state[I_K]
        status = state[I_ST]
        i = cuda.grid(1)
        if i >= x.shape[0]:
            return
        x0, O0, xi_0, xa_0 = init_path(key0, key1, _U64(path0 + i), theta0, uniform_theta0,
                                       Omega0, xi0, stationary_xi0, p)
        x[i] = x0
        Omega[i] = O0
        xi[i] = xi_0
        xi_aux[i] = xa_0
        t[i] = 0.0
        t_comp[i] = 0.0
        k[i] = 0
        status[i] = 0

    return init


@functools.cache
def advance_kernel(spec: KernelSpec):
    """``advance[blocks, threads](state, t_target, max_steps, key0, key1, path0, p, step_rec,
    unfinished)``: the integrator's ``advance_path`` (its ``state``, ``p`` and ``step_rec``) for one
    path per thread; sets ``unfinished[0] = 1`` if a
    path stopped short of ``t_target`` (step budget spent). The clock's compensation ``t_comp``
    is path state, so the result does not depend on how a segment is split into launches."""
    advance_path = integrator.build(spec).advance_path

    @cuda.jit(cache=spec.cacheable)
    @own_index(spec.label)
    def advance(state, t_target, max_steps, key0, key1, path0, p, step_rec,
                unfinished):  # pragma: no cover
        i = cuda.grid(1)
        if i >= state[0].shape[0]:
            return
        _, u = advance_path(i, state, t_target, max_steps, key0, key1, path0, p, step_rec)
        if u != 0:
            unfinished[0] = 1

    return advance


@functools.cache
def tracked_kernel(spec: KernelSpec, accs: tuple):
    """:func:`advance_kernel` of a run with per-path accumulators ``accs``
    (:func:`stochpend.observables.track_step`): ``state`` holds their slots after the path's
    arrays (:func:`stochpend.engine.layout.state_arrays`), (n_slots, n_paths) float64. Compiled
    in memory, once per process: :func:`tracked_levels_kernel` of one member (``advance_path``)."""
    return tracked_levels_kernel(spec, accs, 1)


@functools.cache
def tracked_levels_kernel(spec: KernelSpec, accs: tuple, levels: int):
    """:func:`levels_kernel` with every member carrying the per-path accumulators ``accs`` in its
    own slots (``state`` with ``tracks``, (levels * n_slots, n) float64, after ``status``:
    :func:`stochpend.engine.layout.state_arrays`), one set of members per thread: the tracked
    build's ``device_levels`` (the CPU's ``cpu.tracked_levels_kernel``, the same numbers; one
    member: ``advance_path``, :func:`tracked_kernel`). Compiled in memory, once per process (a
    user's accumulators are functions of this process)."""
    advance_levels = integrator.build(spec, observables.track_step(accs)).device_levels[levels]

    @cuda.jit
    def advance(state, t_target, max_steps, key0, key1, path0, p, step_rec,
                unfinished):  # pragma: no cover
        i = cuda.grid(1)
        if i >= state[0].shape[0]:
            return
        _, u = advance_levels(i, state, t_target, max_steps, key0, key1, path0, p, step_rec)
        if u != 0:
            unfinished[0] = 1

    return advance


@functools.cache
def pair_advance_kernel(spec: KernelSpec):
    """``advance[blocks, threads](state, t_target, max_steps, key0, key1, path0, p, step_rec,
    unfinished)``: the integrator's ``advance_pair`` (the coupled coarse/fine pairs of the bias estimate) for
    one pair per thread, as :func:`advance_kernel` runs ``advance_path``: :func:`levels_kernel` with
    2 members (its device variant ``device_levels[2]``: the same operations, the draw tree's nodes
    left to NVVM to inline)."""
    return levels_kernel(spec, 2)


@functools.cache
def levels_kernel(spec: KernelSpec, levels: int):
    """``advance[blocks, threads](state, t_target, max_steps, key0, key1, path0, p, step_rec,
    unfinished)``: ``levels`` coupled members (the integrator's ``advance_levels[levels]``:
    steps h, h/2, ..., h/2**(levels-1) driven by one noise path; ``state`` of
    ``integrator.level_positions``) for one path per thread, as :func:`advance_kernel` runs one
    path (``levels`` 1 is that kernel; 2 the bias estimate's pairs, cached under "/pairs")."""
    if levels == 1:
        return advance_kernel(spec)
    advance_levels = integrator.build(spec).device_levels[levels]
    label = spec.label + ("/pairs" if levels == 2 else f"/levels{levels}")

    @cuda.jit(cache=spec.cacheable)
    @own_index(label)
    def advance(state, t_target, max_steps, key0, key1, path0, p, step_rec,
                unfinished):  # pragma: no cover
        i = cuda.grid(1)
        if i >= state[0].shape[0]:
            return
        _, u = advance_levels(i, state, t_target, max_steps, key0, key1, path0, p, step_rec)
        if u != 0:
            unfinished[0] = 1

    return advance


class LevelEngine(cpu.LevelEngine):
    """Device arrays of a chunk of coupled members (``runner.run_batches`` with ``levels`` > 1
    on a GPU run: the bias estimate's pairs): the members start like the run's paths (the
    KernelSpec's ``init`` kernel, then every member at member 0's start) and are advanced by
    :func:`levels_kernel`; per output time the host copies back the members' state, which the
    CPU's accumulate kernel then sums (so, given the states, the CPU's sums)."""

    name = "cuda"

    @staticmethod
    def kernels(spec: KernelSpec, levels: int) -> tuple[Any, Any]:
        _require(spec.precision)
        return init_kernel(spec), levels_kernel(spec, levels)

    @staticmethod
    def tracked_kernel(spec: KernelSpec, accs: tuple, levels: int) -> Any:
        _require(spec.precision)
        return tracked_levels_kernel(spec, accs, levels)

    def start(self, p0: int, n: int, nb: int) -> None:
        c = self.config
        self.p0, self.n, self.nb = p0, n, nb
        self.path0 = np.uint64(rng.COUPLED_PATH0 + p0)
        dtypes = path_dtypes("cpu", "float64")
        with _quiet():
            # The kernels' state, by name (self.layout: stochpend.engine.layout.state_arrays).
            self.d = {name: cuda.device_array(n, dtype=dtypes.get(name, dtypes["x"])) for name in self.layout}
            if self.track_accs:  # every member's slots (cpu.LevelEngine.start)
                self.d["tracks"] = cuda.to_device(np.tile(observables.track_initial(self.track_accs),
                                                          (self.levels, n)))
            self.flag = cuda.device_array(1, dtype=np.int32)
            x, Omega = self.d["x"], self.d["Omega"]
            self.init[_blocks(n, THREADS_PER_BLOCK), THREADS_PER_BLOCK](
                tuple(self.d[name] for name in layout.state_arrays(1)), self.key0, self.key1,
                self.path0, 0.0 if c.theta0 is None else c.theta0, c.theta0 is None, c.Omega0,
                0.0 if c.xi0 is None else c.xi0, c.xi0 is None, self.record)
            if initial.temperature(c) > 0.0:  # as the run's paths (Engine.start)
                bx, bO = initial.boltzmann(c, int(self.path0), n)
                x.copy_to_device(bx)
                Omega.copy_to_device(bO)
            # The additive channel's state (a run with it), shared by the members as xi is.
            for name, value in zip(self.additive, initial.additive_states(c, int(self.path0), n), strict=True):
                self.d[name].copy_to_device(value)
            member = layout.member_arrays(self.levels)
            for m in range(1, self.levels):
                self.d[member[2 * m]].copy_to_device(x)
                self.d[member[2 * m + 1]].copy_to_device(Omega)
        self._zero_flag = np.zeros(1, dtype=np.int32)
        self.chunk_sums = np.zeros((nb, self.n_times, self.levels, self.n_sums))

    def advance(self, t_target: float, max_steps: int) -> bool:
        """One launch towards t_target; True when every live set has landed on it."""
        with _quiet():
            self.flag.copy_to_device(self._zero_flag)
            self.advance_k[_blocks(self.n, THREADS_PER_BLOCK), THREADS_PER_BLOCK](
                tuple(self.d[name] for name in self.layout), t_target, max_steps, self.key0,
                self.key1, self.path0, self.record, self.step_rec, self.flag)
            return int(self.flag.copy_to_host()[0]) == 0

    def time_sum(self, t_target: float, done: bool) -> float:
        return 0.0

    def host_members(self) -> tuple[list[np.ndarray], np.ndarray, np.ndarray, np.ndarray]:
        """Host copies of the members' (x, Omega), xi, t and the status (the members share xi, t)."""
        members = [self.d[name].copy_to_host() for name in layout.member_arrays(self.levels)]
        return members, self.d["xi"].copy_to_host(), self.d["t"].copy_to_host(), self.d["status"].copy_to_host()

    def put_status(self, status: np.ndarray) -> None:
        self.d["status"].copy_to_device(status)

    def host_tracks(self) -> np.ndarray:
        """A host copy of every member's accumulators' slots (levels * n_slots, n)."""
        return self.d["tracks"].copy_to_host()

    def steps(self) -> int:
        return int(np.sum(self.d["k"].copy_to_host(), dtype=np.uint64))


def accumulate_kernel(spec: KernelSpec, observables_: tuple[str, ...] = ()):
    """``accumulate[n_batches, STATS_THREADS](x, Omega, xi, t, status, tracks, omega2, q,
    batch_size, edges, j, sums, hist)``: the CPU's per-batch sums at output time j, block b
    summing batch b of the chunk into ``sums[b, j, :]`` in path order (the statistics table's
    values, then the user observables', an accumulator's read from its slot of ``tracks``);
    the histogram counts go to ``hist[j, :]`` (they depend on the oscillator, the coupling and
    the user observables only)."""
    return _accumulate_kernel(spec, observables.objects(observables_))


@functools.cache
def _accumulate_kernel(spec: KernelSpec, user: tuple):
    path_values = integrator.statistics(spec.oscillator, spec.coupling)
    user_values = observables.user_values(user, spec.oscillator)
    tpb = STATS_THREADS
    hist_max = SHARED_HIST_MAX
    n_values = _N_VALUES
    n_user = observables.n_user_columns(user)
    n_all = _N_VALUES + n_user
    first_user = N_SUMS

    @cuda.jit(cache=spec.oscillator.builtin and not user)
    @own_index(f"{spec.oscillator.name}/{spec.coupling}/{observables.TABLE_KEY}/{observables.user_key(user)}")
    def accumulate(x, Omega, xi, t, status, tracks, omega2, q, batch_size, edges, j, sums,
                   hist):  # pragma: no cover - device
        b = cuda.blockIdx.x
        tid = cuda.threadIdx.x
        values = cuda.shared.array((n_all, tpb), np.float64)
        skip = cuda.shared.array(tpb, np.int32)
        shared_hist = cuda.shared.array(hist_max, np.int32)
        n_cols = edges.shape[1] + 1
        in_shared = n_cols <= hist_max
        if in_shared:
            for c in range(tid, n_cols, tpb):
                shared_hist[c] = 0
        cuda.syncthreads()
        n_paths = x.shape[0]
        start = b * batch_size
        stop = min(start + batch_size, n_paths)
        s_count = 0.0
        s_bad = 0.0
        # Thread 0's running sums, one per summed value, added in path order.
        total = cuda.local.array(n_all, np.float64)
        for c in range(n_all):
            total[c] = 0.0
        for base in range(start, stop, tpb):
            i = base + tid
            if i < stop:
                counted = False
                if status[i] == 0:
                    ok, E, path = path_values(np.float64(x[i]), np.float64(Omega[i]), omega2, q)
                    mine = user_values(np.float64(x[i]), np.float64(Omega[i]), np.float64(xi[i]), t[i],
                                       tracks, i, omega2, q)
                    for c in range(n_user):
                        ok = ok and math.isfinite(mine[c])
                    if ok:
                        counted = True
                        for c in range(n_values):
                            values[c, tid] = path[c]
                        for c in range(n_user):
                            values[n_values + c, tid] = mine[c]
                        col = hist_column(edges, j, E)
                        if in_shared:
                            cuda.atomic.add(shared_hist, col, 1)
                        else:
                            cuda.atomic.add(hist, (j, col), 1)
                    else:
                        # As on the CPU: a finite state with overflowing moments has escaped;
                        # it is frozen as non-finite from now on.
                        status[i] = 1
                skip[tid] = 0 if counted else 1
            cuda.syncthreads()
            if tid == 0:
                # (not named q: that is the oscillator's record, read above)
                for lane in range(min(tpb, stop - base)):
                    if skip[lane] != 0:
                        s_bad += 1.0
                    else:
                        s_count += 1.0
                        for c in range(n_all):
                            total[c] += values[c, lane]
            cuda.syncthreads()
        if tid == 0:
            sums[b, j, S_COUNT] = s_count
            for c in range(n_values):
                sums[b, j, 1 + c] = total[c]
            sums[b, j, S_NONFINITE] = s_bad
            for c in range(n_user):
                sums[b, j, first_user + c] = total[n_values + c]
        if in_shared:
            for c in range(tid, n_cols, tpb):
                count = shared_hist[c]
                if count != 0:
                    cuda.atomic.add(hist, (j, c), np.int64(count))

    return accumulate


@functools.cache
def joint_kernel(periodic: bool):
    """``joint[n_batches, STATS_THREADS](x, Omega, status, batch_size, x_lo, x_hi, nx, O_lo,
    O_hi, nO, j, sums, counts, hist, offset)``: the CPU's joint (x, Omega) histogram
    (``cpu.joint_kernel``) at output time j, block b counting batch b's finite paths into
    ``counts[b, :]`` (overwritten; atomics, integers: order-independent), then adding the
    counts, their squares and their products with the batch's finite paths (``sums[b, j,
    S_COUNT]``, which ``accumulate`` wrote before) to ``hist[j, offset:]`` as
    ``cpu.joint_sums`` does. Launched only when the run asks for the histogram."""
    from stochpend.engine.joint import cell

    tpb = STATS_THREADS

    @cuda.jit(cache=True)
    @own_index(f"joint/{periodic}")
    def joint(x, Omega, status, batch_size, x_lo, x_hi, nx, O_lo, O_hi, nO, j, sums, counts, hist,
              offset):  # pragma: no cover - device
        b = cuda.blockIdx.x
        tid = cuda.threadIdx.x
        cells = counts.shape[1]
        for c in range(tid, cells, tpb):
            counts[b, c] = 0
        cuda.syncthreads()
        stop = min((b + 1) * batch_size, x.shape[0])
        for i in range(b * batch_size + tid, stop, tpb):
            if status[i] == 0:
                cuda.atomic.add(counts, (b, cell(np.float64(x[i]), np.float64(Omega[i]), periodic,
                                                 x_lo, x_hi, nx, O_lo, O_hi, nO)), 1)
        cuda.syncthreads()
        n_b = np.int64(sums[b, j, S_COUNT])
        for c in range(tid, cells, tpb):
            cb = counts[b, c]
            if cb != 0:
                cuda.atomic.add(hist, (j, offset + c), cb)
                cuda.atomic.add(hist, (j, offset + cells + c), cb * cb)
                cuda.atomic.add(hist, (j, offset + 2 * cells + c), cb * n_b)

    return joint


# -- host side --------------------------------------------------------------------------------
def _performance_warnings() -> tuple[type[Warning], ...]:
    """Numba's performance-warning classes that can be imported here: numba's own
    (``numba.core.errors``, raised by its built-in CUDA target and the simulator) and NVIDIA
    numba-cuda's (``numba.cuda.core.errors``: a separate class, not a subclass, raised for a
    grid under 128 blocks and for copies of non-pinned host memory)."""
    classes: list[type[Warning]] = [NumbaPerformanceWarning]
    with contextlib.suppress(Exception):  # numba-cuda not installed: numba's class only
        classes.append(importlib.import_module("numba.cuda.core.errors").NumbaPerformanceWarning)
    return tuple(dict.fromkeys(classes))


#: What :func:`_quiet` silences (see :func:`_performance_warnings`).
PERFORMANCE_WARNINGS = _performance_warnings()


@contextlib.contextmanager
def _quiet():
    """Silence Numba's performance warnings around our launches and copies: a small ensemble or
    few batches (one block per batch) is legitimate, and a run too small to fill the GPU is
    said once in stochpend's words instead (:func:`fill_note`, :meth:`Engine.start`)."""
    with warnings.catch_warnings():
        for category in PERFORMANCE_WARNINGS:
            warnings.simplefilter("ignore", category)
        yield


def fill_note(n_paths: int, multiprocessors: int, threads_per_block: int = THREADS_PER_BLOCK) -> str | None:
    """The note for a chunk of ``n_paths`` paths too small to fill a GPU of ``multiprocessors``
    SMs (one thread per path, ``threads_per_block``): fewer than two blocks per SM leaves most
    of the GPU idle. ``None`` when the chunk fills it. The results do not depend on it."""
    blocks = _blocks(n_paths, threads_per_block)
    wanted = 2 * multiprocessors
    if multiprocessors < 1 or blocks >= wanted:
        return None
    return (f"backend='cuda': {n_paths} paths run as {blocks} blocks of {threads_per_block} threads on "
            f"a GPU with {multiprocessors} multiprocessors, too few to fill it (it takes at least "
            f"{wanted * threads_per_block} paths); the results are right, but most of the GPU is "
            "idle and the CPU backend may be as fast")


def _multiprocessors() -> int:
    """The current GPU's SM count (0 if it cannot be read, or under the simulator)."""
    if _simulator_enabled():
        return 0
    try:
        return int(cuda.get_current_device().MULTIPROCESSOR_COUNT)
    except Exception:
        return 0


def _blocks(n: int, per_block: int) -> int:
    return max(1, -(-n // per_block))


def _bytes_per_path(precision: str) -> int:
    # x, Omega, xi in the precision; xi_aux, t, t_comp float64; k uint64; status uint8
    return 3 * np.dtype(precision).itemsize + 4 * 8 + 1


class Engine:
    """Device arrays of one chunk of paths and the launches that advance them (for ``runner``)."""

    name = "cuda"
    # The chunk's per-path device arrays, allocated from layout.path_dtypes (see __init__).
    d_x: Any
    d_Omega: Any
    d_xi: Any
    d_xi_aux: Any
    d_t: Any
    d_t_comp: Any
    d_k: Any
    d_status: Any
    d_xi_a: Any  # a run with the additive channel of a coloured noise only
    d_aux_a: Any  # a run with the generic additive channel only

    def __init__(self, config: SimulationConfig, spec: KernelSpec, capacity: int,
                 n_chunk_batches: int) -> None:
        _require(spec.precision)
        self.config = config
        self.spec = spec
        self.init = init_kernel(spec)
        self.advance_k = advance_kernel(spec)
        self.accumulate_k = accumulate_kernel(spec, config.observables)
        # Per-path accumulators (stochpend.observables): their slots ride with the state.
        self.accs = observables.accumulators(observables.objects(config.observables))
        if self.accs:
            self.advance_k = tracked_kernel(spec, self.accs)
        self.capacity = capacity
        # The additive channel's per-path arrays (xi_a; aux_a for the generic channel).
        self.additive = dynamics.additive_arrays(config)
        # The kernels' state tuple, by name (stochpend.engine.layout).
        self.layout = layout.state_arrays(1, tracked=bool(self.accs), channel=bool(self.additive))
        self.n_times = len(config.times)
        from stochpend.model import settings

        self.n_cols = settings.hist_columns(config)
        # The joint (x, Omega) histogram, when the run asks for it (settings.joint_grid).
        self.joint_grid = settings.joint_grid(config)
        if self.joint_grid is not None:
            self.joint_k = joint_kernel(spec.oscillator.periodic)
            with _quiet():
                self.d_joint_counts = cuda.device_array((n_chunk_batches, settings.joint_cells(config)),
                                                        dtype=np.int64)
        with _quiet():
            for name, dtype in path_dtypes("cuda", spec.precision).items():
                if name in ("xi_a", "aux_a") and name not in self.additive:  # only a run with them
                    continue
                setattr(self, "d_" + name, cuda.device_array(capacity, dtype=dtype))
            self.flag = cuda.device_array(1, dtype=np.int32)
            self.d_tracks = cuda.device_array((max(len(self.accs), 1), capacity), dtype=np.float64)
            self.d_sums = cuda.device_array((n_chunk_batches, self.n_times, observables.n_sums(config)),
                                            dtype=np.float64)
            self.d_hist = cuda.device_array((self.n_times, self.n_cols), dtype=np.int64)
            from stochpend.model.settings import hist_edges

            self.d_edges = cuda.to_device(np.ascontiguousarray(hist_edges(config), dtype=np.float64))
        self._zero_flag = np.zeros(1, dtype=np.int32)
        self._fill_checked = False
        self.key0, self.key1 = config.keys.main
        self.record = spec.noise.record(config)
        self.step_rec = integrator.step_record(config)
        self.n = 0
        self.nb = 0
        self.p0 = 0

    @staticmethod
    def default_chunk_paths(precision: str) -> int:
        # The runner's first call into this backend: a bad precision or no usable GPU is one
        # line here, before any device call (a driver-less machine otherwise raises deep in
        # numba.cuda).
        _require(precision)
        if _simulator_enabled():
            return DEFAULT_CHUNK_PATHS
        free, _ = cuda.current_context().get_memory_info()
        return int(max(1, min(DEFAULT_CHUNK_PATHS, free // (2 * _bytes_per_path(precision)))))

    def _view(self, name: str) -> Any:
        """The chunk's paths of device array ``d_<name>`` (the accumulators' slots: every slot)."""
        if name == "tracks":
            return self.d_tracks[:, : self.n]
        return getattr(self, "d_" + name)[: self.n]

    def _views(self) -> tuple:
        """The views of a path's state, ``layout.state_arrays(1)``: (x, Omega, xi, xi_aux, t,
        t_comp, k, status), as the init and accumulate kernels take them."""
        return tuple(self._view(name) for name in layout.state_arrays(1))

    def _state(self) -> tuple:
        """The views as the advance kernel takes them, in the order of ``self.layout``: then the
        accumulators' slots (a run with accumulators) and the additive channel's arrays (a run
        with them)."""
        return tuple(self._view(name) for name in self.layout)

    def start(self, p0: int, n: int, nb: int) -> None:
        """Initial conditions of global paths p0 .. p0 + n - 1."""
        c = self.config
        self.p0, self.n, self.nb = p0, n, nb
        if not self._fill_checked:  # once per engine: its first chunk is its largest
            self._fill_checked = True
            note = fill_note(n, _multiprocessors())
            if note is not None:
                from stochpend.text._warnings import StochpendWarning

                warnings.warn(note, StochpendWarning, stacklevel=2)
        with _quiet():
            self.init[_blocks(n, THREADS_PER_BLOCK), THREADS_PER_BLOCK](
                self._views(), self.key0, self.key1, p0,
                0.0 if c.theta0 is None else c.theta0, c.theta0 is None, c.Omega0,
                0.0 if c.xi0 is None else c.xi0, c.xi0 is None, self.record)
            self.d_hist.copy_to_device(np.zeros((self.n_times, self.n_cols), dtype=np.int64))
            if self.accs:
                self._put_tracks(np.broadcast_to(observables.track_initial(self.accs), (len(self.accs), n)))
            if initial.temperature(c) > 0.0:  # the Boltzmann law, drawn on the host (stochpend.model.initial)
                x, Omega = initial.boltzmann(c, p0, n)
                self.d_x[:n].copy_to_device(x.astype(self.d_x.dtype))
                self.d_Omega[:n].copy_to_device(Omega.astype(self.d_Omega.dtype))
            # The additive channel's start, its stationary law, drawn on the host (stochpend.model.initial).
            for name, value in zip(self.additive, initial.additive_states(c, p0, n), strict=True):
                getattr(self, "d_" + name)[:n].copy_to_device(value)

    def _put_tracks(self, tracks: np.ndarray) -> None:
        full = np.zeros(self.d_tracks.shape)
        full[:, : tracks.shape[1]] = tracks
        self.d_tracks.copy_to_device(full)

    def load(self, p0: int, arrays: dict[str, np.ndarray]) -> None:
        """Continue a chunk from host arrays (a checkpoint's RunState fields)."""
        self.p0 = p0
        self.n = arrays["x"].shape[0]
        self.nb = arrays["chunk_sums"].shape[0]
        with _quiet():
            for name, view in zip(layout.state_arrays(1), self._views(), strict=True):
                view.copy_to_device(np.ascontiguousarray(arrays[name], dtype=view.dtype))
            sums = np.zeros(self.d_sums.shape)
            sums[: self.nb] = arrays["chunk_sums"]
            self.d_sums.copy_to_device(sums)
            self.d_hist.copy_to_device(np.ascontiguousarray(arrays["chunk_hist"], dtype=np.int64))
            if self.accs:
                self._put_tracks(np.asarray(arrays["tracks"], dtype=np.float64))
            for name in self.additive:
                getattr(self, "d_" + name)[: self.n].copy_to_device(
                    np.ascontiguousarray(arrays[name], dtype=np.float64))

    def max_steps(self) -> int:
        return max(_MIN_STEPS_PER_LAUNCH, _WORK_PER_LAUNCH // max(self.n, 1))

    def advance(self, t_target: float, max_steps: int) -> bool:
        """One launch towards t_target; True when every live path has landed on it."""
        with _quiet():
            self.flag.copy_to_device(self._zero_flag)
            self.advance_k[_blocks(self.n, THREADS_PER_BLOCK), THREADS_PER_BLOCK](
                self._state(), t_target, max_steps, self.key0, self.key1, self.p0, self.record,
                self.step_rec, self.flag)
            return int(self.flag.copy_to_host()[0]) == 0

    def time_sum(self, t_target: float, done: bool) -> float:
        return self.n * t_target if done else float(np.sum(self.d_t[: self.n].copy_to_host()))

    def accumulate(self, j: int, edges_j: np.ndarray) -> None:
        c = self.config
        x, Omega, xi, _, t, _, _, status = self._views()
        with _quiet():
            self.accumulate_k[self.nb, STATS_THREADS](
                x, Omega, xi, t, status, self.d_tracks[:, : self.n], c.omega**2, self.step_rec[integrator.STEP_Q],
                c.batch_size, self.d_edges, j, self.d_sums, self.d_hist)
            if self.joint_grid is not None:
                x_edges, O_edges = self.joint_grid
                nx, nO = c.joint_bins
                self.joint_k[self.nb, STATS_THREADS](
                    x, Omega, status, c.batch_size, float(x_edges[j, 0]), float(x_edges[j, -1]), nx,
                    float(O_edges[j, 0]), float(O_edges[j, -1]), nO, j, self.d_sums,
                    self.d_joint_counts, self.d_hist, c.hist_bins + 2)

    def steps(self) -> int:
        return int(np.sum(self.d_k[: self.n].copy_to_host(), dtype=np.uint64))

    def arrays(self) -> dict[str, np.ndarray]:
        """Host copies of the chunk's state (for a checkpoint)."""
        out = {name: view.copy_to_host() for name, view in zip(layout.state_arrays(1), self._views(), strict=True)}
        out["chunk_sums"], out["chunk_hist"] = self.results()
        out["tracks"] = self.d_tracks.copy_to_host()[: len(self.accs), : self.n]
        for name in ("xi_a", "aux_a"):
            out[name] = getattr(self, "d_" + name)[: self.n].copy_to_host() if name in self.additive else np.empty(0)
        return out

    def results(self) -> tuple[np.ndarray, np.ndarray]:
        return self.d_sums.copy_to_host()[: self.nb], self.d_hist.copy_to_host()

    def final_tracks(self) -> tuple[np.ndarray, np.ndarray]:
        """Host copies of the accumulators' slots (n_slots, n) and the status (n,) of the
        chunk's paths (for each path's final first-passage time: stochpend.model.passage)."""
        with _quiet():
            return (self.d_tracks.copy_to_host()[: len(self.accs), : self.n],
                    self.d_status[: self.n].copy_to_host())


def path_states(
    config: SimulationConfig, first_path: int, n_paths: int, *, precision: str = "float64"
) -> dict[str, np.ndarray]:
    """Final state of global paths ``first_path .. first_path + n_paths - 1`` at t_max.

    The paths land on every output time on the way, exactly as in :func:`run_batches`, so this
    is the state the last statistics were taken from. Returns host arrays ``x``, ``Omega``,
    ``xi``, ``xi_aux``, ``t``, ``t_comp``, ``k`` (steps taken) and ``status``. For path-by-path
    comparisons with the CPU kernels.
    """
    _require(precision)
    if not (0 <= first_path and 1 <= n_paths and first_path + n_paths <= config.paths):
        raise ValueError(f"paths {first_path}..{first_path + n_paths - 1} are not in the ensemble")
    engine = Engine(config, spec_for(config, precision), n_paths, 1)
    engine.start(first_path, n_paths, 1)
    for t_target in config.times:
        max_steps = engine.max_steps()
        while not engine.advance(float(t_target), max_steps):
            pass
    state = engine.arrays()
    del state["chunk_sums"], state["chunk_hist"], state["tracks"]
    for name in ("xi_a", "aux_a"):
        if name not in engine.additive:
            del state[name]
    return state


# -- offline compilation (benchmarks/cuda_registers.py) ----------------------------------------
#: The accumulators' slots as the host passes them (``Engine._state``: ``d_tracks[:, :n]``, a
#: 2-d view that is not contiguous when the chunk is shorter than the capacity; a full chunk's
#: view types as "C" and compiles the same code once more).
_TRACKS = nbtypes.Array(nbtypes.float64, 2, "A")


def _path_arrays(precision: str) -> tuple:
    """The types of ``Engine._views()``: (x, Omega, xi, xi_aux, t, t_comp, k, status), 1-d
    C-contiguous device arrays in the dtypes of :func:`layout.path_dtypes`."""
    dtypes = path_dtypes("cuda", precision)
    return tuple(nbtypes.Array(numpy_support.from_dtype(dtypes[name]), 1, "C")
                 for name in ("x", "Omega", "xi", "xi_aux", "t", "t_comp", "k", "status"))


def _init_signature(precision: str, noise: Any) -> tuple:
    """(state, key0, key1, path0, theta0, uniform_theta0, Omega0, xi0, stationary_xi0, p) as
    :meth:`Engine.start` launches :func:`init_kernel` (Python ints int64, floats float64, bools
    boolean, the noise's record one float64 per parameter)."""
    f64, b = nbtypes.float64, nbtypes.boolean
    return (nbtypes.Tuple(_path_arrays(precision)), nbtypes.uint64, nbtypes.uint64, nbtypes.int64,
            f64, b, f64, f64, b, nbtypes.UniTuple(f64, len(noise.parameters)))


def _q_type(oscillator: Any):
    # Oscillator.record: an integer setting (power_n) stays an integer, the rest are floats.
    return nbtypes.Tuple(tuple(nbtypes.int64 if getattr(e, "name", e) == "power_n" else nbtypes.float64
                               for e in oscillator.parameters) or (nbtypes.float64,))


def _accumulate_signature(precision: str, oscillator: Any) -> tuple:
    """(x, Omega, xi, t, status, tracks, omega2, q, batch_size, edges, j, sums, hist) as
    :meth:`Engine.accumulate` launches the accumulate kernel."""
    x, Omega, xi, _, t, _, _, status = _path_arrays(precision)
    f64 = nbtypes.float64
    return (x, Omega, xi, t, status, _TRACKS, f64, _q_type(oscillator), nbtypes.int64,
            nbtypes.Array(f64, 2, "C"), nbtypes.int64, nbtypes.Array(f64, 3, "C"),
            nbtypes.Array(nbtypes.int64, 2, "C"))


def _joint_signature(precision: str) -> tuple:
    """(x, Omega, status, batch_size, x_lo, x_hi, nx, O_lo, O_hi, nO, j, sums, counts, hist,
    offset) as :meth:`Engine.accumulate` launches :func:`joint_kernel`."""
    x, Omega, _, _, _, _, _, status = _path_arrays(precision)
    f64, i64 = nbtypes.float64, nbtypes.int64
    counts = nbtypes.Array(i64, 2, "C")
    return (x, Omega, status, i64, f64, f64, i64, f64, f64, i64, i64, nbtypes.Array(f64, 3, "C"),
            counts, counts, i64)


def _user_objects() -> dict[str, tuple]:
    """User observables of each kind for the compile check (not registered: the kernels are
    specialised on the objects). Their functions are ordinary user code: Python floats, math."""
    time_average = observables.TimeAverage("cc_Om2_avg", lambda x, Omega, xi, t: Omega * Omega,
                                            window=(0.0, 1.0))
    running_sum = observables.RunningSum(
        "cc_xi_int", lambda x0, O0, xi0, x1, O1, xi1, t0, t1: 0.5 * (t1 - t0) * (xi0 + xi1), rates=True)
    first_passage = observables.FirstPassage(
        "cc_escape", lambda x, Omega, xi, t: 0.5 * Omega * Omega - math.cos(x), threshold=1.5)
    value = observables.Observable("cc_x_now", lambda x, Omega, xi, t: x * x + math.sin(Omega))
    return {
        "time-average": (time_average,),
        "running-sum": (running_sum, observables.DISPLACEMENT),
        "first-passage": (first_passage,),
        "all": (value, observables.LOG_ENERGY, time_average, running_sum, first_passage),
    }


def _other_kernels(precisions: tuple[str, ...]) -> list[tuple[str, object, tuple]]:
    """init, tracked advance, accumulate and joint kernels (see :func:`kernel_variants`)."""
    from stochpend.model import noises, oscillators

    out: list[tuple[str, object, tuple]] = []
    builtin = {noise.name: noise for noise in noises.BUILTIN}
    pendulum = oscillators.BUILTIN["pendulum"]
    user = _user_objects()
    for precision in precisions:
        for noise in noises.BUILTIN:
            out.append((f"init {noise.name}/{precision}", init_kernel(KernelSpec(pendulum, "force", noise, precision, True)).py_func,
                        _init_signature(precision, noise)))
    # Tracked advance: each accumulator kind, then all of them, on the paper's OU pendulum; and
    # all of them with the family's damping and the generic additive channel (the state's
    # arrays: the slots, then the channel's).
    for precision in precisions:
        for adaptive in (True, False):
            spec = KernelSpec(pendulum, "force", builtin["ou"], precision, adaptive)
            for kind, objs in user.items():
                accs = observables.accumulators(objs)
                out.append((f"tracked {spec.label} [{kind}]", tracked_kernel(spec, accs).py_func,
                            _advance_signature(precision, spec.noise, pendulum, tracks=True)))
        terms = frozenset({"damping", "additive_noise"})
        spec = KernelSpec(pendulum, "force", builtin["white"], precision, True, False, terms, builtin["dichotomous"])
        accs = observables.accumulators(user["all"])
        out.append((f"tracked {spec.label} [all]", tracked_kernel(spec, accs).py_func,
                    _advance_signature(precision, spec.noise, pendulum, terms, spec.additive, tracks=True)))
        # A noise with events: the accumulators see the noise before its flip at a step's end.
        spec = KernelSpec(pendulum, "force", builtin["dichotomous"], precision, True)
        out.append((f"tracked {spec.label} [all]", tracked_kernel(spec, accs).py_func,
                    _advance_signature(precision, spec.noise, pendulum, tracks=True)))
    # accumulate: the statistics of each oscillator and coupling (no user observables), then
    # every kind of user observable (the histogram's shared or global counting is chosen at run
    # time, in the same kernel).
    for precision in precisions:
        for osc in oscillators.BUILTIN.values():
            for coupling in oscillators.COUPLINGS:
                if osc.periodic and coupling == "position":
                    continue
                spec = KernelSpec(osc, coupling, builtin["ou"], precision, True)
                out.append((f"accumulate {osc.name}/{coupling}/{precision}",
                            _accumulate_kernel(spec, ()).py_func, _accumulate_signature(precision, osc)))
        spec = KernelSpec(pendulum, "force", builtin["ou"], precision, True)
        for kind, objs in user.items():
            out.append((f"accumulate pendulum/force/{precision} [{kind}]",
                        _accumulate_kernel(spec, objs).py_func, _accumulate_signature(precision, pendulum)))
        for periodic in (True, False):
            out.append((f"joint {'periodic' if periodic else 'open'}/{precision}",
                        joint_kernel(periodic).py_func, _joint_signature(precision)))
    return out


def _advance_signature(precision: str, noise: Any, oscillator: Any, terms: frozenset = frozenset(),
                       additive: Any = None, tracks: bool = False):
    """(state, t_target, max_steps, key0, key1, path0, p, step_rec, unfinished) as the host launches
    the advance kernel of ``noise`` and ``oscillator``: the noise's record, one float64 per
    ``noise.parameters``; the step record (omega2, q, h_max, step_c) with the oscillator's record
    q, one float64 per ``oscillator.parameters`` (at least one: ``Oscillator.record``); with the
    generic additive channel (``additive``, its noise), its record and its Philox key; with
    per-path accumulators (``tracks``, :func:`tracked_kernel`), their slots after ``status``."""
    f64 = nbtypes.Array(nbtypes.float64, 1, "C")
    arrays = list(_path_arrays(precision))
    if tracks:
        arrays.append(_TRACKS)
    if "additive_noise" in terms:  # the generic channel's xi_a, aux_a, last (float64)
        arrays.extend((f64, f64))
    state = nbtypes.Tuple(tuple(arrays))
    record = nbtypes.UniTuple(nbtypes.float64, len(noise.parameters))
    # The oscillator's record as Oscillator.record builds it: an integer setting (power_n) stays
    # an integer, everything else is a float.
    q = _q_type(oscillator)
    step_fields = [nbtypes.float64, q, nbtypes.float64, nbtypes.float64]
    if terms:  # the family's record d (stochpend.model.dynamics.record): ten float64
        step_fields.append(nbtypes.UniTuple(nbtypes.float64, 10))
    if additive is not None:  # the channel's record pa and key (ka0, ka1)
        step_fields.append(nbtypes.UniTuple(nbtypes.float64, len(additive.parameters)))
        step_fields.append(nbtypes.UniTuple(nbtypes.uint64, 2))
    step_rec = nbtypes.Tuple(tuple(step_fields))
    return (state, nbtypes.float64, nbtypes.int64, nbtypes.uint64, nbtypes.uint64, nbtypes.int64,
            record, step_rec, nbtypes.Array(nbtypes.int32, 1, "C"))


def _pair_advance_signature(noise: Any, oscillator: Any, terms: frozenset = frozenset(),
                            additive: Any = None, levels: int = 2, tracks: bool = False):
    sig = _advance_signature("float64", noise, oscillator, terms, additive, tracks)
    f64 = nbtypes.Array(nbtypes.float64, 1, "C")
    x, Omega, *rest = sig[0].types
    # x, Omega, then the finer members' (the pair's fine member xf, Omegaf); path0 is a uint64
    # (2**63 + pair index)
    return (nbtypes.Tuple((x, Omega, *(f64, f64) * (levels - 1), *rest)), *sig[1:5], nbtypes.uint64, *sig[6:])


def kernel_variants(precisions: tuple[str, ...] = PRECISIONS) -> list[tuple[str, object, tuple]]:
    """Every kind of kernel the backend launches: ``(label, python function, signature)`` for
    offline compilation (``benchmarks/cuda_registers.py``, ``make cuda-compile-check``), the
    label's first word the kind:

    * ``advance``: each oscillator and coupling it takes, each noise, adaptive and fixed steps,
      each precision; the family's term sets and the generic additive channel;
    * ``pairs``: the bias estimate's pair kernels of the same Specs (float64 only: the pairs
      always run in float64);
    * ``init``: each noise, each precision;
    * ``tracked``: the advance kernel with per-path accumulators (a time average, running
      sums, a first passage, all of them; with the family and the additive channel too);
    * ``accumulate``: each oscillator and coupling, then each kind of user observable;
    * ``joint``: the joint (x, Omega) histogram, periodic and open coordinates.

    The signatures are the argument types the host launches each kernel with."""
    from stochpend.model import noises, oscillators

    out = []
    for precision in precisions:
        for osc in oscillators.BUILTIN.values():
            for coupling in oscillators.COUPLINGS:
                if osc.periodic and coupling == "position":
                    continue
                for noise in noises.BUILTIN:
                    for adaptive in (True, False):
                        spec = KernelSpec(osc, coupling, noise, precision, adaptive)
                        kernel = advance_kernel(spec)
                        out.append((f"advance {spec.label}", kernel.py_func,
                                    _advance_signature(precision, noise, osc)))
                        if precision == "float64":
                            out.append((f"pairs {spec.label}", pair_advance_kernel(spec).py_func,
                                        _pair_advance_signature(noise, osc)))
    # The family's terms (stochpend.model.dynamics) on the paper's pendulum: damping with the additive
    # white noise and every term on; then the generic channel.
    pendulum = oscillators.BUILTIN["pendulum"]
    for terms in (frozenset({"damping", "additive"}),
                  frozenset({"additive", *(term.name for term in TABLE)})):
        for precision in precisions:
            for noise in noises.BUILTIN:
                if noise.name not in ("ou", "white"):
                    continue
                spec = KernelSpec(pendulum, "force", noise, precision, True, False, terms)
                out.append((f"advance {spec.label}", advance_kernel(spec).py_func,
                            _advance_signature(precision, noise, pendulum, terms)))
                if precision == "float64":
                    out.append((f"pairs {spec.label}", pair_advance_kernel(spec).py_func,
                                _pair_advance_signature(noise, pendulum, terms)))
    # The additive channel of a coloured noise (additive_noise): damping with the OU (additive_tau
    # > 0), the harmonic and the dichotomous noise on the channel (its own state, draws and
    # events), the paper's white noise multiplying the force.
    builtin = {noise.name: noise for noise in noises.BUILTIN}
    white = builtin["white"]
    for channel_name in ("ou", "harmonic", "dichotomous"):
        channel = builtin[channel_name]
        terms = frozenset({"damping", "additive_noise"})
        for precision in precisions:
            spec = KernelSpec(pendulum, "force", white, precision, True, False, terms, channel)
            out.append((f"advance {spec.label}", advance_kernel(spec).py_func,
                        _advance_signature(precision, white, pendulum, terms, channel)))
            if precision == "float64":
                out.append((f"pairs {spec.label}", pair_advance_kernel(spec).py_func,
                            _pair_advance_signature(white, pendulum, terms, channel)))
    return out + _levels_kernels() + _other_kernels(precisions)


def _levels_kernels() -> list[tuple[str, object, tuple]]:
    """The coupled levels' kernels (:func:`levels_kernel`, 3 and 4 members; 2 is ``pairs``),
    float64 as the pairs, labelled ``levels <KernelSpec> [L=n]``: the paper's pendulum with each
    built-in noise (adaptive steps), OU with fixed steps, the family's term sets of
    :func:`kernel_variants` and the generic additive channel."""
    from stochpend.model import noises, oscillators

    builtin = {noise.name: noise for noise in noises.BUILTIN}
    pendulum = oscillators.BUILTIN["pendulum"]
    specs = [(KernelSpec(pendulum, "force", noise, "float64", True), ()) for noise in noises.BUILTIN]
    specs.append((KernelSpec(pendulum, "force", builtin["ou"], "float64", False), ()))
    for terms in (frozenset({"damping", "additive"}),
                  frozenset({"additive", *(term.name for term in TABLE)})):
        specs.append((KernelSpec(pendulum, "force", builtin["white"], "float64", True, False, terms), ()))
    for channel_name in ("ou", "harmonic", "dichotomous"):
        channel = builtin[channel_name]
        terms = frozenset({"damping", "additive_noise"})
        specs.append((KernelSpec(pendulum, "force", builtin["white"], "float64", True, False, terms, channel), ()))
    out = []
    for spec, _ in specs:
        for levels in integrator.LEVELS[2:]:
            out.append((f"levels {spec.label} [L={levels}]", levels_kernel(spec, levels).py_func,
                        _pair_advance_signature(spec.noise, pendulum, spec.terms, spec.additive, levels)))
    # Pairs carrying every kind of accumulator (a target on an accumulator's mean): the OU
    # pendulum, adaptive and fixed steps, and the family with the generic channel (no events).
    accs = observables.accumulators(_user_objects()["all"])
    for spec in (KernelSpec(pendulum, "force", builtin["ou"], "float64", True),
                 KernelSpec(pendulum, "force", builtin["ou"], "float64", False),
                 KernelSpec(pendulum, "force", builtin["white"], "float64", True, False,
                            frozenset({"damping", "additive_noise"}), builtin["harmonic"])):
        out.append((f"tracked levels {spec.label} [L=2]", tracked_levels_kernel(spec, accs, 2).py_func,
                    _pair_advance_signature(spec.noise, pendulum, spec.terms, spec.additive, 2, tracks=True)))
    return out
