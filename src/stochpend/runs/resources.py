"""What a simulation will cost, estimated before any work: memory and path-steps.

:func:`estimate` computes, from a validated :class:`~stochpend.model.settings.SimulationConfig`,

* the peak host memory of the run: the per-path state of one chunk of paths (57 bytes a path in
  float64, 45 in float32: x, Omega, xi in the working precision; xi_aux, t, t_comp in float64;
  k uint64, status uint8), the per-batch power sums, the energy histograms and their edges,
  and the output Dataset (about the sums, histogram and edges again). A chunk is whole
  batches, as many as fit in ``chunk_paths`` (2**20 paths by default on the CPU) and at least
  one, as :mod:`stochpend.engine.runner` cuts them: an ensemble of huge batches (paths/n_batches
  beyond chunk_paths) holds a whole batch at a time. On the CUDA backend the
  state lives on the GPU (reported as ``device_bytes``; the backend sizes its chunks to the
  free device memory) and the host holds the rest;
* a lower bound on the work, ``paths * t_max / h_max`` path-steps (no step is longer than
  ``h_max``; the adaptive step makes the real count larger, often by a factor 1.5 to 2);
* a rough duration from that lower bound and :data:`CPU_PATH_STEPS_PER_S_PER_CORE` or
  :data:`GPU_PATH_STEPS_PER_S` (approximate figures, see below): a hint, not a promise.

:func:`check` refuses, with one ``ValueError`` line naming the parameter, a run whose memory
does not fit in the memory available now (``psutil.virtual_memory().available``), or whose
lower-bound work exceeds ``max_path_steps`` (default :data:`DEFAULT_MAX_PATH_STEPS`, raised
with ``max_path_steps=`` or ``stochpend simulate --max-path-steps``).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any

from stochpend.model import observables as observables_
from stochpend.model.observables import N_SUMS, n_sums
from stochpend.model.settings import DEFAULT_H_MAX, DEFAULT_STEP_C, SimulationConfig, short_repr
from stochpend.model.settings import joint_cells as _joint_cells

__all__ = [
    "DEFAULT_MAX_PATH_STEPS",
    "LONG_RUN_S",
    "Estimate",
    "available_memory",
    "check",
    "check_reduced",
    "estimate",
    "estimate_reduced",
    "work_limit",
    "format_bytes",
    "format_seconds",
]

#: Largest lower-bound work accepted without ``max_path_steps``: 1e13 path-steps is about
#: 20 minutes on a GPU at :data:`GPU_PATH_STEPS_PER_S`, about 4 days on 16 CPU cores at
#: :data:`CPU_PATH_STEPS_PER_S_PER_CORE`; the paper's largest run (10**4 paths to t = 10**5)
#: is 2e10.
DEFAULT_MAX_PATH_STEPS = 1e13
#: Runs estimated to last longer than this (seconds) announce their estimate on stderr
#: (command line), so that a long run shows a sign of life even with --quiet.
LONG_RUN_S = 10.0
#: Approximate adaptive-step rate of one CPU core (benchmarks: 2.8e7 path-steps/s on 2 cores
#: for the default OU run, docs/performance.md). Machines differ by a factor of a few.
CPU_PATH_STEPS_PER_S_PER_CORE = 1.4e7
#: Assumed rate of one recent NVIDIA GPU (float64): the order of magnitude of stochpend's
#: fixed-step OU kernel on an H100, 1.3e10 to 1.9e10 path-steps/s (measured by a teammate for the
#: issue "Kernels at the hardware floor"); adaptive steps are unmeasured and slower (more work a
#: step): a hint only. ``python benchmarks/gpu_bench.py`` measures both.
GPU_PATH_STEPS_PER_S = 1e10
#: Seconds Numba takes to compile each CPU kernel of a run on its first use (a cold kernel
#: cache; measured on a shared 2-core machine, compile_time_s of benchmarks/startup.py's demo:
#: 0.6, 3.7, 0.8 and 3.1 s, and 1.1 and 0.7 s for the one-path drivers): the initial
#: conditions, the step loop (SIMD lanes or lock-step blocks, or one path at a time), the
#: statistics, and the bias estimate's coupled pairs. Loading a cached kernel takes
#: milliseconds.
COMPILE_S = {"init": 1.0, "advance": 4.0, "accumulate": 1.0, "pairs": 3.0,
             "advance_one_path": 1.5, "pairs_one_path": 1.0}
#: Paths per chunk by default: ``stochpend.runs.simulate.DEFAULT_CHUNK_PATHS`` (CPU) and
#: ``stochpend.engine.cuda.DEFAULT_CHUNK_PATHS`` (GPU; also capped by the free device memory).
CPU_CHUNK_PATHS = 1 << 20
CUDA_CHUNK_PATHS = 1 << 26
#: Per-path state: x, Omega, xi in the working precision; xi_aux, t, t_comp (float64), k
#: (uint64), status (uint8); 8 or 16 bytes more for the additive channel's xi_a, aux_a
#: (``_additive_bytes``).
STATE_BYTES_PER_PATH = {"float64": 4 * 8 + 8 + 8 + 8 + 1, "float32": 3 * 4 + 8 + 8 + 8 + 8 + 1}
_DEFAULT_PATHS = 10_000
_DEFAULT_T_MAX = 1000.0
_DEFAULT_N_TIMES = 40
#: The smallest step control accepted from a user.
MIN_STEP_C = 1e-6
_DEFAULT_HIST_BINS = 100
_DEFAULT_N_BATCHES = 100


@dataclass(frozen=True)
class Estimate:
    """Resources of one run (see the module docstring for what each figure counts)."""

    memory_bytes: int  # peak host memory
    min_path_steps: float  # paths * t_max / h_max: a lower bound
    seconds: float  # rough duration of min_path_steps at the assumed rate
    device_bytes: int = 0  # GPU memory of the chunk state (cuda backend), else 0
    chunk_paths: int = 0
    backend: str = "cpu"
    precision: str = "float64"
    workers: str = ""  # "2 CPU cores", "the GPU"
    rate: float = 0.0  # assumed path-steps per second
    #: (part of memory, bytes, the parameter that sets it), largest first
    parts: tuple[tuple[str, int, str], ...] = field(default=())
    formula: str = "paths x t_max / h_max"  # what min_path_steps counts
    #: expected seconds compiling the kernels not in Numba's cache (:func:`compile_seconds`;
    #: 0 unless the caller asked, see :func:`with_compile`)
    compile_seconds: float = 0.0

    @property
    def total_seconds(self) -> float:
        """The run's rough duration, compiling included."""
        return self.seconds + self.compile_seconds

    def describe(self) -> str:
        """One line: the work, the rough duration (and the compiling) and the memory."""
        mem = f"peak memory {format_bytes(self.memory_bytes)}"
        if self.device_bytes:
            mem += f" (and {format_bytes(self.device_bytes)} on the GPU)"
        comp = ""
        if self.compile_seconds > 0:
            comp = (f", plus ~{format_seconds(self.compile_seconds)} compiling kernels (first use, "
                    "cached after)")
        return (f"at least {self.min_path_steps:.3g} path-steps ({self.formula}), roughly "
                f"{format_seconds(self.seconds)} on {self.workers} at ~{self.rate:.2g} path-steps/s"
                f"{comp}; {mem}")


def compile_seconds(config: Any, *, backend: str = "cpu", precision: str = "float64",
                    pairs: bool = True, counted: set | None = None, calibrated: bool = True) -> float:
    """Expected seconds compiling the CPU kernels that a run of ``config`` needs and Numba's
    cache lacks (:data:`COMPILE_S` each; 0 when all are cached), on this machine now: times the
    compile scale measured here and the load's slowdown (:mod:`stochpend.numerics._calibration`;
    ``calibrated=False``: the built-in figures alone). ``pairs``: the run estimates
    its bias (the coupled pairs' kernel). ``counted``: kernels counted already, for an earlier
    run of the same process (updated). The GPU's kernels are not counted (CUDA compiles them at
    launch). Imports the CPU backend (Numba); compiles nothing."""
    if backend != "cpu":
        return 0.0
    from stochpend.engine import cpu
    from stochpend.numerics._jitcache import in_cache

    seconds = 0.0
    spec = cpu.spec_for(config, precision)
    for kind, kernel in cpu.compiled_kernels(spec, pairs=pairs, observables=getattr(config, "observables", ())).items():
        if in_cache(kernel) or (counted is not None and kernel in counted):
            continue
        seconds += COMPILE_S[kind]
        if counted is not None:
            counted.add(kernel)
    if calibrated and seconds > 0:
        from stochpend.numerics import _calibration

        seconds *= _calibration.compile_scale() * _calibration.slowdown(1)  # Numba compiles on one thread
    return seconds


def with_compile(est: Estimate, config: Any, *, pairs: bool = True,
                 counted: set | None = None) -> Estimate:
    """``est`` with the expected compile time of ``config``'s kernels (:func:`compile_seconds`)."""
    import dataclasses

    return dataclasses.replace(est, compile_seconds=compile_seconds(
        config, backend=est.backend, precision=est.precision, pairs=pairs, counted=counted))


def format_bytes(n: float) -> str:
    """1536 -> '1.5 KiB' (binary units)."""
    try:
        n = float(n)
    except OverflowError:  # an int beyond 1e308
        return "more than 1e308 B"
    if not math.isfinite(n):
        return f"{n} B"
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"):
        if abs(n) < 1024 or unit == "EiB":
            return f"{n:.0f} B" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024.0
    raise AssertionError  # pragma: no cover


def format_seconds(s: float) -> str:
    """Seconds in the largest sensible unit: '12 s', '3.5 min', '2.0 h', '4.1 days', '3e+05 years'."""
    if not math.isfinite(s):
        return "forever"
    if s < 90:
        return f"{s:.2g} s"
    if s < 5400:
        return f"{s / 60:.2g} min"
    if s < 2 * 86400:
        return f"{s / 3600:.2g} h"
    if s < 365.25 * 86400:
        return f"{s / 86400:.2g} days"
    return f"{s / (365.25 * 86400):.2g} years"


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation now, or None when unknown: the machine's
    available memory, or less where this process's control group (a Slurm job, a container)
    has a memory limit (:func:`cgroup_headroom`), since there the kernel kills the process
    at the limit whatever the machine has."""
    return _memory_bound()[0]


def _memory_bound() -> tuple[int | None, str]:
    """``(bytes, what bounds them)``: :func:`available_memory` and, for the refusal's wording,
    "this machine has" or "this process's memory limit (cgroup) leaves"."""
    try:
        import psutil
    except ImportError:  # pragma: no cover - psutil is a dependency
        try:
            machine = int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (AttributeError, OSError, ValueError):
            machine = None
    else:
        machine = int(psutil.virtual_memory().available)
    bounds = [(machine, "this machine has"), (cgroup_headroom(), "this process's memory limit (cgroup) leaves"),
              (address_space_headroom(), "this process's address-space limit (ulimit -v) leaves")]
    known = [(n, what) for n, what in bounds if n is not None]
    return min(known, key=lambda b: b[0]) if known else (None, "this machine has")


def address_space_headroom() -> int | None:
    """Bytes this process may still map under its address-space limit (``ulimit -v``, RLIMIT_AS,
    common on shared login nodes), or None without one: beyond it every allocation fails."""
    try:
        import resource

        limit = resource.getrlimit(resource.RLIMIT_AS)[0]
        if limit == resource.RLIM_INFINITY:
            return None
        import psutil

        return max(0, int(limit) - int(psutil.Process().memory_info().vms))
    except (ImportError, OSError, ValueError):  # pragma: no cover - no resource module or /proc
        return None


#: A cgroup v1 limit at or above this is "no limit" (the kernel writes 2**63 rounded to pages).
_NO_LIMIT = 1 << 60


def _read_int(path: str) -> int | None:
    try:
        with open(path) as f:
            text = f.read().strip()
    except OSError:
        return None
    try:
        return int(text)
    except ValueError:
        return None  # cgroup v2 writes "max" for no limit


def _stat_value(path: str, key: str) -> int:
    try:
        with open(path) as f:
            for line in f:
                name, _, value = line.partition(" ")
                if name == key:
                    return int(value)
    except (OSError, ValueError):
        pass
    return 0


def cgroup_headroom(root: str = "/sys/fs/cgroup", proc_cgroup: str = "/proc/self/cgroup") -> int | None:
    """Bytes this process's memory control group can still take: the smallest of limit - usage
    + reclaimable page cache (``inactive_file``) over the group and its ancestors (cgroup v2,
    ``memory.max``), or of the v1 memory controller's group (``memory.limit_in_bytes``); None
    where no limit is set or the files cannot be read."""
    try:
        with open(proc_cgroup) as f:
            lines = f.read().splitlines()
    except OSError:
        return None
    best: int | None = None

    def consider(limit: int | None, usage: int | None, cache: int) -> None:
        nonlocal best
        if limit is None or usage is None or limit >= _NO_LIMIT:
            return
        room = max(0, limit - usage + cache)
        best = room if best is None else min(best, room)

    for line in lines:
        hier, _, rest = line.partition(":")
        controllers, _, path = rest.partition(":")
        if hier == "0" and controllers == "":  # v2: walk up from the group to the root
            parts = [p for p in path.split("/") if p]
            for depth in range(len(parts), -1, -1):
                d = os.path.join(root, *parts[:depth])
                consider(_read_int(os.path.join(d, "memory.max")),
                         _read_int(os.path.join(d, "memory.current")),
                         _stat_value(os.path.join(d, "memory.stat"), "inactive_file"))
        elif "memory" in controllers.split(","):  # v1; in a container the group is the mount's root
            for d in (os.path.join(root, "memory", *[p for p in path.split("/") if p]),
                      os.path.join(root, "memory")):
                if os.path.exists(os.path.join(d, "memory.limit_in_bytes")):
                    consider(_read_int(os.path.join(d, "memory.limit_in_bytes")),
                             _read_int(os.path.join(d, "memory.usage_in_bytes")),
                             _stat_value(os.path.join(d, "memory.stat"), "total_inactive_file"))
                    break
    return best


def _cores(threads: Any) -> int:
    if isinstance(threads, int) and not isinstance(threads, bool) and threads >= 1:
        return threads
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def _memory_parts(*, paths: int, chunk: int, chunk_given: bool, batch_size: int, n_batches: int,
                  n_times: int, hist_bins: int, bytes_per_path: int,
                  n_sums: int = N_SUMS, joint_cells: int = 0) -> list[tuple[str, int, str]]:
    """(part, bytes, the parameter that makes it large), largest first. ``n_sums``: columns of
    the per-batch sums (the statistics table's and the run's user observables').
    ``joint_cells``: the joint (x, Omega) histogram's (``params.joint_cells``; 0: none)."""
    n_cols = hist_bins + 2
    batches_in_chunk = min(n_batches, max(1, -(-chunk // batch_size)))
    state = chunk * bytes_per_path
    sums = n_batches * n_times * n_sums * 8
    chunk_sums = batches_in_chunk * n_times * n_sums * 8
    hist = n_times * n_cols * 8  # the run's total
    chunk_hist = n_times * n_cols * 8 + batches_in_chunk * n_cols * 8  # the chunk's, and per batch
    edges = n_times * (hist_bins + 1) * 8
    # The output Dataset holds about sums + hist + edges again: counted twice below.
    # x/x_default >= n_times/40, in integers (hist_bins may be any int, even 10**400)
    hist_name = "hist_bins" if hist_bins * _DEFAULT_N_TIMES >= n_times * _DEFAULT_HIST_BINS else "n_times"
    sums_name = "n_batches" if n_batches * _DEFAULT_N_TIMES >= n_times * _DEFAULT_N_BATCHES else "n_times"
    state_name = "chunk_paths" if chunk_given and chunk < paths else "paths"
    parts = [
        ("histograms and their edges", 2 * hist + chunk_hist + 2 * edges, hist_name),
        ("per-batch sums", 2 * sums + chunk_sums, sums_name),
        ("path state", state, state_name),
    ]
    if joint_cells:
        # Per output time, 3 integers a cell in the run's total and the chunk's; the Dataset's
        # counts, density and error; and one count a cell per batch of the chunk.
        joint = n_times * joint_cells * 8 * 9 + batches_in_chunk * joint_cells * 8
        parts.append(("joint (x, Omega) histogram", joint, "joint_bins"))
    parts.sort(key=lambda p: -p[1])
    return parts


def kernel_kind(config: Any, precision: str = "float64") -> str:
    """The calibration's name for the CPU kernel of ``config`` ("cpu pendulum/force/ou/..."): a
    quartic oscillator's or the one-path kernel's rate is not the pendulum's SIMD lanes', nor is
    a run's with per-path accumulators (" tracked lanes": the lanes also update each path's
    slots after every step, about 1.2 times slower with the displacement on the OU pendulum;
    " tracked": one path at a time, where the KernelSpec has no lanes, and the lanes' kind
    before they carried accumulators, 2.5 to 3.4 times slower: its samples are not theirs).
    Imports the CPU backend (Numba); "cpu" where the kernel cannot be named."""
    try:
        from stochpend.engine import cpu, integrator
        from stochpend.model import observables

        tracked = observables.accumulators(observables.objects(getattr(config, "observables", ())))
        spec = cpu.spec_for(config, precision)
        if not tracked:
            return f"cpu {spec.label}"
        return f"cpu {spec.label} tracked" + (" lanes" if integrator.lanes_supported(spec) else "")
    except Exception:  # a configuration the backend refuses: the caller's own check says why
        return "cpu"


def _rate(cuda: bool, threads: Any, kind: str = "cpu") -> tuple[float, str]:
    """The expected rate of the lower-bound work on the CPU's ``threads`` (or the GPU), and on
    what: measured on this machine by earlier runs of the same kernel ``kind`` and scaled to the
    load of now (:mod:`stochpend.numerics._calibration`), else :data:`CPU_PATH_STEPS_PER_S_PER_CORE` a
    core. Never another kernel's: a quartic oscillator's runs, whose energy grows and whose steps
    shrink far below h_max, do a thousand times the lower bound's work, the pendulum's twice."""
    if cuda:
        return GPU_PATH_STEPS_PER_S, "the GPU"
    from stochpend.numerics import _calibration

    cores = _cores(threads)
    rate, measured = _calibration.rate(kind, CPU_PATH_STEPS_PER_S_PER_CORE, cores)
    where = f"{cores} CPU core" + ("s" if cores > 1 else "")
    return rate, where + (" (rate measured here)" if measured else "")


def _valid_chunk(chunk_paths: Any) -> bool:
    return isinstance(chunk_paths, int) and not isinstance(chunk_paths, bool) and chunk_paths >= 1


def estimate(
    config: SimulationConfig,
    *,
    backend: str = "cpu",
    precision: str = "float64",
    chunk_paths: int | None = None,
    threads: int | None = None,
) -> Estimate:
    """Peak memory, lower-bound path-steps and a rough duration of ``config``'s run.

    ``backend``, ``precision``, ``chunk_paths`` and ``threads`` are read leniently (an
    unknown value counts as the default): :func:`stochpend.simulate` validates them itself.
    ``backend="auto"`` is estimated as the CPU.
    """
    cuda = backend == "cuda"
    if precision not in STATE_BYTES_PER_PATH:
        precision = "float64"
    given = _valid_chunk(chunk_paths)
    requested = chunk_paths if given and chunk_paths is not None else (CUDA_CHUNK_PATHS if cuda else CPU_CHUNK_PATHS)
    # As stochpend.engine.runner chunks: whole batches, at least one (so a huge batch is one chunk).
    chunk = min(config.paths, max(1, requested // config.batch_size) * config.batch_size)
    parts = _memory_parts(paths=config.paths, chunk=chunk, chunk_given=given, batch_size=config.batch_size,
                          n_batches=config.n_batches, n_times=len(config.times), hist_bins=config.hist_bins,
                          bytes_per_path=STATE_BYTES_PER_PATH[precision] + _additive_bytes(config),
                          n_sums=n_sums(config), joint_cells=_joint_cells(config))
    n_passages = sum(isinstance(observables_.get(name), observables_.FirstPassage) for name in config.observables)
    if n_passages:  # every path's passage time (stochpend.model.passage), and its sorted copy
        parts.append(("first-passage times", 2 * n_passages * config.paths * 8, "paths"))
        parts.sort(key=lambda p: -p[1])
    device = 0
    if cuda:  # the state lives on the GPU
        device = next(b for label, b, _ in parts if label == "path state")
        parts = [p for p in parts if p[0] != "path state"]
    min_steps, formula = _min_path_steps(config)
    rate, workers = _rate(cuda, threads, "cpu" if cuda else kernel_kind(config, precision))
    return Estimate(
        memory_bytes=int(sum(p[1] for p in parts)), min_path_steps=min_steps, seconds=min_steps / rate,
        device_bytes=int(device), chunk_paths=int(chunk), backend="cuda" if cuda else "cpu",
        precision=precision, workers=workers, rate=rate, parts=tuple(parts), formula=formula,
    )


def _additive_bytes(config: Any) -> int:
    """The additive channel's per-path state (float64 each): xi_a for the Ornstein-Uhlenbeck
    channel, xi_a and aux_a for the generic one (``additive_noise``), for a run with it."""
    from stochpend.model import dynamics

    return 8 * len(dynamics.additive_arrays(config))


def _min_path_steps(config: Any) -> tuple[float, str]:
    """A lower bound on the path-steps of a stepped run, and what it counts: no step is longer
    than h_max, and every path stops at every output time (a step ends there), so at least
    ``max(paths x t_max / h_max, paths x output times)``."""
    by_step = float(config.paths) * config.t_max / config.h_max
    by_times = float(config.paths) * len(config.times)
    if by_times > by_step:
        return by_times, "paths x output times"
    return by_step, "paths x t_max / h_max"


#: Per-path state of the reduced dynamics (stochpend.runs.reduced): the energy variable, the status,
#: the final energies, and xi for the second order.
REDUCED_BYTES_PER_PATH = 8 + 1 + 8
REDUCED_CHUNK_PATHS = 1 << 18  # stochpend.runs.reduced.DEFAULT_CHUNK_PATHS


def estimate_reduced(config: Any, *, chunk_paths: int | None = None, threads: int | None = None,
                     keep_energies: bool = False) -> Estimate:
    """:func:`estimate` for :func:`stochpend.runs.reduced.simulate_reduced` (a ``ReducedConfig``).

    Its runner advances whole batches (a chunk is at least one batch); the work is
    ``paths * t_max / h_max`` steps for the second order and one exact transition per path and
    output time for the others. ``keep_energies``: the run also returns every path's final
    energy (:func:`stochpend.runs.reduced.sample_reduced`, 8 bytes a path).
    """
    given = _valid_chunk(chunk_paths)
    bs = config.batch_size
    chunk = min(config.paths, max(1, (chunk_paths if given else REDUCED_CHUNK_PATHS) // bs) * bs)
    per_path = REDUCED_BYTES_PER_PATH + (8 if config.order == "second" else 0)
    parts = _memory_parts(paths=config.paths, chunk=chunk, chunk_given=given, batch_size=bs,
                          n_batches=config.n_batches, n_times=len(config.times), hist_bins=config.hist_bins,
                          bytes_per_path=per_path)
    if keep_energies:
        parts = sorted([*parts, ("per-path energies", 8 * config.paths, "paths")], key=lambda p: -p[1])
    if config.order == "second":
        min_steps, formula = _min_path_steps(config)
    else:
        min_steps, formula = float(config.paths) * len(config.times), "paths x output times"
    rate, workers = _rate(False, threads, f"reduced-{config.order}")
    return Estimate(
        memory_bytes=int(sum(p[1] for p in parts)), min_path_steps=min_steps, seconds=min_steps / rate,
        chunk_paths=int(chunk), workers=workers, rate=rate, parts=tuple(parts), formula=formula,
    )


def work_limit(max_path_steps: Any = None) -> float:
    """The path-step limit ``max_path_steps`` stands for (None: the default); validates it."""
    if max_path_steps is None:
        return DEFAULT_MAX_PATH_STEPS
    accepted = "a number > 0 of path-steps (inf: no limit)"
    if isinstance(max_path_steps, bool):
        raise ValueError(f"max_path_steps={max_path_steps!r} is not accepted: {accepted}")
    try:
        v = float(max_path_steps)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"max_path_steps={max_path_steps!r} is not accepted: {accepted}") from None
    if not v > 0:  # also NaN
        raise ValueError(f"max_path_steps={max_path_steps!r} is not accepted: {accepted}")
    return v


_ADVICE = {
    "hist_bins": "use fewer histogram bins (hist_bins, --hist-bins)",
    "joint_bins": "use fewer joint histogram bins (joint_bins, --joint-bins) or output times",
    "n_times": "use fewer output times (n_times or times)",
    "n_batches": "use fewer batches (n_batches)",
    "chunk_paths": "use a smaller chunk_paths",
    "paths": "use fewer paths",
}


def _refuse_memory(est: Estimate, values: dict[str, Any]) -> None:
    available, where = _memory_bound()
    if available is not None and est.memory_bytes > available:
        _, _, name = est.parts[0]
        detail = ", ".join(f"{label} {format_bytes(b)}" for label, b, _ in est.parts)
        raise ValueError(
            f"{name}={short_repr(values[name])} is not accepted: the run needs {format_bytes(est.memory_bytes)} "
            f"of memory ({detail}) and {where} {format_bytes(available)} available; {_ADVICE[name]}"
        )


def _refuse_work(est: Estimate, limit: float, factors: dict[str, float], values: dict[str, Any],
                 formula: str, advice: str = "use fewer paths, a shorter t_max or a larger h_max") -> None:
    if est.min_path_steps <= limit:
        return
    name = max(factors, key=lambda k: factors[k])  # the one furthest above its default
    if factors[name] <= 1.0:  # none is: the limit itself is small; paths is the usual knob
        name = "paths"
    raise ValueError(
        f"{name}={short_repr(values[name])} is not accepted: the run needs at least {est.min_path_steps:.3g} "
        f"path-steps ({formula}), roughly {format_seconds(est.seconds)} on {est.workers}, above the limit "
        f"of {limit:.3g}; {advice}, or raise the limit with max_path_steps= (--max-path-steps)"
    )


def check(
    config: SimulationConfig,
    *,
    backend: str = "cpu",
    precision: str = "float64",
    chunk_paths: int | None = None,
    max_path_steps: float | None = None,
    threads: int | None = None,
) -> Estimate:
    """Refuse, before any work, a run that cannot fit in memory or exceeds the work limit.

    Raises ``ValueError`` (one line naming the parameter responsible, the figures and what
    to change); returns the :class:`Estimate` otherwise. ``max_path_steps`` (default
    :data:`DEFAULT_MAX_PATH_STEPS`; ``math.inf`` for no limit) bounds ``paths * t_max /
    h_max``.
    """
    limit = work_limit(max_path_steps)
    if 0 < config.step_c < MIN_STEP_C:
        # Far below any accuracy need (1e-300): every path would exhaust its step budget, which
        # the run would then report as a physical blow-up. (--accuracy auto refines below it.)
        raise ValueError(f"step_c={config.step_c!r} is not accepted: 0 (fixed step) or a number >= "
                         f"{MIN_STEP_C:g}; the default is {DEFAULT_STEP_C:g}")
    est = estimate(config, backend=backend, precision=precision, chunk_paths=chunk_paths, threads=threads)
    values = {"hist_bins": config.hist_bins, "n_times": len(config.times), "n_batches": config.n_batches,
              "chunk_paths": est.chunk_paths, "paths": config.paths, "t_max": config.t_max,
              "h_max": config.h_max, "joint_bins": ",".join(map(str, config.joint_bins))}
    # The work first: a run that would never end is refused as such, whatever else it needs.
    factors = {"paths": config.paths / _DEFAULT_PATHS, "t_max": config.t_max / _DEFAULT_T_MAX,
               "h_max": DEFAULT_H_MAX / config.h_max}
    if est.formula == "paths x output times":
        factors = {"paths": config.paths / _DEFAULT_PATHS, "n_times": len(config.times) / _DEFAULT_N_TIMES}
        formula = f"paths x output times = {config.paths} x {len(config.times)}"
        advice = "use fewer paths or output times"
    else:
        formula = f"paths x t_max / h_max = {config.paths} x {config.t_max:g} / {config.h_max:g}"
        advice = "use fewer paths, a shorter t_max or a larger h_max"
    _refuse_work(est, limit, factors, values, formula, advice)
    _refuse_memory(est, values)
    return est


def check_reduced(config: Any, *, chunk_paths: int | None = None, max_path_steps: float | None = None,
                  threads: int | None = None, keep_energies: bool = False) -> Estimate:
    """:func:`check` for the reduced dynamics (a ``stochpend.runs.reduced.ReducedConfig``)."""
    limit = work_limit(max_path_steps)
    est = estimate_reduced(config, chunk_paths=chunk_paths, threads=threads, keep_energies=keep_energies)
    n_times = len(config.times)
    values = {"hist_bins": config.hist_bins, "n_times": n_times, "n_batches": config.n_batches,
              "chunk_paths": est.chunk_paths, "paths": config.paths, "t_max": config.t_max,
              "h_max": config.h_max}
    _refuse_memory(est, values)
    if config.order == "second" and est.formula != "paths x output times":
        factors = {"paths": config.paths / _DEFAULT_PATHS, "t_max": config.t_max / _DEFAULT_T_MAX,
                   "h_max": 0.05 * config.tau / config.h_max}
        formula = f"paths x t_max / h_max = {config.paths} x {config.t_max:g} / {config.h_max:g}"
        advice = "use fewer paths, a shorter t_max or a larger h_max"
    else:
        factors = {"paths": config.paths / _DEFAULT_PATHS, "n_times": n_times / _DEFAULT_N_TIMES}
        formula = f"paths x output times = {config.paths} x {n_times}"
        advice = "use fewer paths or output times"
    _refuse_work(est, limit, factors, values, formula, advice)
    return est
