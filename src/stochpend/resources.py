"""What a simulation will cost, estimated before any work: memory and path-steps.

:func:`estimate` computes, from a validated :class:`~stochpend.params.SimulationConfig`,

* the peak host memory of the run: the per-path state of one chunk of paths (57 bytes a path in
  float64, 41 in float32: x, Omega, xi, xi_aux, t, t_comp in the working precision or float64,
  k uint64, status uint8), the per-batch power sums, the energy histograms and their edges,
  and the output Dataset (about the sums, histogram and edges again). A chunk is
  ``min(paths, chunk_paths)`` paths, ``chunk_paths`` defaulting to 2**20 on the CPU: the
  runner never holds more paths than that, whatever the batch size. On the CUDA backend the
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

from stochpend.params import DEFAULT_H_MAX, SimulationConfig

__all__ = [
    "DEFAULT_MAX_PATH_STEPS",
    "LONG_RUN_S",
    "Estimate",
    "available_memory",
    "check",
    "estimate",
    "work_limit",
    "format_bytes",
    "format_seconds",
]

#: Largest lower-bound work accepted without ``max_path_steps``: 1e13 path-steps is about
#: 3 hours on a GPU at :data:`GPU_PATH_STEPS_PER_S`, about 4 days on 16 CPU cores at
#: :data:`CPU_PATH_STEPS_PER_S_PER_CORE`; the paper's largest run (10**4 paths to t = 10**5)
#: is 2e10.
DEFAULT_MAX_PATH_STEPS = 1e13
#: Runs estimated to last longer than this (seconds) announce their estimate on stderr
#: (command line), so that a long run shows a sign of life even with --quiet.
LONG_RUN_S = 10.0
#: Approximate adaptive-step rate of one CPU core (benchmarks: 2.8e7 path-steps/s on 2 cores
#: for the default OU run, docs/performance.md). Machines differ by a factor of a few.
CPU_PATH_STEPS_PER_S_PER_CORE = 1.4e7
#: Assumed rate of one recent NVIDIA GPU (float64): NOT measured (docs/gpu.md has no GPU
#: figures yet); an order of magnitude only.
GPU_PATH_STEPS_PER_S = 1e9
#: Paths per chunk by default: ``stochpend.simulate.DEFAULT_CHUNK_PATHS`` (CPU) and
#: ``stochpend._backends.cuda.DEFAULT_CHUNK_PATHS`` (GPU; also capped by the free device memory).
CPU_CHUNK_PATHS = 1 << 20
CUDA_CHUNK_PATHS = 1 << 26
#: Per-path state: x, Omega, xi, xi_aux in the working precision; t, t_comp (float64), k
#: (uint64), status (uint8).
STATE_BYTES_PER_PATH = {"float64": 4 * 8 + 8 + 8 + 8 + 1, "float32": 4 * 4 + 8 + 8 + 8 + 1}
#: Number of power sums per batch and output time (stochpend._backends.cpu.N_SUMS).
N_SUMS = 9
_DEFAULT_PATHS = 10_000
_DEFAULT_T_MAX = 1000.0
_DEFAULT_N_TIMES = 40
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

    def describe(self) -> str:
        """One line: the work, the rough duration and the memory."""
        mem = f"peak memory {format_bytes(self.memory_bytes)}"
        if self.device_bytes:
            mem += f" (and {format_bytes(self.device_bytes)} on the GPU)"
        return (f"at least {self.min_path_steps:.3g} path-steps (paths x t_max / h_max), roughly "
                f"{format_seconds(self.seconds)} on {self.workers} at ~{self.rate:.2g} path-steps/s; {mem}")


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
    """Bytes of memory available to a new allocation now, or None when unknown."""
    try:
        import psutil
    except ImportError:  # pragma: no cover - psutil is a dependency
        try:
            return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
        except (AttributeError, OSError, ValueError):
            return None
    return int(psutil.virtual_memory().available)


def _cores(threads: Any) -> int:
    if isinstance(threads, int) and not isinstance(threads, bool) and threads >= 1:
        return threads
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


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
    if isinstance(chunk_paths, bool) or not isinstance(chunk_paths, int) or chunk_paths < 1:
        chunk_paths = CUDA_CHUNK_PATHS if cuda else CPU_CHUNK_PATHS
    chunk = min(config.paths, chunk_paths)
    n_times = len(config.times)
    n_cols = config.hist_bins + 2
    bs = config.batch_size
    batches_in_chunk = min(config.n_batches, max(1, -(-chunk // bs)))

    state = chunk * STATE_BYTES_PER_PATH[precision]
    sums = config.n_batches * n_times * N_SUMS * 8
    chunk_sums = batches_in_chunk * n_times * N_SUMS * 8
    hist = n_times * n_cols * 8  # the run's total
    chunk_hist = n_times * n_cols * 8 + batches_in_chunk * n_cols * 8  # the chunk's, and per batch
    edges = n_times * (config.hist_bins + 1) * 8
    # ... and the output Dataset, about sums + hist + edges again (counted in the parts below)

    # Attribute each part to the parameter that makes it large (relative to its default).
    times_name = "n_times"
    r_times = n_times / _DEFAULT_N_TIMES
    hist_name = "hist_bins" if config.hist_bins / _DEFAULT_HIST_BINS >= r_times else times_name
    sums_name = "n_batches" if config.n_batches / _DEFAULT_N_BATCHES >= r_times else times_name
    state_name = "chunk_paths" if chunk == chunk_paths and chunk < config.paths else "paths"
    parts = [
        ("histograms and their edges", hist + chunk_hist + edges + hist + edges, hist_name),
        ("per-batch sums", sums + chunk_sums + sums, sums_name),
    ]
    device = 0
    if cuda:
        device = state
    else:
        parts.append(("path state", state, state_name))
    parts.sort(key=lambda p: -p[1])
    memory = sum(p[1] for p in parts)  # = state + sums + chunk_sums + hist + chunk_hist + edges + dataset

    min_steps = float(config.paths) * config.t_max / config.h_max
    if not math.isfinite(min_steps):
        min_steps = math.inf
    if cuda:
        rate, workers = GPU_PATH_STEPS_PER_S, "the GPU"
    else:
        cores = _cores(threads)
        rate = CPU_PATH_STEPS_PER_S_PER_CORE * cores
        workers = f"{cores} CPU core" + ("s" if cores > 1 else "")
    return Estimate(
        memory_bytes=int(memory), min_path_steps=min_steps, seconds=min_steps / rate,
        device_bytes=int(device), chunk_paths=int(chunk), backend="cuda" if cuda else "cpu",
        precision=precision, workers=workers, rate=rate, parts=tuple(parts),
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
    "n_times": "use fewer output times (n_times or times)",
    "n_batches": "use fewer batches (n_batches)",
    "chunk_paths": "use a smaller chunk_paths",
    "paths": "use fewer paths",
}


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
    est = estimate(config, backend=backend, precision=precision, chunk_paths=chunk_paths, threads=threads)

    available = available_memory()
    if available is not None and est.memory_bytes > available:
        label, _, name = est.parts[0]
        value = {"hist_bins": config.hist_bins, "n_times": len(config.times), "n_batches": config.n_batches,
                 "chunk_paths": est.chunk_paths, "paths": config.paths}[name]
        detail = ", ".join(f"{lbl} {format_bytes(b)}" for lbl, b, _ in est.parts)
        raise ValueError(
            f"{name}={value!r} is not accepted: the run needs {format_bytes(est.memory_bytes)} of memory "
            f"({detail}) and this machine has {format_bytes(available)} available; {_ADVICE[name]}"
        )

    if est.min_path_steps > limit:
        factors = {
            "paths": config.paths / _DEFAULT_PATHS,
            "t_max": config.t_max / _DEFAULT_T_MAX,
            "h_max": DEFAULT_H_MAX / config.h_max,
        }
        name = max(factors, key=lambda k: factors[k])  # the one furthest above its default
        if factors[name] <= 1.0:  # none is: the limit itself is small; paths is the usual knob
            name = "paths"
        value = {"paths": config.paths, "t_max": config.t_max, "h_max": config.h_max}[name]
        raise ValueError(
            f"{name}={value!r} is not accepted: the run needs at least {est.min_path_steps:.3g} path-steps "
            f"(paths x t_max / h_max = {config.paths} x {config.t_max:g} / {config.h_max:g}), roughly "
            f"{format_seconds(est.seconds)} on {est.workers}, above the limit of {limit:.3g}; use fewer "
            "paths, a shorter t_max or a larger h_max, or raise the limit with max_path_steps= "
            "(--max-path-steps)"
        )
    return est
