"""Parameter sweeps: many ensembles described in TOML, run as (parameter set, batches) tasks.

A sweep is a grid (Cartesian product) or a list of cases of :class:`SimulationConfig`
parameters. Each set's batches are cut into blocks; each block is one task that returns the
per-batch sums of its batches (:func:`run_block`). Placing those sums back is exact (see
:mod:`stochpend.model.power_sums`) and random numbers are keyed by (seed, global path index), so the
result does not depend on the engine: in this process, Dask threads, a local cluster or a
remote one give the same numbers to the last bit. Each set's discretisation bias is then
estimated in this process, as :func:`stochpend.simulate` estimates it (:func:`sweep`).

TOML format (see docs/scale-out.md)::

    description = "Fig. 2"          # optional, stored in the result's attributes

    [base]                          # parameters shared by every set (SimulationConfig.build)
    noise = "ou"
    omega = 1.0
    paths = 2000
    t_max = 100.0

    [grid]                          # each key a list: the Cartesian product, in this order
    D = [1, 10, 100]
    tau = [0.1, 1, 10]

or, instead of ``[grid]``, a list of cases (each overrides ``[base]``)::

    [[case]]
    D = 1
    tau = 0.1

    [[case]]
    D = 10
    tau = 1

A total-error target, as ``stochpend.simulate``'s (issue 35), runs every set as a target run
(:func:`stochpend.runs.multilevel.target_run`, with the set's own seed) instead of its blocks; top-level
keys, or :func:`sweep`'s keywords of the same names (which override them)::

    target_error = 0.01             # the relative total error of each statistic and time
    target_confidence = 0.95        # optional
    target_statistics = "mean_E"    # optional: names, comma-separated or a list
    target_times = [1.0, 10.0]      # optional: among every set's output times
"""

from __future__ import annotations

import importlib
import inspect
import itertools
import json
import math
import os
import time as _time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np
import xarray as xr

from stochpend.model.power_sums import EnsembleSums
from stochpend.model.settings import SimulationConfig, hist_edges, joint_cells, joint_grid
from stochpend.numerics._sources import BUILD
from stochpend.runs import bias, multilevel
from stochpend.runs._blocks import BlockResult, Task, run_block
from stochpend.runs._sweep_sets import flat_sets as flat_sets  # where 'show' reads it without Numba
from stochpend.runs.lifecycle import provenance
from stochpend.text._docs import documented
from stochpend.text.progress import NoProgress, Progress

__all__ = ["BlockResult", "SweepPlan", "Task", "load_spec", "plan_tasks", "run_block", "sweep"]

#: Every parameter a sweep may set: the keywords of SimulationConfig.build.
PARAMETERS: tuple[str, ...] = tuple(
    name for name in inspect.signature(SimulationConfig.build).parameters
    if name not in ("cls", "noise_params", "osc_params", "dyn_params")  # own parameters are keys of their own
)


def _declared() -> tuple[str, ...]:
    """The parameters the registered noises and user models declare for themselves (keys a sweep
    file may set besides :data:`PARAMETERS`; the set's noise or oscillator validates them)."""
    from stochpend.model import dynamics, noises
    from stochpend.model import user_models as models
    from stochpend.model.parameters import own

    pieces = [noises.get(name) for name in noises.names()] + [models.get(name) for name in models.names()]
    channel = [name for n in noises.names() for name in dynamics.channel_parameters(noises.get(n))]
    return tuple(dict.fromkeys([*dynamics.names(), *(p.name for piece in pieces for p in own(piece)), *channel]))


#: Parameters whose value is a list: settable in [base] and [[case]], not a grid axis.
LIST_PARAMETERS = ("times", "hist_E_max", "observables", "joint_bins", "joint_x_range", "joint_Omega_max")
#: A sweep's target: simulate's keywords (stochpend.runs.multilevel), top-level keys of a sweep file.
TARGET_KEYS = ("target_error", "target_confidence", "target_statistics", "target_times")
TOP_LEVEL = ("description", "base", "grid", "case", *TARGET_KEYS)
#: Attributes that differ between runs of the same numbers (never data variables).
_RUN_ATTRS = ("backend", "threads", "wall_time_s", "path_steps", "path_steps_per_s", "created", "bias_wall_time_s",
              "compile_time_s", "total_wall_time_s")
SCHEDULER_HELP = "sync, threads, local, or a scheduler address such as tcp://HOST:8786"


@dataclass(frozen=True)
class SweepPlan:
    """A validated sweep: the configurations in row-major order over ``shape``."""

    kind: str  # "grid" or "case"
    dims: tuple[str, ...]
    shape: tuple[int, ...]
    coords: dict[str, tuple[tuple[str, ...], np.ndarray]]
    configs: tuple[SimulationConfig, ...]
    swept: tuple[str, ...]
    description: str
    source: str
    text: str
    #: The file's target keys (:data:`TARGET_KEYS`) as given; empty: none.
    target: dict[str, Any] = field(default_factory=dict)

    @property
    def n_sets(self) -> int:
        return len(self.configs)


# -- parsing and validation ------------------------------------------------------------------
def _fmt_value(v: Any) -> str:
    return repr(v) if not isinstance(v, list) or len(v) <= 6 else f"[{v[0]!r}, ..., {v[-1]!r}] ({len(v)} values)"


def _scalar_ok(v: Any) -> bool:
    return isinstance(v, (int, float, str)) and not isinstance(v, bool)


def _check_params(table: Any, where: str, source: str, *, grid: bool = False) -> dict[str, Any]:
    if not isinstance(table, Mapping):
        raise ValueError(f"{source}: {where}={_fmt_value(table)} is not accepted: a table of parameters")
    out = {}
    for key, value in table.items():
        name = f"{where}.{key}"
        if key not in PARAMETERS and key not in _declared():
            accepted = ", ".join(PARAMETERS + _declared())
            raise ValueError(f"{source}: {name} is not accepted: unknown parameter; accepted: {accepted}")
        if grid:
            if key in LIST_PARAMETERS:
                raise ValueError(f"{source}: {name} is not accepted: {key} is a list and cannot be a grid "
                                 f"axis; set it in [base] or per [[case]]")
            if not isinstance(value, list) or not value:
                raise ValueError(f"{source}: {name}={_fmt_value(value)} is not accepted: a grid axis is a "
                                 f"non-empty list of values, e.g. {key} = [1, 10, 100]")
            for v in value:
                if not _scalar_ok(v):
                    raise ValueError(f"{source}: {name}={_fmt_value(value)} is not accepted: each value must be "
                                     f"a number or a string, got {v!r}")
            norm = [float(v) if isinstance(v, (int, float)) else v for v in value]
            if len(set(map(repr, norm))) != len(norm):
                raise ValueError(f"{source}: {name}={_fmt_value(value)} is not accepted: repeated values")
        elif key in LIST_PARAMETERS:
            if not (_scalar_ok(value) or (isinstance(value, list) and all(_scalar_ok(v) for v in value))):
                raise ValueError(f"{source}: {name}={_fmt_value(value)} is not accepted: a number or a list of numbers")
        elif not _scalar_ok(value):
            hint = " (put lists of values under [grid])" if isinstance(value, list) else ""
            raise ValueError(f"{source}: {name}={_fmt_value(value)} is not accepted: a single number or string{hint}")
        out[key] = value
    return out


def _build(params: dict[str, Any], source: str, where: str) -> SimulationConfig:
    own = {k: v for k, v in params.items() if k not in PARAMETERS}  # the noise's and oscillator's own
    try:
        return SimulationConfig.build(**{k: v for k, v in params.items() if k in PARAMETERS}, noise_params=own)
    except ValueError as exc:
        raise ValueError(f"{source}: {where}: {str(exc).splitlines()[0]}") from None


def _coord_value(config: SimulationConfig, key: str, raw: Any) -> Any:
    """The value a swept parameter took, as stored in a coordinate."""
    if key == "n_times":
        return len(config.times)
    names = {f.name for f in fields(config)}
    if key in dict(config.noise_params):
        return dict(config.noise_params)[key]
    if key in dict(config.osc_params):
        return dict(config.osc_params)[key]
    if key in names:
        v = getattr(config, key)
        if v is None:
            return {"theta0": "uniform", "xi0": "stationary", "tau": "none"}.get(key, "none")
        return v
    return raw


def _coord_array(values: list[Any]) -> np.ndarray:
    """Numbers (with "none", e.g. tau of white noise, as NaN), or strings if any is a string."""
    numbers = [v for v in values if v != "none"]
    if "none" in values and numbers and all(isinstance(v, (int, float)) for v in numbers):
        return np.asarray([np.nan if v == "none" else float(v) for v in values])
    if any(isinstance(v, str) for v in values):
        return np.asarray([str(v) for v in values])
    return np.asarray(values)


#: The most parameter sets one sweep may hold: each is validated (~60 us, ~1 KB) before any work,
#: and a 742-byte grid of 5 axes x 25 values would otherwise expand to 9.8 million (3.7 GB).
MAX_SETS = 100_000


def _check_count(n: int, source: str, key: str, how: str) -> None:
    """Refuse a sweep of more than :data:`MAX_SETS` sets, counted before anything is expanded."""
    if n > MAX_SETS:
        raise ValueError(f"{source}: {key} is not accepted: {how} make {n:.3g} parameter sets, more than "
                         f"{MAX_SETS:,}; split it into several sweeps")


def load_spec(spec: Mapping[str, Any] | str | os.PathLike | SweepPlan) -> SweepPlan:
    """Parse and validate a sweep (a TOML file or the same structure as a dict).

    Every parameter set is built (and so validated) here, before any work. Refusals are one
    ``ValueError`` line naming the file and the key.
    """
    if isinstance(spec, SweepPlan):
        return spec
    if isinstance(spec, Mapping):
        data = dict(spec)
        source = "sweep"
        text = json.dumps(data, sort_keys=True, default=str)
    else:
        from stochpend.files._toml import read_toml

        p = Path(spec)
        source = p.name
        text, data = read_toml(p, "sweep")

    for key in data:
        if key not in TOP_LEVEL:
            hint = " (parameters go under [base], [grid] or [[case]])" if key in PARAMETERS else ""
            raise ValueError(f"{source}: {key} is not accepted: unknown key{hint}; accepted: "
                             f"{', '.join(TOP_LEVEL)}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ValueError(f"{source}: description={description!r} is not accepted: a string")
    if "\x00" in description:  # found before the sweep runs, not when its result is written
        raise ValueError(f"{source}: description is not accepted: it holds a NUL character (\\u0000), "
                         "which a NetCDF attribute cannot store")
    base = _check_params(data.get("base", {}), "base", source)
    has_grid, has_case = "grid" in data, "case" in data
    if has_grid == has_case:
        raise ValueError(f"{source}: a sweep needs exactly one of [grid] (a product of values) or "
                         f"[[case]] (a list of parameter sets); found {'both' if has_grid else 'neither'}")

    raw_sets: list[dict[str, Any]]
    coords: dict[str, tuple[tuple[str, ...], np.ndarray]] = {}
    if has_grid:
        grid = _check_params(data["grid"], "grid", source, grid=True)
        if not grid:
            raise ValueError(f"{source}: grid is not accepted: empty; give at least one parameter with a list of values")
        for key in grid:
            if key in base:
                raise ValueError(f"{source}: grid.{key} is not accepted: {key} is also set in [base]")
        dims = tuple(grid)
        shape = tuple(len(v) for v in grid.values())
        _check_count(math.prod(shape), source, "grid", " x ".join(f"{len(v)} {k}" for k, v in grid.items()))
        raw_sets = [dict(zip(dims, combo, strict=True)) for combo in itertools.product(*grid.values())]
        configs = []
        for params in raw_sets:
            where = "grid set (" + ", ".join(f"{k}={v!r}" for k, v in params.items()) + ")"
            configs.append(_build({**base, **params}, source, where))
        for axis, key in enumerate(dims):
            stride = int(np.prod(shape[axis + 1:], dtype=np.int64))
            values = [_coord_value(configs[i * stride], key, grid[key][i]) for i in range(shape[axis])]
            coords[key] = ((key,), _coord_array(values))
        kind = "grid"
        swept = dims
    else:
        cases = data["case"]
        if not isinstance(cases, list) or not cases:
            raise ValueError(f"{source}: case is not accepted: a non-empty list of tables ([[case]] ...)")
        _check_count(len(cases), source, "case", f"{len(cases)} [[case]] tables")
        raw_sets = [_check_params(c, f"case[{i}]", source) for i, c in enumerate(cases)]
        configs = [_build({**base, **params}, source, f"case[{i}]") for i, params in enumerate(raw_sets)]
        dims = ("case",)
        shape = (len(configs),)
        keys = []
        for params in raw_sets:
            keys += [k for k in params if k not in keys and k not in LIST_PARAMETERS]
        coords["case"] = (("case",), np.arange(len(configs)))
        for key in keys:
            values = [_coord_value(c, key, {**base, **p}.get(key)) for c, p in zip(configs, raw_sets, strict=True)]
            coords[key] = (("case",), _coord_array(values))
        kind = "case"
        swept = tuple(keys)

    seen: dict[str, int] = {}
    for i, c in enumerate(configs):
        key = repr(c)  # every field, floats exactly
        if key in seen:
            a, b = _set_name(kind, seen[key], raw_sets), _set_name(kind, i, raw_sets)
            why = " (a swept parameter has no effect there)" if kind == "grid" else ""
            raise ValueError(f"{source}: {b} is not accepted: it is the same simulation as {a}{why}")
        seen[key] = i
    if len({c.observables for c in configs}) > 1:
        raise ValueError(f"{source}: observables is not accepted: it differs between sets; set it once, in "
                         "[base] (every set reports the same variables)")
    n_times = {len(c.times) for c in configs}
    if len(n_times) > 1:
        raise ValueError(f"{source}: n_times is not accepted: it differs between sets ({sorted(n_times)}); "
                         f"every set must have the same number of output times")
    joint = {c.joint_bins for c in configs}
    if len(joint) > 1:
        raise ValueError(f"{source}: joint_bins is not accepted: it differs between sets ({sorted(joint)}); "
                         f"every set must have the same joint histogram bins, or none")
    bins = {c.hist_bins for c in configs}
    if len(bins) > 1:
        raise ValueError(f"{source}: hist_bins is not accepted: it differs between sets ({sorted(bins)}); "
                         f"every set must have the same number of histogram bins")
    target = {k: data[k] for k in TARGET_KEYS if k in data}
    spec_ = SweepPlan(kind=kind, dims=dims, shape=shape, coords=coords, configs=tuple(configs),
                      swept=tuple(swept), description=description, source=source, text=text, target=target)
    targets(spec_)  # a bad target in the file is refused here, with everything else
    return spec_


def targets(plan: SweepPlan, given: Mapping[str, Any] | None = None, *, precision: str = "float64",
            max_path_steps: Any = None) -> list[multilevel.Target] | None:
    """Each set's validated target (None: the sweep has none): the file's :data:`TARGET_KEYS`,
    overridden by those ``given`` that are not None (:func:`sweep`'s keywords), with what
    :func:`stochpend.runs.multilevel.check_run` refuses beside a target (``precision``,
    ``max_path_steps``). Refused in one line naming the key (and the set whose output times a
    ``target_times`` misses)."""
    ours = {k: v for k, v in (given or {}).items() if v is not None}
    keys = {**plan.target, **ours}
    if keys.get("target_error") is None:
        if keys:
            name = next(iter(keys))
            source = "" if name in ours else f"{plan.source}: "
            raise ValueError(f"{source}{name}={keys[name]!r} is not accepted without target_error")
        return None
    out = []
    for i, config in enumerate(plan.configs):
        try:
            out.append(multilevel.check_run(config, keys["target_error"], keys.get("target_confidence", 0.95),
                                            keys.get("target_statistics"), keys.get("target_times"),
                                            accuracy="fixed", rtol=None, precision=precision,
                                            max_path_steps=max_path_steps))
        except ValueError as exc:
            # the file named only for its own values: a keyword's is the caller's (the CLI's option)
            source = "" if str(exc).split("=", 1)[0] in ours else f"{plan.source}: "
            where = f" (parameter set {i + 1} of {plan.n_sets})" if plan.n_sets > 1 and i > 0 else ""
            raise ValueError(f"{source}{exc}{where}") from None
    return out


def _set_name(kind: str, i: int, raw_sets: list[dict[str, Any]]) -> str:
    if kind == "case":
        return f"case[{i}]"
    return "grid set (" + ", ".join(f"{k}={v!r}" for k, v in raw_sets[i].items()) + ")"


# -- tasks -----------------------------------------------------------------------------------
def _check_positive_int(name: str, value: Any) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name}={value!r} is not accepted: an integer >= 1")
    return int(value)


def plan_tasks(plan: SweepPlan, tasks_per_set: int) -> list[Task]:
    """Cut every set's batches into at most ``tasks_per_set`` contiguous blocks."""
    tasks = []
    for i, c in enumerate(plan.configs):
        n = min(tasks_per_set, c.n_batches)
        edges = [round(k * c.n_batches / n) for k in range(n + 1)]
        for b0, b1 in itertools.pairwise(edges):
            paths = min(b1 * c.batch_size, c.paths) - b0 * c.batch_size
            tasks.append(Task(i, b0, b1, paths))
    return tasks


class _Tracker:
    """Feeds sweep progress (paths done, tasks done) to a :class:`Progress`.

    ``progress.update`` receives paths; optional duck-typed methods: ``tasks(done, total)``
    and ``note(text)`` (used by the command line for its task counter and the dashboard).
    """

    def __init__(self, progress: Progress, total_paths: int, total_tasks: int) -> None:
        self.progress = progress
        self.total_paths = total_paths
        self.total_tasks = total_tasks
        self.paths_done = 0
        self.tasks_done = 0

    def start(self) -> None:
        self.progress.start(float(self.total_paths), "sweep")
        self._tasks()

    def note(self, text: str) -> None:
        note = getattr(self.progress, "note", None)
        if callable(note):
            note(text)

    def _tasks(self) -> None:
        fn = getattr(self.progress, "tasks", None)
        if callable(fn):
            fn(self.tasks_done, self.total_tasks)

    def partial(self, paths: float) -> None:
        self.progress.update(self.paths_done + paths)

    def done(self, result: BlockResult) -> None:
        self.paths_done += result.paths
        self.tasks_done += 1
        self._tasks()
        self.progress.update(float(self.paths_done))

    def finish(self) -> None:
        self.progress.finish()


class _PartialProgress:
    """Progress of the running task (path-time units) as paths, for the in-process engine."""

    def __init__(self, tracker: _Tracker, t_max: float) -> None:
        self.tracker = tracker
        self.t_max = t_max

    def start(self, total: float, description: str) -> None:
        pass

    def update(self, done: float) -> None:
        self.tracker.partial(done / self.t_max)

    def finish(self) -> None:
        pass


def _run_inprocess(plan: SweepPlan, tasks: list[Task], tracker: _Tracker,
                   on_result: Callable[[BlockResult], None], backend: str,
                   precision: str) -> dict[str, Any]:
    for task in tasks:
        config = plan.configs[task.set_index]
        r = run_block(config, task.set_index, task.b0, task.b1,
                      progress=_PartialProgress(tracker, config.t_max), backend=backend,
                      precision=precision)
        on_result(r)
        tracker.done(r)
    return {"engine": "in-process", "scheduler": "none", "workers": 1}


def _dask_backend(scheduler: Any) -> Any:
    try:
        backend = importlib.import_module("stochpend.runs.dask")
    except ImportError:
        shown = scheduler if isinstance(scheduler, str) else type(scheduler).__name__
        raise ValueError(f"scheduler={shown!r} requires the `dask` extra: pip install 'stochpend[dask]'") from None
    return backend


def check_scheduler(scheduler: Any) -> None:
    """Refuse an unknown scheduler, or a Dask one without the extra, before any work."""
    if scheduler is None:
        return
    if isinstance(scheduler, str):
        if scheduler not in ("sync", "synchronous", "threads", "local") and "://" not in scheduler:
            raise ValueError(f"scheduler={scheduler!r} is not accepted: one of {SCHEDULER_HELP}")
    _dask_backend(scheduler)


def default_tasks_per_set(plan: SweepPlan, slots: int) -> int:
    """About 8 tasks per worker thread, at least one a set: sets differ in cost (Fig. 2's
    dearest set takes a third of the work), so one task a set balances badly."""
    return max(1, math.ceil(8 * slots / plan.n_sets))


# -- the sweep -------------------------------------------------------------------------------
@documented  # help() shows the signature's defaults and the paper's equation numbers
def sweep(
    spec: Mapping[str, Any] | str | os.PathLike | SweepPlan,
    *,
    scheduler: Any = None,
    workers: int | None = None,
    progress: Progress | None = None,
    tasks_per_set: int | None = None,
    backend: str = "cpu",
    precision: str = "float64",
    bias_paths: int | None = None,
    target_error: float | None = None,
    target_confidence: float | None = None,
    target_statistics: Any = None,
    target_times: Any = None,
    max_path_steps: float | None = None,
) -> xr.Dataset:
    """Run every parameter set of a sweep and return one Dataset.

    Parameters
    ----------
    spec : path, dict or SweepPlan
        A TOML file (format in the module docstring and docs/scale-out.md) or the same
        structure as a dict; validated whole before any work.
    scheduler : None, str or distributed.Client
        ``None`` (default): the tasks run one after another in this process, each using all
        Numba threads; no Dask needed. ``"sync"``/``"threads"``: Dask's embedded schedulers
        (no server). ``"local"``: a ``distributed.LocalCluster`` of ``workers`` processes with
        one thread each. ``"tcp://HOST:8786"``: an existing Dask scheduler. A
        ``distributed.Client`` is used as it is (and left open).
    workers : int, optional
        Threads (``"threads"``) or worker processes (``"local"``); default: the CPU count.
    progress : Progress, optional
        Receives the paths done (``start(total_paths, ...)``, ``update(paths_done)``).
    tasks_per_set : int, optional
        Blocks of batches per set (capped at its ``n_batches``). Default: 1 in process, else
        about 8 tasks per worker thread in all. The numbers do not depend on it.
    backend : {"cpu", "cuda", "auto"}
        Where each block runs: the CPU, or the GPU of the process that runs it (in process, or
        on Dask workers that each own a GPU); "auto" picks the GPU when this process has one.
    precision : {"float64", "float32"}
        float32 needs ``backend="cuda"``.
    bias_paths : int, optional
        Coupled pairs estimating each set's discretisation bias, as ``stochpend.simulate``'s
        (default: :func:`stochpend.bias.default_bias_paths` of each set's paths; 0: none). The
        estimates run after the blocks, one set after another in this process on ``backend``
        (whatever the scheduler: about 6 % of the sweep's work by default, so not worth shipping
        to workers), with a note to ``progress`` and no bar.
    target_error, target_confidence, target_statistics, target_times
        A total-error target, as :func:`stochpend.simulate`'s (default: the sweep file's keys
        of these names; none). Every set is then run as :func:`stochpend.simulate` runs it with
        ``target_error`` and the set's parameters (its own seed), one set after another in this
        process: the numbers of each set are those of that run, to the last bit. Every set's
        target and pilot are checked before any work; a ``scheduler`` is refused (a target
        run plans each round from the last, so its sets are not cut into blocks), and
        ``tasks_per_set`` and ``bias_paths`` are not used.
    max_path_steps : float, optional
        With a target: the limit of each set's target run, as :func:`stochpend.simulate`'s.

    Returns
    -------
    xarray.Dataset
        The variables of :func:`stochpend.simulate` with the swept dimensions first: dims
        ``(D, tau, time)`` for a grid over D and tau, ``(case, time)`` for cases (the
        parameters are coordinates along ``case``); so ``<name>_bias``, ``<name>_bias_stderr``
        and ``<name>_bias_verdict`` of each set (unless ``bias_paths=0``), equal to those
        ``stochpend.simulate`` gives for the set alone. ``path_steps`` per set; parameters
        and bias attributes common to every set are attributes, the others variables over the
        sweep dimensions. With a target: each set's variables of :func:`stochpend.simulate`
        with ``target_error`` (estimates, ``<name>_stat_error``, ``<name>_bias_bound``,
        ``<name>_total_error``, ``<name>_certified``, ``<name>_cost_to_certify``, the levels'
        diagnostics, ``n_samples``, ...) with the swept dimensions first; the ``level``
        dimension is the most levels any set used, the others' padded (NaN; 0 samples and
        path-steps); per-set attributes (``target_levels``, ``target_level_seeds``, ...) are
        variables over the sweep dimensions where the sets differ.
    """
    from stochpend.runs.simulate import check_precision, resolve_backend

    plan = load_spec(spec)
    backend = resolve_backend(backend)
    check_precision(precision, backend)
    workers = _check_positive_int("workers", workers)
    tasks_per_set = _check_positive_int("tasks_per_set", tasks_per_set)
    if bias_paths is not None:
        bias_paths = bias.check_bias_paths(bias_paths, 0)
    sets = targets(plan, {"target_error": target_error, "target_confidence": target_confidence,
                          "target_statistics": target_statistics, "target_times": target_times},
                   precision=precision, max_path_steps=max_path_steps)
    if sets is not None:
        return _target_sweep(plan, sets, scheduler=scheduler, backend=backend, precision=precision,
                             max_path_steps=max_path_steps, progress=progress)
    check_scheduler(scheduler)
    started = _time.perf_counter()

    results: list[list[BlockResult]] = [[] for _ in plan.configs]

    def on_result(r: BlockResult) -> None:
        results[r.set_index].append(r)

    if scheduler is None:
        tasks = plan_tasks(plan, tasks_per_set or 1)
        tracker = _Tracker(progress or NoProgress(), sum(t.paths for t in tasks), len(tasks))
        tracker.start()
        try:
            info = _run_inprocess(plan, tasks, tracker, on_result, backend, precision)
        finally:
            tracker.finish()
    else:
        with _dask_backend(scheduler).connect(scheduler, workers) as engine:
            tasks = plan_tasks(plan, tasks_per_set or default_tasks_per_set(plan, engine.slots))
            tracker = _Tracker(progress or NoProgress(), sum(t.paths for t in tasks), len(tasks))
            if engine.dashboard:
                tracker.note(f"Dask dashboard: {engine.dashboard}")
            tracker.start()
            try:
                engine.run(plan, tasks, tracker, on_result, backend=backend, precision=precision)
            finally:
                tracker.finish()
            info = engine.info()
    estimates = _bias_estimates(plan, bias_paths, backend, tracker)
    wall = _time.perf_counter() - started
    info = {**info, "backend": backend, "precision": precision}
    return _assemble(plan, results, info=info, n_tasks=len(tasks), wall_time_s=wall, estimates=estimates)


def _bias_estimates(plan: SweepPlan, bias_paths: int | None, backend: str,
                    tracker: _Tracker) -> list[bias.BiasEstimate] | None:
    """Each set's bias estimate, as :func:`stochpend.simulate` makes it (None: ``bias_paths=0``)."""
    if bias_paths == 0:
        return None
    tracker.note(f"estimating the discretisation bias of {plan.n_sets} parameter sets")
    return [bias.estimate(c, bias.default_bias_paths(c.paths) if bias_paths is None else bias_paths,
                          backend=backend) for c in plan.configs]


def _target_sweep(plan: SweepPlan, sets: list[multilevel.Target], *, scheduler: Any, backend: str,
                  precision: str, max_path_steps: Any, progress: Progress | None) -> xr.Dataset:
    """Every set as a target run (:func:`stochpend.runs.multilevel.target_run`), in this process."""
    if scheduler is not None:
        shown = scheduler if isinstance(scheduler, str) else type(scheduler).__name__
        raise ValueError(f"scheduler={shown!r} is not accepted with target_error: a target run plans each "
                         "round from the last, so a target sweep runs its sets one after another in this "
                         "process; leave the scheduler unset")
    for i, (config, target) in enumerate(zip(plan.configs, sets, strict=True)):
        try:  # every set's pilot within the limit, before the first set's work
            multilevel.check_pilot(config, target, backend=backend, max_path_steps=max_path_steps)
        except ValueError as exc:
            raise ValueError(f"{plan.source}: {exc} (parameter set {i + 1} of {plan.n_sets})") from None
    started = _time.perf_counter()
    tracker = _Tracker(progress or NoProgress(), 0, plan.n_sets)
    tracker.progress.start(float(plan.n_sets), "sweep")
    datasets = []
    try:
        for i, (config, target) in enumerate(zip(plan.configs, sets, strict=True)):
            def note(text: str, i: int = i) -> None:
                tracker.note(f"set {i + 1} of {plan.n_sets}: {text}")

            datasets.append(multilevel.target_run(config, target, backend=backend, max_path_steps=max_path_steps,
                                                  note=note))
            tracker.progress.update(float(i + 1))
    finally:
        tracker.finish()
    n_levels = max(ds.sizes["level"] for ds in datasets)
    padded = [ds.reindex(level=np.arange(n_levels), fill_value={
        name: 0 if np.issubdtype(var.dtype, np.integer) else np.nan
        for name, var in ds.data_vars.items() if "level" in var.dims}) for ds in datasets]
    info = {"engine": "in-process", "scheduler": "none", "workers": 1, "backend": backend, "precision": precision}
    return _stacked(plan, padded, [dict(ds.attrs) for ds in datasets],
                    [int(ds.attrs["path_steps"]) for ds in datasets], info=info, n_tasks=plan.n_sets,
                    wall_time_s=_time.perf_counter() - started,
                    compute_s=float(sum(ds.attrs["total_wall_time_s"] for ds in datasets)))


def _assemble(plan: SweepPlan, results: list[list[BlockResult]], *, info: dict[str, Any], n_tasks: int,
              wall_time_s: float, estimates: list[bias.BiasEstimate] | None = None) -> xr.Dataset:
    datasets = []
    per_set_attrs = []
    path_steps = []
    compute_s = 0.0
    for i, (config, rs) in enumerate(zip(plan.configs, results, strict=True)):
        acc = EnsembleSums.empty(config.n_batches, len(config.times), config.hist_bins, config.observables,
                                 config.paths, joint_cells(config))
        steps = 0
        for r in sorted(rs, key=lambda r: r.b0):
            acc.add_batches(r.b0, r.sums, r.hist)
            if r.passage is not None:
                acc.add_passage(r.b0 * config.batch_size, r.passage)
            steps += r.path_steps
            compute_s += r.seconds
        if not acc.complete:
            raise RuntimeError("internal error: a sweep set is missing batches")
        ds = acc.to_dataset(np.asarray(config.times), hist_edges(config), {}, joint_grid(config))
        if estimates is not None:  # the set's variables and attributes as simulate's
            bias.attach(ds, estimates[i])
        datasets.append(ds)
        per_set_attrs.append({**provenance(config, backend=info.get("backend", "cpu"),
                                           precision=info.get("precision", "float64"), threads=0,
                                           wall_time_s=0.0, path_steps=steps), **ds.attrs})
        path_steps.append(steps)
    return _stacked(plan, datasets, per_set_attrs, path_steps, info=info, n_tasks=n_tasks,
                    wall_time_s=wall_time_s, compute_s=compute_s)


def _stacked(plan: SweepPlan, datasets: list[xr.Dataset], per_set_attrs: list[dict[str, Any]],
             path_steps: list[int], *, info: dict[str, Any], n_tasks: int, wall_time_s: float,
             compute_s: float) -> xr.Dataset:
    """The sets' Datasets (alike in variables and shapes) as one, the swept dimensions first;
    attributes common to every set stay attributes, the others become variables."""
    shape = plan.shape
    first = datasets[0]
    times = np.stack([np.asarray(ds.time.values) for ds in datasets])
    same_times = bool(np.all(times == times[0]))
    data_vars: dict[str, Any] = {}
    for name, var in first.data_vars.items():
        stacked = np.stack([ds[name].values for ds in datasets]).reshape(shape + var.shape)
        attrs_ = dict(var.attrs)
        if "censoring" in attrs_:  # the first set's counts would read as every set's
            attrs_["censoring"] = ("right-censored at each set's last output time: the paths not passed by "
                                   "then are its fpt_<name>_censored, the non-finite ones excluded")
        data_vars[str(name)] = (plan.dims + var.dims, stacked, attrs_)
    data_vars["path_steps"] = (plan.dims, np.asarray(path_steps, dtype=np.int64).reshape(shape),
                               {"long_name": "path-steps taken by this parameter set"})

    coords: dict[str, Any] = {k: (d, v) for k, (d, v) in plan.coords.items()}
    for name, coord in first.coords.items():  # a first passage's probabilities: the same in every set
        if name != "time" and name not in coords:
            coords[str(name)] = (coord.dims, coord.values, dict(coord.attrs))
    if same_times:
        coords["time"] = ("time", times[0], dict(first.time.attrs))
    else:
        coords["times"] = (plan.dims + ("time",), times.reshape(shape + (times.shape[1],)),
                           {"long_name": "output times of each parameter set", **first.time.attrs})

    attrs: dict[str, Any] = {"title": "stochpend parameter sweep"}
    for key, value in per_set_attrs[0].items():
        if key in _RUN_ATTRS or key in plan.coords:
            continue
        values = [a[key] for a in per_set_attrs]
        if all(v == value or (v != v and value != value) for v in values):  # NaN: the same too
            if key != "title":
                attrs[key] = value
        elif key not in data_vars:
            data_vars[key] = (plan.dims, _coord_array(values).reshape(shape),
                              {"long_name": f"{key} of each parameter set"})
    total_steps = int(sum(path_steps))
    attrs.update({
        "description": plan.description,
        "sweep_kind": plan.kind,
        "sweep_dims": ",".join(plan.dims),
        "sweep_swept": ",".join(plan.swept),
        "sweep_source": plan.source,
        "sweep_spec": plan.text,
        "sweep_sets": plan.n_sets,
        "sweep_tasks": n_tasks,
        "sweep_engine": info.get("engine", ""),
        "sweep_scheduler": str(info.get("scheduler", "")),
        "sweep_workers": int(info.get("workers", 0)),
        **({"sweep_worker_cpu_targets": info["worker_cpu_targets"]} if "worker_cpu_targets" in info else {}),
        "backend": info.get("backend", "cpu"),
        "precision": info.get("precision", "float64"),
        "stochpend_build": BUILD,
        "wall_time_s": wall_time_s,
        "compute_time_s": compute_s,
        "path_steps": total_steps,
        "path_steps_per_s": total_steps / wall_time_s if wall_time_s > 0 else float("nan"),
        "created": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
    })
    return xr.Dataset(data_vars, coords=coords, attrs=attrs)
