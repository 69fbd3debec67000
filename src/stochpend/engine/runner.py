"""The host loop of every backend: chunks, batches, output times, progress, checkpoints.

The ensemble is cut into ``n_batches`` batches of consecutive global path indices (the units
of the jackknife errors and of Dask tasks), and the batches into chunks that fit in memory.
For each chunk a backend's *engine* (``stochpend.engine.cpu.Engine``, ``...cuda.Engine``)
starts the paths, advances them to each output time in calls of a bounded number of steps,
and sums their statistics per batch; this module does the rest, once for every backend:

* between two calls it reports progress and offers the state to a checkpointer, which may
  write it (and stops the run cleanly on Ctrl-C or SIGTERM: ``stochpend.runs.checkpoint``);
* a :class:`RunState` taken there, read back and passed as ``resume`` continues the run to
  the same numbers, bit for bit: every random number is keyed by (seed, global path, step),
  and the clock's compensation is part of the path's state.

The numbers depend only on the configuration, the batch range and the backend's arithmetic
(never on the chunk size, the thread count, the launch geometry or an interruption).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from stochpend.engine.layout import CHUNK_ARRAYS
from stochpend.files._files import raise_pending
from stochpend.model import observables
from stochpend.model.passage import final_values
from stochpend.model.power_sums import EnsembleSums
from stochpend.model.settings import SimulationConfig, hist_edges, joint_cells
from stochpend.text.progress import NoProgress, Progress

__all__ = ["BACKENDS", "Checkpointer", "RunState", "engine_class", "run_batches"]

#: Backends the runner can drive.
BACKENDS = ("cpu", "cuda")


@dataclass
class RunState:
    """Everything needed to continue :func:`run_batches` exactly where it stopped.

    The run is at chunk ``[b0, b1)`` (batch indices) and has accumulated the output times
    before ``j`` for that chunk (in ``chunk_sums``/``chunk_hist``); ``acc`` holds the finished
    chunks, ``path_steps`` their steps. The per-path arrays are the chunk's state; on a GPU
    they live on the device and are copied here by :meth:`pull` (a checkpointer calls it
    before it writes). A checkpoint is this object written to disk (``stochpend.runs.checkpoint``).
    """

    first_batch: int
    stop_batch: int
    b0: int
    b1: int
    j: int
    x: np.ndarray
    Omega: np.ndarray
    xi: np.ndarray
    t: np.ndarray
    k: np.ndarray
    status: np.ndarray
    t_comp: np.ndarray
    xi_aux: np.ndarray
    chunk_sums: np.ndarray
    chunk_hist: np.ndarray
    acc: EnsembleSums
    path_steps: int
    done_work: float
    backend: str = field(default="cpu", compare=False)
    precision: str = field(default="float64", compare=False)
    #: The per-path accumulators' slots, (n_slots, n) float64 (stochpend.observables); None or
    #: empty without accumulators.
    tracks: Any = None
    #: The additive Ornstein-Uhlenbeck noise's value per path, (n,) float64 (``additive_tau`` > 0,
    #: stochpend.model.dynamics); None or empty for any other run.
    xi_a: Any = None
    #: The generic additive channel's second variable per path, (n,) float64 (``additive_noise``,
    #: stochpend.model.dynamics; its ``xi_a`` is the field above); None or empty for any other run.
    aux_a: Any = None
    #: Set by run_batches: copies a GPU chunk's arrays here (see pull); not saved.
    _sync: Any = field(default=None, init=False, repr=False, compare=False)

    def pull(self) -> None:
        """Bring the live chunk's arrays into this object (a no-op on the CPU)."""
        if self._sync is not None:
            self._sync(self)


#: RunState fields that are not per-chunk arrays.
SCALAR_FIELDS = ("first_batch", "stop_batch", "b0", "b1", "j", "path_steps", "done_work",
                 "backend", "precision")
class Checkpointer(Protocol):
    """Called between kernel calls with the live state; may write it to disk."""

    def maybe_save(self, state: RunState) -> None: ...


class Engine(Protocol):
    """What a backend provides to the runner: one chunk of paths and its kernels."""

    def start(self, p0: int, n: int, nb: int) -> None: ...

    def load(self, p0: int, arrays: dict[str, np.ndarray]) -> None: ...

    def max_steps(self) -> int: ...

    def advance(self, t_target: float, max_steps: int) -> bool: ...

    def time_sum(self, t_target: float, done: bool) -> float: ...

    def accumulate(self, j: int, edges_j: np.ndarray) -> None: ...

    def steps(self) -> int: ...

    def arrays(self) -> dict[str, np.ndarray]: ...

    def results(self) -> tuple[np.ndarray, np.ndarray]: ...

    def final_tracks(self) -> tuple[np.ndarray, np.ndarray]: ...


def engine_class(backend: str, levels: int = 1) -> Any:
    """The Engine class of ``backend`` ("cpu" or "cuda"): of one path per ensemble member, or
    (``levels`` > 1) of coupled members (``LevelEngine``)."""
    if backend == "cpu":
        from stochpend.engine import cpu

        return cpu.Engine if levels == 1 else cpu.LevelEngine
    if backend == "cuda":
        from stochpend.engine import cuda

        return cuda.Engine if levels == 1 else cuda.LevelEngine
    raise ValueError(f"backend={backend!r} is not accepted: one of {', '.join(BACKENDS)}")


def spec_for(config: SimulationConfig, backend: str, precision: str) -> Any:
    if backend == "cpu":
        from stochpend.engine import cpu

        return cpu.spec_for(config, precision)
    from stochpend.engine import cuda

    return cuda.spec_for(config, precision)


def run_batches(
    config: SimulationConfig,
    first_batch: int,
    stop_batch: int,
    *,
    backend: str = "cpu",
    precision: str = "float64",
    chunk_paths: int | None = None,
    progress: Progress | None = None,
    checkpointer: Checkpointer | None = None,
    resume: RunState | None = None,
    levels: int = 1,
    differences: int = 0,
    tracked: bool = False,
    what: str = "simulating",
) -> tuple[Any, int]:
    """Simulate batches ``first_batch .. stop_batch - 1`` and return ``(sums, path_steps)``.

    This is the unit of work that runs, Dask tasks and checkpointed runs are made of. Only the
    batches in range are filled in ``sums`` (an ``EnsembleSums``). ``chunk_paths`` (rounded
    down to whole batches, at least one) bounds the memory; default: the backend's. ``resume``:
    a RunState from a checkpoint of the same configuration, backend and precision.

    ``levels`` > 1: each of the ``config.paths`` members of the ensemble is a set of ``levels``
    coupled members at steps h, h/2, ... driven by one noise path (the bias estimate's pairs, a
    multilevel target's levels; global paths from ``rng.COUPLED_PATH0``): ``sums`` is then a
    ``stats.LevelSums`` (with the 2 members' ``differences`` when asked: 1 the powers of each
    column's differences, 2 also the products for the skewness and flatness), ``path_steps`` the
    finest member's steps; not checkpointed; ``tracked``: each member carries the run's per-path
    accumulators (``LevelEngine``; the multilevel target on an accumulator's mean). ``what``:
    the progress bar's label.
    """
    if levels != 1 and (checkpointer is not None or resume is not None):
        raise ValueError("coupled levels are not checkpointed: checkpointer and resume must be None")
    if not (0 <= first_batch < stop_batch <= config.n_batches):
        raise ValueError(
            f"batches {first_batch}..{stop_batch} are not accepted: need 0 <= first_batch < "
            f"stop_batch <= n_batches = {config.n_batches}"
        )
    progress = progress or NoProgress()
    times = np.asarray(config.times, dtype=np.float64)
    edges = np.ascontiguousarray(hist_edges(config), dtype=np.float64)
    bs = config.batch_size
    n_times = times.size
    Engine = engine_class(backend, levels)
    spec = spec_for(config, backend, precision)
    total_paths = min(stop_batch * bs, config.paths) - first_batch * bs
    progress.start(total_paths * config.t_max, what)

    if resume is None:
        chunk_batches = max(1, (chunk_paths or Engine.default_chunk_paths(precision)) // bs)
        chunk_batches = min(chunk_batches, stop_batch - first_batch)
    else:
        chunk_batches = resume.b1 - resume.b0
    capacity = min(chunk_batches * bs, total_paths)
    engine = (Engine(config, spec, capacity, chunk_batches) if levels == 1 else
              Engine(config, spec, capacity, chunk_batches, levels=levels, differences=differences,
                     tracked=tracked))

    def chunk(b0: int, b1: int) -> tuple[int, int]:
        p0 = b0 * bs
        return p0, min(b1 * bs, config.paths) - p0

    if resume is None:
        b1 = min(first_batch + chunk_batches, stop_batch)
        p0, n = chunk(first_batch, b1)
        engine.start(p0, n, b1 - first_batch)
        # The chunk's arrays reach the state only when a checkpointer asks (RunState.pull).
        state = RunState(first_batch, stop_batch, first_batch, b1, 0,
                         **dict.fromkeys(CHUNK_ARRAYS),  # type: ignore[arg-type]  # filled by pull
                         acc=(EnsembleSums.empty(config.n_batches, n_times, config.hist_bins, config.observables,
                                                 config.paths, joint_cells(config))
                              if levels == 1 else engine.empty_sums()),
                         path_steps=0, done_work=0.0, backend=backend, precision=precision)
    else:
        state = resume
        engine.load(state.b0 * bs, {name: getattr(state, name) for name in CHUNK_ARRAYS})
    state.backend, state.precision = backend, precision
    # path_steps counts every step taken, the live chunk's too (its k); the finished chunks'
    # share is kept here.
    finished = [state.path_steps - (engine.steps() if resume is not None else 0)]
    state._sync = _syncer(engine, finished)
    # The accumulator slots that hold first-passage times, in slot order.
    passages = [i for i, a in enumerate(engine.accs) if isinstance(a, observables.FirstPassage)]

    while True:
        max_steps = engine.max_steps()
        while state.j < n_times:
            t_target = float(times[state.j])
            while True:
                done = engine.advance(t_target, max_steps)
                progress.update(state.done_work + engine.time_sum(t_target, done))
                raise_pending()  # a Ctrl-C whose exception was dropped stops the run here
                if done:
                    break
                if checkpointer is not None:
                    checkpointer.maybe_save(state)
            engine.accumulate(state.j, edges[state.j])
            state.j += 1
            if checkpointer is not None:
                checkpointer.maybe_save(state)
        if passages:  # each path's final passage times (stochpend.model.passage), before the chunk goes
            tracks, status = engine.final_tracks()
            state.acc.add_passage(state.b0 * bs, final_values(tracks[passages], status))
        state.acc.add_batches(state.b0, *engine.results())
        finished[0] += engine.steps()
        state.path_steps = finished[0]
        state.done_work += engine.n * config.t_max
        if state.b1 >= stop_batch:
            break
        b0 = state.b1
        b1 = min(b0 + chunk_batches, stop_batch)
        p0, n = chunk(b0, b1)
        engine.start(p0, n, b1 - b0)
        state.b0, state.b1, state.j = b0, b1, 0
        if checkpointer is not None:
            checkpointer.maybe_save(state)
    progress.finish()
    return state.acc, state.path_steps


def _syncer(engine: Any, finished: list[int]) -> Callable[[RunState], None]:
    def sync(state: RunState) -> None:
        for name, value in engine.arrays().items():
            setattr(state, name, value)
        state.path_steps = finished[0] + engine.steps()

    return sync
