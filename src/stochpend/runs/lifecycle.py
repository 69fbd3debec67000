"""One run's lifecycle, written once: a validated :class:`RunOptions` and :func:`execute`.

A run of one configuration goes through the same steps whoever asks for it (``stochpend.
simulate`` and :func:`stochpend.runs.simulate.run`, a checkpointed run or its resume in
:mod:`stochpend.runs.checkpoint`, a run of :mod:`stochpend.paper.reproduce`): the thread count, the
compile clock and its note, the compile helper, ``accuracy="auto"``'s pilot, the host loop
(:func:`stochpend.engine.runner.run_batches`, saving and resuming through a checkpointer when given),
the bias estimate, and the Dataset with its provenance. :func:`execute` does them in that order;
the callers only validate and hand over a :class:`RunOptions`, and add what is theirs (where the result
goes, the per-batch sums). Where a run runs is decided here too (:func:`resolve_backend`,
:func:`check_precision`; importable from :mod:`stochpend.simulate` as before).

Sweeps run blocks of batches (:mod:`stochpend.runs._blocks`) and estimate each set's bias after the
blocks (:mod:`stochpend.sweep`); the reduced dynamics have their own loop
(:mod:`stochpend.runs.reduced`).
"""

from __future__ import annotations

import contextlib
import platform
import sys
import time as _time
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

import numba
import numpy as np
import xarray as xr

from stochpend._version import __version__
from stochpend.engine import integrator, runner
from stochpend.engine.runner import RunState
from stochpend.model import observables
from stochpend.model import user_models as models
from stochpend.model.power_sums import EnsembleSums
from stochpend.model.settings import SimulationConfig, hist_edges, joint_grid
from stochpend.numerics import _cputarget
from stochpend.numerics._jitcache import CompileClock
from stochpend.runs import _compile_helper, bias, resources
from stochpend.text.progress import NoProgress, Progress

__all__ = ["Checkpointing", "RunOptions", "Saver", "check_precision", "check_threads", "compile_note", "cuda_status", "execute",
           "numba_threads", "provenance", "resolve_backend"]


class Saver(runner.Checkpointer, Protocol):
    """What a checkpointed run saves through (:class:`stochpend.runs.checkpoint.FileCheckpointer`)."""

    def record(self, config: SimulationConfig, bias_paths: int, choice: bias.LevelChoice | None) -> None:
        """The run as it will go on: the configuration that runs (refined by ``auto``), the
        pairs of its bias estimate and the level ``auto`` chose; saved with every checkpoint."""

    def signals(self) -> contextlib.AbstractContextManager[None]:
        """Ctrl-C and SIGTERM deferred to the next kernel boundary while the batches run."""

    def elapsed_s(self) -> float:
        """Seconds the run has taken, its earlier (interrupted) sessions included."""

    def attrs(self) -> dict[str, Any]:
        """The checkpoint's attributes for the result (file, interval, resumptions)."""


@dataclass(frozen=True)
class Checkpointing:
    """A checkpointed run: its :class:`Saver`, and when it resumes, the state it stopped in and
    the level choice ``accuracy="auto"`` made before (so that the pilot is not run again)."""

    saver: Saver
    resume: RunState | None = None
    choice: bias.LevelChoice | None = None


@dataclass(frozen=True)
class RunOptions:
    """How one configuration is run, validated: backend, precision, threads, chunk, bias pairs,
    accuracy, budget and checkpoints (what is simulated is the
    :class:`~stochpend.model.settings.SimulationConfig`). Build it with :meth:`build`.

    ``bias_paths`` is resolved (0: no estimate; with ``accuracy="auto"`` the pilot's pairs, the
    default when 0); ``threads``/``chunk_paths`` None: Numba's threads and the backend's chunk.
    """

    config: SimulationConfig
    backend: str = "cpu"
    precision: str = "float64"
    threads: int | None = None
    chunk_paths: int | None = None
    bias_paths: int = 0
    accuracy: str = "fixed"
    rtol: float | None = None
    max_path_steps: float | None = None
    checkpointing: Checkpointing | None = None

    @classmethod
    def build(cls, config: SimulationConfig, *, backend: str = "cpu", precision: str = "float64",
              threads: Any = None, chunk_paths: Any = None, bias_paths: Any = None,
              accuracy: Any = "fixed", rtol: Any = None, max_path_steps: float | None = None,
              checkpointing: Checkpointing | None = None) -> RunOptions:
        """Validate the settings of a run of ``config`` (a ``ValueError`` of one line naming the
        parameter; memory and work are checked too, :func:`stochpend.runs.resources.check`) and
        resolve ``backend="auto"`` and the default ``bias_paths``."""
        accuracy, rtol = bias.check_accuracy(accuracy, rtol)
        bias_paths = bias.check_bias_paths(bias_paths, config.paths)
        resources.check(config, backend=backend, precision=precision, chunk_paths=chunk_paths,
                        max_path_steps=max_path_steps)
        backend = resolve_backend(backend)
        check_precision(precision, backend)
        check_threads(threads)
        _cputarget.apply_environment()  # STOCHPEND_CPU_TARGET: refused here if it cannot hold
        if chunk_paths is not None and (isinstance(chunk_paths, bool) or not isinstance(chunk_paths, int)
                                        or chunk_paths < 1):
            raise ValueError(f"chunk_paths={chunk_paths!r} is not accepted: an integer >= 1")
        return cls(config, backend, precision, threads, chunk_paths, bias_paths, accuracy, rtol,
                   max_path_steps, checkpointing)


def check_precision(precision: str, backend: str) -> None:
    """Refuse an unknown precision, or float32 anywhere but the CUDA backend."""
    if precision not in integrator.PRECISIONS:
        raise ValueError(f"precision={precision!r} is not accepted: one of float64, float32")
    if precision == "float32" and backend != "cuda":
        raise ValueError("precision='float32' is not accepted with backend='cpu': float32 runs on the CUDA backend")


def cuda_status(backend: str = "cuda") -> tuple[bool, str, bool]:
    """``(usable, why, broken)`` for the CUDA backend: the driver and device
    (``_backends.cuda.availability``), then a tiny kernel compiled and launched once per process
    (``_backends.cuda_probe``). ``broken``: a GPU was found but the CUDA stack cannot compile or
    run on it. For ``backend="auto"`` the simulator counts as not usable (never picked
    implicitly) and is not probed."""
    try:
        from stochpend.engine import cuda as _cuda
    except Exception as exc:  # numba without a CUDA target
        return False, f"numba.cuda cannot be imported ({type(exc).__name__})", False
    usable, why = _cuda.availability()
    if not usable:
        return False, why, False
    if backend == "auto" and _cuda._simulator_enabled():
        return False, why, False  # never pick the (slow) simulator implicitly
    from stochpend.engine import cuda_probe

    ok, probe_why = cuda_probe.probe()
    if not ok:
        return False, f"{why}: {probe_why}", True
    return True, why, False


def resolve_backend(backend: str, *, note: Callable[[str], None] | None = None) -> str:
    """Map "auto" to the GPU when one is usable (else the CPU); refuse an unusable "cuda".

    A GPU whose CUDA stack cannot compile a kernel is not usable: "auto" then runs on the CPU
    and says why in one line, through ``note`` (default: a ``RuntimeWarning``).
    """
    if backend == "cpu":
        return "cpu"
    if backend not in ("auto", "cuda"):
        raise ValueError(f"backend={backend!r} is not accepted: one of cpu, cuda, auto")
    usable, why, broken = cuda_status(backend)
    if usable:
        return "cuda"
    if backend == "auto":
        if broken:
            message = f"backend='auto' runs on the CPU: the CUDA stack is unusable ({why})"
            if note is None:
                warnings.warn(message, RuntimeWarning, stacklevel=2)
            else:
                note(message)
        return "cpu"
    advice = ("install a numba-cuda that works with this numpy (pip install 'stochpend[cuda]' "
              "pins one)" if broken else "install the extra with pip install 'stochpend[cuda]' on "
              "a machine with an NVIDIA GPU")
    raise ValueError(f"backend='cuda' is not accepted: {why}; {advice}, or use backend='cpu'")


def check_threads(threads: Any) -> None:
    """Refuse a thread count this machine cannot run (``None``: the default)."""
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int)
                                or not 1 <= threads <= numba.config.NUMBA_NUM_THREADS):
        raise ValueError(f"threads={threads!r} is not accepted: an integer in [1, {numba.config.NUMBA_NUM_THREADS}]")


@contextlib.contextmanager
def numba_threads(threads: int | None) -> Iterator[int]:
    """Run the block on ``threads`` Numba threads (None: as set), then restore the count;
    yields the count that was set before."""
    previous = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    try:
        yield previous
    finally:
        numba.set_num_threads(previous)


def execute(run: RunOptions, *, progress: Progress | None = None) -> tuple[xr.Dataset, EnsembleSums]:
    """Run ``run`` from start (or from its checkpoint) to its Dataset.

    Returns the Dataset of :func:`stochpend.simulate` (with ``checkpoint``, ``resumed`` and
    ``command_line`` attributes when checkpointed) and the sums it was built from
    (``sums.sums``: shape (n_batches, n_times, N_SUMS)). Compiling is timed apart
    (``compile_time_s``): ``wall_time_s`` and ``path_steps_per_s`` are the run's own; a resumed
    run's earlier sessions count in its ``wall_time_s``.
    """
    progress = progress or NoProgress()
    config = run.config
    saving = run.checkpointing
    choice = None if saving is None else saving.choice
    pilot = run.accuracy == "auto" and choice is None
    # "auto" reports the pilot's bias scaled to the chosen level: no estimate at the end.
    estimating = run.accuracy != "auto" and run.bias_paths > 0
    helper = None  # the compile helper, compiling the pair kernel meanwhile (the run waits for it)
    calibrating = _Calibrating(config, run, pairs=estimating or pilot)
    # The pair kernel counts also where the helper compiles it: the run waits for the helper
    # (compile_time_s includes the wait), and the calibration compares with the same sum.
    compile_clock = CompileClock(lambda: compile_note(
        config, run.backend, run.precision, pairs=estimating or pilot))
    started = _time.perf_counter()

    def elapsed() -> float:
        return saving.saver.elapsed_s() if saving is not None else _time.perf_counter() - started

    waited = 0.0
    est = None
    with numba_threads(run.threads) as previous_threads:
        try:
            compile_clock.__enter__()
            if estimating:
                helper = _compile_helper.start(config, backend=run.backend, bias_paths=run.bias_paths)
            if pilot:
                choice = bias.choose_level(config, run.bias_paths or bias.default_bias_paths(config.paths),
                                           rtol=run.rtol, progress=progress, backend=run.backend)
                # the refined run must pass the same memory and work checks as the one asked for
                resources.check(choice.config, backend=run.backend, precision=run.precision,
                                chunk_paths=run.chunk_paths, max_path_steps=run.max_path_steps)
            if choice is not None:
                config = choice.config
            resume = None if saving is None else saving.resume
            first, stop = (0, config.n_batches) if resume is None else (resume.first_batch, resume.stop_batch)
            guard: contextlib.AbstractContextManager[None] = contextlib.nullcontext()
            if saving is not None:
                saving.saver.record(config, run.bias_paths, choice)
                guard = saving.saver.signals()
            with guard:
                sums, path_steps = runner.run_batches(
                    config, first, stop, backend=run.backend, precision=run.precision,
                    chunk_paths=run.chunk_paths, progress=progress,
                    checkpointer=None if saving is None else saving.saver, resume=resume)
            wall_main = elapsed() - compile_clock.seconds
            # The estimate is not checkpointed: a few per cent of the run, redone in full if the
            # process stops during it (the checkpoint of the finished batches is still there).
            if choice is not None:
                est = choice.extrapolated()
            elif estimating:
                if helper is not None:
                    waited = helper.wait()  # compiling the pair kernel, in the helper
                est = bias.estimate(config, run.bias_paths, progress=progress, backend=run.backend)
        finally:
            if helper is not None:
                helper.stop()
            compile_clock.__exit__(None, None, None)
            compile_clock.seconds += waited
    # Compiling (a cold kernel cache) is reported apart: wall_time_s and path_steps_per_s are
    # the run's own, comparable between a first and a later run.
    attrs = provenance(config, backend=run.backend, precision=run.precision,
                       threads=run.threads or previous_threads,
                       wall_time_s=elapsed() - compile_clock.seconds, path_steps=path_steps)
    attrs["simulation_wall_time_s"] = wall_main
    attrs["compile_time_s"] = compile_clock.seconds
    calibrating.record(config, compile_s=compile_clock.seconds, wall_s=elapsed() - compile_clock.seconds,
                       threads=run.threads or previous_threads, resumed=saving is not None and saving.resume is not None)
    if saving is not None:
        attrs.update(saving.saver.attrs())
    ds = sums.to_dataset(np.asarray(config.times), hist_edges(config), attrs, joint_grid(config))
    if est is not None:
        bias.attach(ds, est, choice)
    return ds, sums


class _Calibrating:
    """What a run measures for the estimates of later runs (:mod:`stochpend.numerics._calibration`): its
    compile time against the built-in figure of the kernels it compiles, and its rate of
    lower-bound path-steps (what :func:`stochpend.runs.resources.estimate` divides by the rate)."""

    def __init__(self, config: SimulationConfig, run: RunOptions, *, pairs: bool) -> None:
        from stochpend.numerics import _calibration

        self.backend = run.backend
        self.load = _calibration.current_load()  # before this run adds its own threads
        self.builtin_compile_s = resources.compile_seconds(config, backend=run.backend, precision=run.precision,
                                                           pairs=pairs, calibrated=False)

    def record(self, config: SimulationConfig, *, compile_s: float, wall_s: float, threads: int,
               resumed: bool) -> None:
        """``config``: the run's (``accuracy="auto"``: the refined one, the pilot counted in its time)."""
        if self.backend != "cpu":
            return
        from stochpend.numerics import _calibration

        if self.builtin_compile_s > 0:
            _calibration.record_compile(compile_s, self.builtin_compile_s, load=self.load)
        if not resumed:  # a resumed run's wall time spans sessions, under other loads
            work = resources.estimate(config).min_path_steps
            _calibration.record_rate(resources.kernel_kind(config), work, wall_s, threads, load=self.load)


def compile_note(config: SimulationConfig, backend: str, precision: str, *,
                 pairs: bool = True) -> None:
    """Said once, on stderr, when a run's first kernel is not in Numba's cache: compiling is
    about to take a while (a note, not a result; with its expected duration)."""
    label = runner.spec_for(config, backend, precision).label
    seconds = resources.compile_seconds(config, backend=backend, precision=precision,
                                        pairs=pairs)
    expected = f"~{resources.format_seconds(seconds)}, " if seconds > 0 else ""
    text = f"compiling kernels for {label} (first use: {expected}cached after)"
    if sys.stderr.isatty():  # folded to the terminal; one line in a pipe or a log, for grep
        import shutil
        import textwrap

        text = textwrap.fill(text, width=max(40, shutil.get_terminal_size().columns), break_on_hyphens=False,
                             break_long_words=False)
    print(text, file=sys.stderr, flush=True)


def provenance(config: SimulationConfig, *, backend: str, threads: int, wall_time_s: float,
               path_steps: int, precision: str = "float64") -> dict[str, Any]:
    """Attributes stored with every result: enough to reproduce it, down to the compiled
    kernel (``kernel``: oscillator/coupling/noise/precision/step/math; the fast-math SIMD
    kernels and the C library's differ in the last bits)."""
    attrs: dict[str, Any] = {"title": "stochpend ensemble simulation"}
    attrs.update(config.to_attrs())
    user_model = models.get(config.potential)
    if user_model is not None:
        attrs["model"] = f"user-defined ({user_model.description or 'stochpend.models.Model'})"
        attrs["model_source"] = user_model.source()
    for name in config.observables:  # the code of each user observable, as for a user's model
        attrs[f"observable_{name}_source"] = observables.get(name).source()
    attrs.update({f"scheme_{k}": v for k, v in integrator.SCHEME.items()})
    attrs.update(
        {
            "rng": "Philox4x32-10, key = seed, counter = (draw, global path index)",
            "backend": backend,
            "precision": precision,
            "kernel": runner.spec_for(config, backend, precision).label,
            "threads": threads,
            "wall_time_s": wall_time_s,
            "path_steps": path_steps,
            "path_steps_per_s": path_steps / wall_time_s if wall_time_s > 0 else float("nan"),
            "stochpend_version": __version__,
            "numba_version": numba.__version__,
            "cpu_target": _cputarget.describe(),
            "numpy_version": np.__version__,
            "python_version": platform.python_version(),
            "machine": f"{platform.machine()} {platform.processor() or platform.system()}",
            "created": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
            "reference": "K. Mallick and P. Marcq, On the stochastic pendulum with Ornstein-Uhlenbeck noise (2004)",
        }
    )
    return {k: (int(v) if isinstance(v, bool) else v) for k, v in attrs.items()}
