"""Checkpoint and resume for long single runs.

A checkpoint is the complete :class:`~stochpend.runs.simulate.RunState` between two kernel calls
(per-path arrays, the sums of the finished output times and chunks), the configuration, the
package version and where the result goes. Resuming continues ``run_batches`` from that state:
random numbers are keyed by (seed, global path index, step), so an interrupted and resumed run
gives the same numbers, to the last bit, as an uninterrupted one.

File format (no pickle; everything little-endian)::

    magic        16 bytes   b"STOCHPEND-CKPT\\x00\\x01"
    header_len    8 bytes   unsigned 64-bit integer
    header        header_len bytes of UTF-8 JSON (format, versions, config, config_sha256,
                  run position, output path, bias_paths, the level ``accuracy="auto"``
                  chose with its pilot's sizes, and the table of arrays: name, dtype,
                  shape, offset, nbytes)
    payload       the raw bytes of the arrays, one after the other
    checksum     32 bytes   SHA-256 of everything above

The file is written to a temporary file in the same directory, flushed to disk and renamed
over the previous checkpoint (``os.replace``), so a crash leaves either the old or the new
checkpoint, never a mixture. Reading verifies the checksum over the whole file before
anything is parsed: a truncated or corrupted file is refused, never half-loaded. A checkpoint
written by another stochpend version or build (the fingerprint of the code that determines
the numbers, :data:`stochpend.numerics._sources.BUILD`), or whose configuration no longer validates to the
same hash, is refused with a one-line message (``ValueError``).

An ``accuracy="auto"`` run saves the configuration it runs (refined to the chosen level) and its
pilot (the ``pilot_*`` arrays, the bias of every statistic at the coarse step): a resumed run
rebuilds the level choice from them (:func:`stochpend.bias.level_choice`, which must give the
saved level and configuration back) and reports the same bias, without running the pilot again.
A checkpoint without ``bias_paths`` or ``accuracy`` (written before they were recorded) resumes
with the default pairs at the fixed step, as it was run.

A target run's checkpoint (``simulate(target_error=...)``, :mod:`stochpend.runs.multilevel`; header
``kind = "target"``, :class:`TargetCheckpoint`) is the same file around another state: the
journal of the rounds and ensembles the run has done (:class:`stochpend.runs.multilevel.Journal`),
saved at round boundaries (:class:`TargetCheckpointer`). Its record is checked field by field
and its target as a new one is; resuming replays the journal, each round checked against the
one the loop asks for, and goes on (:func:`run_target_checkpointed`), to the uninterrupted
run's numbers to the last bit.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import os
import signal
import struct
import threading
import time as _time
from collections.abc import Iterator
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numba
import numpy as np
import xarray as xr

from stochpend._version import __version__
from stochpend.engine.layout import path_dtypes
from stochpend.engine.runner import BACKENDS, RunState
from stochpend.files import _files, io
from stochpend.model import observables
from stochpend.model.dynamics import additive_arrays
from stochpend.model.observables import n_sums
from stochpend.model.power_sums import EnsembleSums, passage_slots
from stochpend.model.settings import SimulationConfig, hist_columns
from stochpend.numerics import _cputarget
from stochpend.numerics._sources import BUILD
from stochpend.runs import bias, multilevel
from stochpend.runs.lifecycle import Checkpointing, RunOptions, execute
from stochpend.text.progress import Progress

__all__ = [
    "Checkpoint",
    "CheckpointInterrupt",
    "FileCheckpointer",
    "TargetCheckpoint",
    "TargetCheckpointer",
    "config_from_json",
    "config_hash",
    "config_to_json",
    "read",
    "resume",
    "run_checkpointed",
    "run_target_checkpointed",
    "write",
    "write_target",
]

MAGIC = b"STOCHPEND-CKPT\x00\x01"
FORMAT = "stochpend-checkpoint"
FORMAT_VERSION = 1
_LEN = struct.Struct("<Q")
_DIGEST = 32

#: RunState's scalar fields (in the header) and its non-per-path arrays; every other field
#: of RunState is an array with one entry per path of the current chunk, saved as it is, so a
#: new per-path field (such as ``t_comp``) is checkpointed without a change here.
_RUN_FIELDS = ("first_batch", "stop_batch", "b0", "b1", "j", "path_steps", "done_work")
_CHUNK_ARRAYS = {"chunk_sums": "<f8", "chunk_hist": "<i8"}
_ACC_ARRAYS = {"acc_sums": "<f8", "acc_hist": "<i8", "acc_filled": "|b1"}
_PATH_ARRAYS = tuple(f.name for f in fields(RunState)
                     if f.name not in (*_RUN_FIELDS, *_CHUNK_ARRAYS, "acc", "backend", "precision", "_sync",
                                       "tracks", "xi_a", "aux_a"))
#: The per-path accumulators' slots (stochpend.observables), (n_slots, n), written when the run
#: has accumulators; the finished chunks' final passage times (stochpend.model.passage), (n_passages,
#: paths), when it has first passages.
_TRACK_ARRAYS = {"tracks": "<f8", "acc_passage": "<f8"}
#: The additive Ornstein-Uhlenbeck noise's per-path value (stochpend.model.dynamics, additive_tau > 0),
#: (n,), written for a run with it only (so every other run's checkpoint is what it was).
#: The generic additive channel (``additive_noise``) adds its noise's second variable ``aux_a``.
_ADDITIVE_ARRAYS = {"xi_a": "<f8", "aux_a": "<f8"}
#: Dtype kinds a per-path array may have (never object: nothing here can hold a pickle).
_NUMERIC_KINDS = "biuf"
#: An ``accuracy="auto"`` run's pilot (:class:`stochpend.bias.BiasEstimate`): (value, stderr)
#: of each statistic's bias and coarse value, shape (statistics, n_times, 2), in the order of
#: :func:`_statistic_names`; its non-finite pairs and decorrelation, (n_times,).
_PILOT_ARRAYS = {"pilot_bias": "<f8", "pilot_coarse": "<f8", "pilot_nonfinite": "<i8",
                 "pilot_decorrelation": "<f8"}
#: The header's ``accuracy`` record: the chosen level and rtol, the pilot's sizes and cost.
_PILOT_KEYS = ("level", "rtol", "pilot_paths", "pilot_path_steps", "pilot_wall_time_s", "pilot_batches")
#: A target run's checkpoint (header ``kind = "target"``): per round of its journal
#: (:class:`stochpend.runs.multilevel.Journal`), in order, the samples at each time (R, T) and the six
#: (S, T) arrays of :class:`stochpend.runs.multilevel.Round` (:data:`_ROUND_MEANS`), (R, 6, S, T); per
#: ensemble of the independent route its means and their variances, (Q, 2, S, T), NaN after its
#: last time. The header's ``target`` record holds the target, the limits and each round's and
#: ensemble's scalars (:data:`_ROUND_KEYS`, :data:`_ENSEMBLE_KEYS`).
_TARGET_ARRAYS = {"target_n": "<i8", "target_means": "<f8", "target_ensembles": "<f8"}
_ROUND_MEANS = ("f", "f_var", "c", "c_var", "y", "y_var", "d1", "d2", "d3", "d4")
_ROUND_KEYS = ("level", "stop", "seed", "batches", "path_steps", "nonfinite")
_ENSEMBLE_KEYS = ("seed", "h", "n", "stop", "path_steps", "nonfinite")
_TARGET_KEYS = ("error", "confidence", "statistics", "times", "max_path_steps", "max_seconds", "rounds",
                "ensembles")


class CheckpointInterrupt(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) during a checkpointed run: the state was saved to ``path`` first."""

    def __init__(self, path: Path, signum: int = signal.SIGINT) -> None:
        super().__init__(f"interrupted; checkpoint written to {path}")
        self.path = path
        self.signum = int(signum)

    @property
    def exit_code(self) -> int:
        """128 + the signal number: 130 for Ctrl-C, 143 for SIGTERM."""
        return 128 + self.signum


# -- configuration as JSON -------------------------------------------------------------------
def config_to_json(config: SimulationConfig) -> dict[str, Any]:
    """Every field of the configuration as plain JSON values (floats round-trip exactly)."""
    out: dict[str, Any] = {}
    for f in fields(config):
        if f.name == "extra" or (f.name in ("observables", "noise_params", "osc_params", "dyn_params",
                                            "joint_bins", "joint_x_range", "joint_Omega_max",
                                            "additive_noise")
                                 and not getattr(config, f.name)):
            continue  # written only when used: checkpoints from before keep their hash
        v = getattr(config, f.name)
        pairs = f.name in ("noise_params", "osc_params", "dyn_params")
        out[f.name] = [list(p) for p in v] if pairs else list(v) if isinstance(v, tuple) else v
    return out


def config_from_json(data: dict[str, Any]) -> SimulationConfig:
    """Rebuild (and so re-validate) a configuration written by :func:`config_to_json`."""
    kwargs = dict(data)
    if kwargs.get("theta0") is None:
        kwargs["theta0"] = "uniform"
    if kwargs.get("xi0") is None:
        kwargs["xi0"] = "stationary"
    return SimulationConfig.build(**kwargs)


def config_hash(config: SimulationConfig) -> str:
    """SHA-256 of the canonical JSON of the configuration."""
    text = json.dumps(config_to_json(config), sort_keys=True, separators=(",", ":"), allow_nan=False)
    return hashlib.sha256(text.encode()).hexdigest()


# -- the checkpoint object ------------------------------------------------------------------
@dataclass(kw_only=True)
class _Saved:
    """What every checkpoint holds beside its run's own state: the configuration, where the
    result goes, the interval and the sessions so far."""

    config: SimulationConfig
    out: Path | None = None
    overwrite: bool = False
    every_s: float | None = None
    elapsed_s: float = 0.0
    resumed: int = 0
    command_line: str | None = None
    created: str = ""
    stochpend_version: str = __version__


@dataclass(kw_only=True)
class Checkpoint(_Saved):
    """A run's state plus what is needed to finish it as the original command would have."""

    state: RunState
    threads: int | None = None
    chunk_paths: int | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    #: Pairs of the bias estimate (0: none); None: not recorded (the default).
    bias_paths: int | None = None
    #: The level ``accuracy="auto"`` chose, with its pilot; None: the step as given.
    choice: bias.LevelChoice | None = None


@dataclass(kw_only=True)
class TargetCheckpoint(_Saved):
    """A target run (:func:`stochpend.runs.multilevel.target_run`) between two rounds: its target,
    the journal of the rounds and ensembles it has run, the limits it was given (the work
    limit, None: none; the wall-time budget) and where its result goes."""

    target: multilevel.Target
    journal: multilevel.Journal
    backend: str = "cpu"
    max_path_steps: float | None = None
    max_seconds: float | None = None


def _statistic_names(config: SimulationConfig) -> list[str]:
    """The statistics a bias estimate of ``config`` reports: the table's, then the user
    observables' (:func:`stochpend.bias.estimate`'s order)."""
    return [s.name for s in observables.STATISTICS + observables.user_statistics(config.observables)]


def _pilot_arrays(choice: bias.LevelChoice | None) -> dict[str, np.ndarray]:
    if choice is None:
        return {}
    p = choice.pilot
    names = _statistic_names(choice.config)
    return {
        "pilot_bias": np.array([np.stack(p.bias[name], axis=-1) for name in names], dtype="<f8"),
        "pilot_coarse": np.array([np.stack(p.coarse[name], axis=-1) for name in names], dtype="<f8"),
        "pilot_nonfinite": np.ascontiguousarray(p.nonfinite, dtype="<i8"),
        "pilot_decorrelation": np.ascontiguousarray(p.decorrelation, dtype="<f8"),
    }


def _pilot_record(choice: bias.LevelChoice | None) -> dict[str, Any] | None:
    if choice is None:
        return None
    p = choice.pilot
    return {"level": int(choice.level), "rtol": choice.rtol, "pilot_paths": int(p.paths),
            "pilot_path_steps": int(p.path_steps), "pilot_wall_time_s": float(p.wall_time_s),
            "pilot_batches": int(p.batches)}


def _level_choice(p: Path, config: SimulationConfig, record: dict[str, Any],
                  arrays: dict[str, np.ndarray]) -> bias.LevelChoice:
    """The level choice saved with an ``auto`` run, rebuilt from its pilot; refused unless it
    gives the saved level and the configuration that ran (a crafted level cannot run a step
    its pilot did not choose)."""
    level = record["level"]
    factor = 2.0**level  # exact: refined() divides by the same power of two
    pilot_config = replace(config, h_max=config.h_max * factor, step_c=config.step_c * factor)

    def pairs(name: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        return {stat: (arrays[name][i, :, 0].copy(), arrays[name][i, :, 1].copy())
                for i, stat in enumerate(_statistic_names(config))}

    pilot = bias.BiasEstimate(
        np.asarray(config.times, dtype=np.float64), pairs("pilot_bias"), pairs("pilot_coarse"),
        record["pilot_paths"], record["pilot_path_steps"], float(record["pilot_wall_time_s"]),
        arrays["pilot_nonfinite"], pilot_config.h_max, pilot_config.step_c, record["pilot_batches"],
        arrays["pilot_decorrelation"])
    choice = bias.level_choice(pilot_config, pilot, record["rtol"])
    if choice.level != level or config_hash(choice.config) != config_hash(config):
        raise _refuse(p, f"malformed header: accuracy.level={level!r} is not the level its pilot "
                         f"chooses ({choice.level})")
    return choice


def _state_arrays(state: RunState) -> dict[str, np.ndarray]:
    state.pull()  # a GPU run's chunk lives on the device
    arrays = {name: np.ascontiguousarray(getattr(state, name)) for name in _PATH_ARRAYS}
    arrays["chunk_sums"] = np.ascontiguousarray(state.chunk_sums, dtype=_CHUNK_ARRAYS["chunk_sums"])
    arrays["chunk_hist"] = np.ascontiguousarray(state.chunk_hist, dtype=_CHUNK_ARRAYS["chunk_hist"])
    arrays["acc_sums"] = np.ascontiguousarray(state.acc.sums, dtype=_ACC_ARRAYS["acc_sums"])
    arrays["acc_hist"] = np.ascontiguousarray(state.acc.hist, dtype=_ACC_ARRAYS["acc_hist"])
    arrays["acc_filled"] = np.ascontiguousarray(state.acc.filled, dtype=_ACC_ARRAYS["acc_filled"])
    if state.tracks is not None and state.tracks.shape[0] > 0:
        arrays["tracks"] = np.ascontiguousarray(state.tracks, dtype=_TRACK_ARRAYS["tracks"])
    for name in _ADDITIVE_ARRAYS:
        value = getattr(state, name)
        if value is not None and value.shape[0] > 0:
            arrays[name] = np.ascontiguousarray(value, dtype=_ADDITIVE_ARRAYS[name])
    if state.acc.passage is not None:
        arrays["acc_passage"] = np.ascontiguousarray(state.acc.passage, dtype=_TRACK_ARRAYS["acc_passage"])
    for name in _PATH_ARRAYS:
        a = arrays[name]
        if a.dtype.kind not in _NUMERIC_KINDS:  # pragma: no cover - a RunState field of another kind
            raise TypeError(f"RunState.{name} has dtype {a.dtype}: not checkpointable")
        arrays[name] = a.astype(a.dtype.newbyteorder("<"), copy=False)
    return arrays


def write(path: str | os.PathLike, ckpt: Checkpoint) -> Path:
    """Write ``ckpt`` to ``path`` atomically (temporary file, fsync, ``os.replace``)."""
    # The arrays first: pulling them (state.pull) brings the run's position up to date
    arrays = {**_state_arrays(ckpt.state), **_pilot_arrays(ckpt.choice)}
    st = ckpt.state
    header = {
        **_common_header(ckpt),
        "run": {
            "first_batch": int(st.first_batch), "stop_batch": int(st.stop_batch), "b0": int(st.b0),
            "b1": int(st.b1), "j": int(st.j), "path_steps": int(st.path_steps),
            "done_work": float(st.done_work),
        },
        "backend": st.backend,
        "precision": st.precision,
        "threads": ckpt.threads,
        "chunk_paths": ckpt.chunk_paths,
        "extra": ckpt.extra,
        "bias_paths": ckpt.bias_paths,
        "accuracy": _pilot_record(ckpt.choice),
    }
    return _write_file(Path(path), header, arrays)


def _common_header(ckpt: _Saved) -> dict[str, Any]:
    """What every checkpoint's header holds: the format, the versions and build, the
    configuration and its hash, and where the result goes."""
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "stochpend_version": ckpt.stochpend_version,
        "stochpend_build": BUILD,
        "numpy_version": np.__version__,
        "numba_version": numba.__version__,
        "cpu_target": _cputarget.describe(),
        "created": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
        "config": config_to_json(ckpt.config),
        "config_sha256": config_hash(ckpt.config),
        "out": None if ckpt.out is None else str(ckpt.out),
        "overwrite": bool(ckpt.overwrite),
        "every_s": ckpt.every_s,
        "elapsed_s": float(ckpt.elapsed_s),
        "resumed": int(ckpt.resumed),
        "command_line": ckpt.command_line,
    }


def _write_file(p: Path, header: dict[str, Any], arrays: dict[str, np.ndarray]) -> Path:
    """The file of the module docstring: ``header`` with the table of ``arrays``, their bytes,
    the checksum; written atomically."""
    table = []
    offset = 0
    for name, a in arrays.items():
        table.append({"name": name, "dtype": a.dtype.str, "shape": list(a.shape), "offset": offset,
                      "nbytes": a.nbytes})
        offset += a.nbytes
    head = json.dumps({**header, "arrays": table}, sort_keys=True, allow_nan=False).encode()

    def put(fd: int) -> None:
        digest = hashlib.sha256()
        chunks: list[bytes | memoryview] = [MAGIC, _LEN.pack(len(head)), head]
        chunks += [a.reshape(-1).data.cast("B") for a in arrays.values()]
        for chunk in chunks:
            _files.write_all(fd, chunk)
            digest.update(chunk)
        _files.write_all(fd, digest.digest())

    # Only a regular file is replaced; a failed write leaves the previous checkpoint as it was.
    _files.write_atomic(p, put, overwrite=True, name="checkpoint")
    return p


def write_target(path: str | os.PathLike, ckpt: TargetCheckpoint) -> Path:
    """Write a target run's checkpoint to ``path`` atomically (as :func:`write`)."""
    t, journal = ckpt.target, ckpt.journal
    S, T = len(t.statistics), len(t.times)
    means = np.full((len(journal.rounds), len(_ROUND_MEANS), S, T), np.nan, dtype="<f8")
    counts = np.zeros((len(journal.rounds), T), dtype="<i8")
    for i, (_, r) in enumerate(journal.rounds):
        counts[i] = r.n
        for k, name in enumerate(_ROUND_MEANS):
            means[i, k] = getattr(r, name)
    ensembles = np.full((len(journal.ensembles), 2, S, T), np.nan, dtype="<f8")
    for q, e in enumerate(journal.ensembles):
        ensembles[q, 0, :, :e.stop + 1], ensembles[q, 1, :, :e.stop + 1] = e.f, e.f_var
    limit = ckpt.max_path_steps
    header = {
        **_common_header(ckpt),
        "kind": "target",
        "backend": ckpt.backend,
        "target": {
            "error": t.error, "confidence": t.confidence, "statistics": list(t.statistics),
            "times": [float(x) for x in t.times],
            "max_path_steps": None if limit is None or not math.isfinite(limit) else float(limit),
            "max_seconds": ckpt.max_seconds,
            "rounds": [{"level": int(level), "stop": int(r.stop), "seed": int(r.seed), "batches": int(r.batches),
                        "path_steps": int(r.path_steps), "nonfinite": int(r.nonfinite)}
                       for level, r in journal.rounds],
            "ensembles": [{"seed": int(e.seed), "h": float(e.h), "n": int(e.n), "stop": int(e.stop),
                           "path_steps": int(e.path_steps), "nonfinite": int(e.nonfinite)}
                          for e in journal.ensembles],
        },
    }
    return _write_file(Path(path), header, {"target_n": counts, "target_means": means,
                                            "target_ensembles": ensembles})


def _refuse(path: Path, why: str) -> ValueError:
    return ValueError(f"checkpoint={str(path)!r} is not accepted: {why}")


#: Peak memory of :func:`read` in units of the file's size: the bytes, the arrays copied out of
#: them and the state built from those; measured 2.59 for a 1.2 MB checkpoint (tracemalloc,
#: tests/unit/test_checkpoint.py), where the guard assumed 2.
READ_PEAK = 3


def read(path: str | os.PathLike) -> Checkpoint | TargetCheckpoint:
    """Read and verify a checkpoint (a target run's: :class:`TargetCheckpoint`); refuse
    (``ValueError``, one line) anything doubtful.

    Order: magic, SHA-256 over the whole file (truncation or corruption), format, stochpend
    version, configuration hash, then the array table against the configuration.
    """
    p = Path(path)
    if not p.is_file():
        raise _refuse(p, "no such file")
    # The file is read whole, and its arrays copied out of it (a sparse 64 GiB file with the
    # magic bytes would otherwise end in a MemoryError): READ_PEAK times its size must fit.
    from stochpend.runs import resources

    size, have = p.stat().st_size, resources.available_memory()
    if have is not None and READ_PEAK * size > have:
        raise _refuse(p, f"it is {resources.format_bytes(size)}, and reading it needs {READ_PEAK} times that, "
                         f"more than the {resources.format_bytes(have)} of memory available")
    data = p.read_bytes()
    if len(data) < len(MAGIC) + _LEN.size + _DIGEST or not data.startswith(MAGIC):
        if MAGIC.startswith(data[: len(MAGIC)]) and len(data) > 0:
            raise _refuse(p, "the file is truncated (a partial stochpend checkpoint)")
        raise _refuse(p, "not a stochpend checkpoint (wrong magic bytes)")
    body, digest = memoryview(data)[:-_DIGEST], data[-_DIGEST:]
    if hashlib.sha256(body).digest() != digest:
        raise _refuse(p, "checksum mismatch: the file is truncated or corrupted")
    (head_len,) = _LEN.unpack_from(body, len(MAGIC))
    start = len(MAGIC) + _LEN.size
    if start + head_len > len(body):
        raise _refuse(p, "header length beyond the end of the file")
    try:  # the writer never writes NaN or Infinity (allow_nan=False): refuse them here too
        header = json.loads(bytes(body[start:start + head_len]).decode(), parse_constant=_no_constant)
    except (UnicodeDecodeError, ValueError, RecursionError) as exc:
        why = "nested too deeply" if isinstance(exc, RecursionError) else str(exc)
        raise _refuse(p, f"unreadable header ({why})") from None
    payload = body[start + head_len:]
    try:
        return _from_header(p, header, payload)
    except (KeyError, TypeError, AttributeError, OverflowError, ValueError) as exc:
        if isinstance(exc, ValueError) and str(exc).startswith("checkpoint="):
            raise
        raise _refuse(p, f"malformed header ({type(exc).__name__}: {exc})") from None


def _no_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a valid value")


def _check_settings(p: Path, header: dict[str, Any]) -> None:
    """The run's settings in the header have the types the writer gives them (a crafted but
    correctly checksummed file fails here in one line, not later in a traceback)."""
    def positive_int(v: Any) -> bool:
        return v is None or (isinstance(v, int) and not isinstance(v, bool) and v >= 1)

    def number(v: Any, *, none: bool) -> bool:
        return (none and v is None) or (isinstance(v, int | float) and not isinstance(v, bool)
                                        and math.isfinite(v) and v >= 0)

    def integer(v: Any, lo: int, hi: int) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and lo <= v <= hi

    def pilot(v: Any) -> bool:
        return v is None or (
            isinstance(v, dict) and sorted(v) == sorted(_PILOT_KEYS)
            and integer(v["level"], 0, bias.MAX_LEVEL)
            and (v["rtol"] is None or (number(v["rtol"], none=False) and 0 < v["rtol"] < 1))
            and integer(v["pilot_paths"], 2, 1 << 40) and integer(v["pilot_path_steps"], 0, 2**63 - 1)
            and number(v["pilot_wall_time_s"], none=False)
            and integer(v["pilot_batches"], 1, bias.BIAS_BATCHES))

    checks = {
        "threads": positive_int(header.get("threads")),
        "chunk_paths": positive_int(header.get("chunk_paths")),
        "every_s": number(header.get("every_s"), none=True) and header.get("every_s") != 0,
        "elapsed_s": number(header.get("elapsed_s", 0.0), none=False),
        "resumed": positive_int(header.get("resumed", 0) or None),
        # Text that reaches the result's attributes or a path: a NUL (valid JSON) is refused here,
        # before the work; NetCDF cannot store it, and the run could never have been written.
        "out": header.get("out") is None or (isinstance(header.get("out"), str) and "\x00" not in header["out"]),
        "command_line": header.get("command_line") is None
        or (isinstance(header.get("command_line"), str) and "\x00" not in header["command_line"]),
    }
    if "run" in header:  # an ordinary run's (a target run's are checked with its record)
        checks.update({
            "done_work": number(header["run"].get("done_work"), none=False),
            # None: a checkpoint from before bias_paths was recorded (the default pairs)
            "bias_paths": header.get("bias_paths") is None or integer(header.get("bias_paths"), 0, 0)
            or integer(header.get("bias_paths"), 2, 1 << 40),
            "accuracy": pilot(header.get("accuracy")),
        })
    bad = [k for k, ok in checks.items() if not ok]
    if bad:
        from stochpend.text._terminal import short

        shown = header.get(bad[0], header.get("run", {}).get(bad[0]))
        raise _refuse(p, f"malformed header: {bad[0]}={short(repr(shown))}")


def _from_header(p: Path, header: dict[str, Any], payload: memoryview) -> Checkpoint | TargetCheckpoint:
    config = _origin(p, header)
    if header.get("kind", "run") != "run":
        if header["kind"] != "target":
            raise _refuse(p, f"unknown kind {header['kind']!r}")
        return _target_from_header(p, header, payload, config)
    return _run_from_header(p, header, payload, config)


def _origin(p: Path, header: dict[str, Any]) -> SimulationConfig:
    """The format, the stochpend that wrote the file, and its configuration (rebuilt, and so
    validated, to the hash it was saved with)."""
    if header.get("format") != FORMAT:
        raise _refuse(p, f"unknown format {header.get('format')!r}")
    if header.get("format_version") != FORMAT_VERSION:
        raise _refuse(p, f"checkpoint format version {header.get('format_version')!r}; "
                         f"this stochpend reads version {FORMAT_VERSION}")
    version = header.get("stochpend_version")
    if version != __version__:
        raise _refuse(p, f"written by stochpend {version}, this is stochpend {__version__}; "
                         f"resume it with stochpend {version}")
    build = header.get("stochpend_build")
    if build != BUILD:
        raise _refuse(p, f"written by stochpend {build}, this is stochpend {BUILD}: the code that "
                         f"determines the numbers differs; resume it with the stochpend that wrote it")
    try:
        config = config_from_json(header["config"])
    except ValueError as exc:
        raise _refuse(p, f"its configuration no longer validates ({exc})") from None
    if config_hash(config) != header.get("config_sha256"):
        raise _refuse(p, "configuration hash mismatch: the stored configuration does not rebuild "
                         "to the configuration that ran")
    return config


def _run_from_header(p: Path, header: dict[str, Any], payload: memoryview, config: SimulationConfig) -> Checkpoint:
    version = header["stochpend_version"]
    run = header["run"]
    r = {k: run[k] for k in _RUN_FIELDS}
    n_times = len(config.times)
    bs = config.batch_size
    ok = (all(isinstance(v, int) and not isinstance(v, bool) and 0 <= v < 2**63
              for k, v in r.items() if k != "done_work")
          and 0 <= r["first_batch"] <= r["b0"] < r["b1"] <= r["stop_batch"] <= config.n_batches
          and 0 <= r["j"] <= n_times and r["path_steps"] >= 0)
    if not ok:
        raise _refuse(p, f"inconsistent run position {r}")
    _check_settings(p, header)  # before the arrays: `accuracy` says which arrays there are
    n = min(r["b1"] * bs, config.paths) - r["b0"] * bs
    n_cols = hist_columns(config)
    shapes: dict[str, tuple[int, ...]] = {name: (n,) for name in _PATH_ARRAYS}
    shapes.update({
        "chunk_sums": (r["b1"] - r["b0"], n_times, n_sums(config)),
        "chunk_hist": (n_times, n_cols),
        "acc_sums": (config.n_batches, n_times, n_sums(config)),
        "acc_hist": (n_times, n_cols),
        "acc_filled": (config.n_batches,),
    })
    n_slots = len(observables.accumulators(observables.objects(config.observables)))
    if n_slots:
        shapes["tracks"] = (n_slots, n)
    n_passages = len(passage_slots(config.observables))
    if n_passages:
        shapes["acc_passage"] = (n_passages, config.paths)
    for name in additive_arrays(config):
        shapes[name] = (n,)
    record = header.get("accuracy")
    if record is not None:
        n_stats = len(_statistic_names(config))
        shapes.update({"pilot_bias": (n_stats, n_times, 2), "pilot_coarse": (n_stats, n_times, 2),
                       "pilot_nonfinite": (n_times,), "pilot_decorrelation": (n_times,)})
    backend = header.get("backend", "cpu")
    precision = header.get("precision", "float64")
    if backend not in BACKENDS or precision not in ("float64", "float32"):
        raise _refuse(p, f"unknown backend {backend!r} or precision {precision!r}")
    # Every array has the one dtype its engine holds it in (S15, S16: an '<i8' position or a
    # '|b1' status, same size, was accepted and reinterpreted as garbage).
    fixed: dict[str, Any] = {**_CHUNK_ARRAYS, **_ACC_ARRAYS, **_PILOT_ARRAYS, **_TRACK_ARRAYS,
                             **path_dtypes(backend, precision), **_ADDITIVE_ARRAYS}
    arrays = _arrays(p, header, payload, shapes, fixed)

    acc = EnsembleSums(arrays["acc_sums"], arrays["acc_hist"], arrays["acc_filled"], config.observables,
                       arrays.get("acc_passage"))
    fields_read: dict[str, Any] = {k: (float(v) if k == "done_work" else int(v)) for k, v in r.items()}
    fields_read.update({name: arrays[name] for name in _PATH_ARRAYS})
    state = RunState(**fields_read,
                     chunk_sums=arrays["chunk_sums"], chunk_hist=arrays["chunk_hist"], acc=acc,
                     backend=backend, precision=precision, tracks=arrays.get("tracks"),
                     xi_a=arrays.get("xi_a"), aux_a=arrays.get("aux_a"))
    out = header.get("out")
    return Checkpoint(
        config=config, state=state, out=None if out is None else Path(out),
        overwrite=bool(header.get("overwrite", False)), every_s=header.get("every_s"),
        threads=header.get("threads"), chunk_paths=header.get("chunk_paths"),
        elapsed_s=float(header.get("elapsed_s", 0.0)), resumed=int(header.get("resumed", 0)),
        command_line=header.get("command_line"), created=str(header.get("created", "")),
        stochpend_version=version, extra=dict(header.get("extra") or {}),
        bias_paths=header.get("bias_paths"),
        choice=None if record is None else _level_choice(p, config, record, arrays),
    )


def _target_from_header(p: Path, header: dict[str, Any], payload: memoryview,
                        config: SimulationConfig) -> TargetCheckpoint:
    """A target run's checkpoint: its record and arrays checked as hostile, field by field, the
    target validated against the configuration as a new one is; whether each round is the one
    the run makes is checked as it replays (:class:`stochpend.runs.multilevel.Journal`)."""
    from stochpend.runs import resources

    _check_settings(p, header)
    rec = header["target"]
    if not isinstance(rec, dict) or sorted(rec) != sorted(_TARGET_KEYS):
        raise _refuse(p, "malformed header: target")
    try:
        target = multilevel.check_target(config, rec["error"], rec["confidence"], rec["statistics"], rec["times"])
        limit = None if rec["max_path_steps"] is None else resources.work_limit(rec["max_path_steps"])
        max_seconds = multilevel.check_max_seconds(rec["max_seconds"])
    except ValueError as exc:
        raise _refuse(p, f"its target no longer validates ({exc})") from None
    if not isinstance(rec["statistics"], list) or not isinstance(rec["times"], list):
        raise _refuse(p, "malformed header: target")
    backend = header.get("backend")
    if backend not in BACKENDS:
        raise _refuse(p, f"unknown backend {backend!r}")
    S, T = len(target.statistics), len(target.times)

    def integer(v: Any, lo: int, hi: int) -> bool:
        return isinstance(v, int) and not isinstance(v, bool) and lo <= v < hi

    rounds, ensembles = rec["rounds"], rec["ensembles"]
    if not isinstance(rounds, list) or not isinstance(ensembles, list):
        raise _refuse(p, "malformed header: target.rounds")
    for i, r in enumerate(rounds):
        if not (isinstance(r, dict) and sorted(r) == sorted(_ROUND_KEYS)
                and integer(r["level"], 0, multilevel.MAX_LEVEL + 1) and integer(r["stop"], 0, T)
                and integer(r["seed"], 0, 2**64) and integer(r["batches"], 1, multilevel.LEVEL_BATCHES + 1)
                and integer(r["path_steps"], 0, 2**63) and integer(r["nonfinite"], 0, 2**63)):
            raise _refuse(p, f"malformed header: target.rounds[{i}]")
    for q, e in enumerate(ensembles):
        if not (isinstance(e, dict) and sorted(e) == sorted(_ENSEMBLE_KEYS) and integer(e["seed"], 0, 2**64)
                and isinstance(e["h"], float) and math.isfinite(e["h"]) and e["h"] > 0
                and integer(e["n"], 1, 1 << 40) and integer(e["stop"], 0, T)
                and integer(e["path_steps"], 0, 2**63) and integer(e["nonfinite"], 0, 2**63)):
            raise _refuse(p, f"malformed header: target.ensembles[{q}]")
    shapes = {"target_n": (len(rounds), T), "target_means": (len(rounds), len(_ROUND_MEANS), S, T),
              "target_ensembles": (len(ensembles), 2, S, T)}
    arrays = _arrays(p, header, payload, shapes, _TARGET_ARRAYS)
    journal = multilevel.Journal(source=f"checkpoint={str(p)!r}", elapsed_s=float(header.get("elapsed_s", 0.0)))
    for i, r in enumerate(rounds):
        n, stop = arrays["target_n"][i], r["stop"]
        # a round's samples reach every time up to its last, none after (multilevel._counts)
        if not (n[0] >= 1 and np.all(n[:stop + 1] == n[0]) and np.all(n[stop + 1:] == 0)):
            raise _refuse(p, f"array 'target_n' row {i} is not a round's samples to time index {stop}")
        means = {name: arrays["target_means"][i, k] for k, name in enumerate(_ROUND_MEANS)}
        journal.rounds.append((r["level"], multilevel.Round(
            n=n, stop=stop, t_stop=float(target.times[stop]), path_steps=r["path_steps"], seed=r["seed"],
            batches=r["batches"], nonfinite=r["nonfinite"], **means)))
    for q, e in enumerate(ensembles):
        stop = e["stop"]
        journal.ensembles.append(multilevel.Ensemble(
            e["seed"], e["h"], e["n"], stop, arrays["target_ensembles"][q, 0, :, :stop + 1].copy(),
            arrays["target_ensembles"][q, 1, :, :stop + 1].copy(), e["path_steps"], e["nonfinite"]))
    out = header.get("out")
    return TargetCheckpoint(
        config=config, target=target, journal=journal, backend=backend, max_path_steps=limit,
        max_seconds=max_seconds, out=None if out is None else Path(out),
        overwrite=bool(header.get("overwrite", False)), every_s=header.get("every_s"),
        elapsed_s=float(header.get("elapsed_s", 0.0)), resumed=int(header.get("resumed", 0)),
        command_line=header.get("command_line"), created=str(header.get("created", "")),
        stochpend_version=header["stochpend_version"])


def _arrays(p: Path, header: dict[str, Any], payload: memoryview, shapes: dict[str, tuple[int, ...]],
            fixed: dict[str, Any]) -> dict[str, np.ndarray]:
    """The arrays of the header's table, each of the one dtype ``fixed`` and shape ``shapes``
    give its name and within the payload; every one of ``shapes`` present, no other."""
    arrays: dict[str, np.ndarray] = {}
    entry: Any
    for entry in header["arrays"]:
        name = entry["name"]
        if name not in shapes or name in arrays:
            raise _refuse(p, f"unexpected array {name!r}")
        try:
            dtype = np.dtype(entry["dtype"])
        except TypeError:
            raise _refuse(p, f"array {name!r} has dtype {entry['dtype']!r}") from None
        ok_dtype = dtype.str == np.dtype(fixed[name]).str
        if not ok_dtype or tuple(entry["shape"]) != shapes[name]:
            expected = np.dtype(fixed[name]).str
            raise _refuse(p, f"array {name!r} has dtype {entry['dtype']} and shape {tuple(entry['shape'])}, "
                             f"expected {expected} and {shapes[name]}")
        off, nbytes = int(entry["offset"]), int(entry["nbytes"])
        if nbytes != dtype.itemsize * int(np.prod(shapes[name])) or off < 0 or off + nbytes > len(payload):
            raise _refuse(p, f"array {name!r} lies outside the file")
        arrays[name] = np.frombuffer(payload[off:off + nbytes], dtype=dtype).reshape(shapes[name]).copy()
    missing = set(shapes) - set(arrays)
    if missing:
        raise _refuse(p, f"missing arrays {sorted(missing)}")
    return arrays


# -- saving during a run ---------------------------------------------------------------------
class FileCheckpointer:
    """A :class:`~stochpend.runs.simulate.Checkpointer` that writes the state every ``every_s`` seconds,
    and at the run's last kernel boundary (so that the result, if it cannot be written, is kept).

    It is also where a deferred Ctrl-C or SIGTERM takes effect: :meth:`request_stop` (called
    by the signal handler of :func:`run_checkpointed`) makes the next ``maybe_save``, which
    runs only between kernel calls where the state is consistent, write a checkpoint and raise
    :class:`CheckpointInterrupt`.
    """

    def __init__(self, path: str | os.PathLike, every_s: float | None, *, config: SimulationConfig,
                 out: Path | None = None, overwrite: bool = False, threads: int | None = None,
                 chunk_paths: int | None = None, command_line: str | None = None,
                 elapsed_before_s: float = 0.0, resumed: int = 0) -> None:
        self.path = Path(path)
        self.every_s = every_s
        self.config = config
        self.out = out
        self.overwrite = overwrite
        self.threads = threads
        self.chunk_paths = chunk_paths
        self.command_line = command_line
        self.elapsed_before_s = elapsed_before_s
        self.resumed = resumed
        self.started = _time.monotonic()
        self.last_save = self.started
        self.saves = 0
        self.stop_requested = False
        self.stop_signal = int(signal.SIGINT)
        self.bias_paths: int | None = None
        self.choice: bias.LevelChoice | None = None

    def record(self, config: SimulationConfig, bias_paths: int, choice: bias.LevelChoice | None) -> None:
        """The run as it goes on (:class:`stochpend.runs.lifecycle.Saver`): saved with every checkpoint,
        so that a resume runs the same refined configuration with the same bias estimate."""
        self.config, self.bias_paths, self.choice = config, bias_paths, choice

    def signals(self) -> contextlib.AbstractContextManager[None]:
        return deferred_signals(self)

    def attrs(self) -> dict[str, Any]:
        out: dict[str, Any] = {"checkpoint": str(self.path),
                               "checkpoint_every_s": "none" if self.every_s is None else float(self.every_s),
                               "resumed": self.resumed}
        if self.command_line:
            out["command_line"] = self.command_line
        return out

    def request_stop(self, signum: int = signal.SIGINT) -> None:
        self.stop_requested = True
        self.stop_signal = int(signum)

    def elapsed_s(self) -> float:
        return self.elapsed_before_s + (_time.monotonic() - self.started)

    def save(self, state: RunState) -> Path:
        """Write the state; a failed write (full disk) raises :class:`stochpend.io.WriteError`
        with one line, the previous checkpoint left as it was."""
        ckpt = Checkpoint(
            config=self.config, state=state, out=self.out, overwrite=self.overwrite,
            every_s=self.every_s, threads=self.threads, chunk_paths=self.chunk_paths,
            elapsed_s=self.elapsed_s(), resumed=self.resumed, command_line=self.command_line,
            bias_paths=self.bias_paths, choice=self.choice,
        )
        return self._written(lambda: write(self.path, ckpt))

    def _written(self, write_file: Any) -> Path:
        """Call ``write_file()``; a failure in one line that says what is kept (see :meth:`save`)."""
        try:
            write_file()
        except (OSError, ValueError) as exc:
            # ValueError: something not a regular file appeared at the path while the run worked
            # (NEW12, a symlink); it is not replaced, and mid-run that is a failure (exit 1), not
            # input refused before the work (exit 2).
            why = io.reason(exc) if isinstance(exc, OSError) else str(exc).split(" is not accepted: ", 1)[-1]
            if self.path.is_file() and not self.path.is_symlink():
                kept = (f"the previous checkpoint is kept: continue with `{resume_advice(self.path, self.out)}` "
                        "once the cause is fixed")
            elif self.saves > 0 or self.resumed:  # written before, and gone now: say so
                where = self.path.parent
                gone = "" if where.is_dir() else f" (its directory {str(where)!r} is gone)"
                kept = f"the checkpoint written before is gone too{gone}: the run is lost"
            else:
                kept = "no checkpoint was written before"
            raise io.WriteError(f"cannot write the checkpoint {str(self.path)!r}: {why}; {kept}",
                                getattr(exc, "errno", None)) from None
        self.saves += 1
        self.last_save = _time.monotonic()
        return self.path

    def maybe_save(self, state: RunState) -> None:
        if self.stop_requested:
            self.save(state)
            raise CheckpointInterrupt(self.path, self.stop_signal)
        if self.every_s is not None and _time.monotonic() - self.last_save >= self.every_s:
            self.save(state)
        elif state.b1 >= state.stop_batch and state.j == len(self.config.times):
            # The last kernel boundary: save, so that a result that cannot be written (full
            # disk, a crash in the write, an output taken meanwhile) costs no recomputation.
            self.save(state)


class TargetCheckpointer(FileCheckpointer):
    """Saves a target run's journal (:class:`stochpend.runs.multilevel.Journal`) at its round
    boundaries: every ``every_s`` seconds, and on a deferred Ctrl-C or SIGTERM, after which it
    raises :class:`CheckpointInterrupt` (a round under way when the signal comes is finished
    first: its work is kept)."""

    def __init__(self, path: str | os.PathLike, every_s: float | None, *, config: SimulationConfig,
                 target: multilevel.Target, backend: str = "cpu", max_path_steps: float | None = None,
                 max_seconds: float | None = None, out: Path | None = None, overwrite: bool = False,
                 command_line: str | None = None, elapsed_before_s: float = 0.0, resumed: int = 0) -> None:
        super().__init__(path, every_s, config=config, out=out, overwrite=overwrite, command_line=command_line,
                         elapsed_before_s=elapsed_before_s, resumed=resumed)
        self.target, self.backend = target, backend
        self.max_path_steps, self.max_seconds = max_path_steps, max_seconds

    def save_journal(self, journal: multilevel.Journal) -> Path:
        """Write the run as it stands (a failed write as :meth:`FileCheckpointer.save`'s)."""
        ckpt = TargetCheckpoint(
            config=self.config, target=self.target, journal=journal, backend=self.backend,
            max_path_steps=self.max_path_steps, max_seconds=self.max_seconds, out=self.out,
            overwrite=self.overwrite, every_s=self.every_s, elapsed_s=self.elapsed_s(), resumed=self.resumed,
            command_line=self.command_line)
        return self._written(lambda: write_target(self.path, ckpt))

    def round_done(self, journal: multilevel.Journal) -> None:
        """A round boundary (the journal's ``saved``): save when asked to stop, or when due."""
        if self.stop_requested:
            self.save_journal(journal)
            raise CheckpointInterrupt(self.path, self.stop_signal)
        if self.every_s is not None and _time.monotonic() - self.last_save >= self.every_s:
            self.save_journal(journal)


@contextlib.contextmanager
def deferred_signals(checkpointer: FileCheckpointer) -> Iterator[None]:
    """First Ctrl-C, SIGTERM or SIGHUP: ask the checkpointer to save and stop at the next kernel boundary.

    A second Ctrl-C raises ``KeyboardInterrupt`` at once (no new checkpoint). A signal that was
    ignored when the run started (``SIG_IGN``, e.g. SIGINT in a background job) stays ignored.
    SIGTERM is what a batch system (Slurm) sends before it kills a job at its time limit.
    Outside the main thread signals cannot be handled, and this does nothing.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: Any) -> None:
        if checkpointer.stop_requested and signum == signal.SIGINT:
            _files.record_signal(signum)  # raised again at the next boundary if dropped
            raise KeyboardInterrupt
        checkpointer.request_stop(signum)

    previous = {}
    # SIGHUP too: a dropped SSH session must not lose the work since the last checkpoint.
    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        if signal.getsignal(sig) is not signal.SIG_IGN:
            previous[sig] = signal.signal(sig, handler)
    # A signal before the handlers were in place whose exception was dropped (a Ctrl-C in an
    # import's weakref callback): the run stops at its first boundary, as for one that came now.
    missed = _files.take_pending()
    if missed is not None:
        checkpointer.request_stop(missed)
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


def check_checkpoint_path(path: str | os.PathLike, *, out: Path | None = None) -> Path:
    """Refuse, before any work, a checkpoint path that exists or cannot be written."""
    p = Path(path)
    if os.path.lexists(p) and p.is_file() and not p.is_symlink():
        raise ValueError(
            f"checkpoint={str(p)!r} is not accepted: the file exists; continue that run with "
            f"`{resume_advice(p, out)}`, or delete the file"
        )
    _files.check_output(p, name="checkpoint")
    if out is not None and Path(out).absolute().resolve() == p.absolute().resolve():
        raise ValueError(f"checkpoint={str(p)!r} is not accepted: it is the same file as --out")
    return p


# -- ownership: one run (or resume) per checkpoint ---------------------------------------------
_HELD: dict[str, int] = {}  # lock paths this process holds -> depth


def lock_path(path: str | os.PathLike) -> Path:
    """The lock file of a checkpoint: ``.NAME-lock`` beside it (the checkpoint itself is
    replaced by a rename at every save, so it cannot carry the lock)."""
    p = Path(path)
    return p.parent / f".{p.name}-lock"


@contextlib.contextmanager
def owned(path: str | os.PathLike, *, break_lock: bool = False) -> Iterator[None]:
    """Hold the exclusive lock of checkpoint ``path`` for the run's life.

    ``fcntl.flock`` on ``.NAME-lock``, which records the holder's host and pid; the kernel
    releases it when the holder dies (even by ``kill -9``), so a lock is never stale on this
    host. A second run or resume of the same checkpoint is refused (``ValueError``, one line
    naming the holder). ``break_lock`` takes the lock from a holder on another host (a shared
    file system) or runs without one on a file system that has no locks. Re-entrant within a
    process (the CLI takes it before reading the checkpoint, the API again around the run).
    """
    import fcntl
    import socket

    p = Path(path)
    lp = lock_path(p)
    key = str(lp.absolute())
    if key in _HELD:
        _HELD[key] += 1
        try:
            yield
        finally:
            _HELD[key] -= 1
        return
    fd = None
    for _ in range(10):
        fd = _open_lock(p, lp)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _plain_holder(fd)
            os.close(fd)
            fd = None
            if break_lock:
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(lp)
                continue
            raise _refuse(p, f"it is in use by {holder}; wait until that run ends (a lock dies with "
                             "its process), or pass --break-lock if it was held from another host "
                             "that is gone") from None
        except OSError as exc:  # a file system without locks (some NFS mounts)
            os.close(fd)
            fd = None
            if not break_lock:
                raise _refuse(p, f"its file system cannot lock it ({io.reason(exc)}); pass --break-lock "
                                 "to run without a lock (then make sure no other run uses it)") from None
            break
        # The holder before us may have removed the lock file between our open and our lock.
        try:
            same = os.stat(lp).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
        fd = None
    else:
        raise _refuse(p, f"its lock file {str(lp)!r} keeps being replaced by other processes")
    if fd is not None:
        os.ftruncate(fd, 0)
        os.write(fd, f"pid {os.getpid()} on host {socket.gethostname()} since "
                     f"{_time.strftime('%Y-%m-%dT%H:%M:%SZ', _time.gmtime())}".encode())
    _HELD[key] = 1
    try:
        yield
    finally:
        del _HELD[key]
        if fd is not None:
            with contextlib.suppress(OSError):
                os.unlink(lp)  # while still holding it: the next run creates a fresh one
            os.close(fd)


def _open_lock(p: Path, lp: Path) -> int:
    """Open (creating it exclusively if absent) the lock file ``lp`` of checkpoint ``p``.

    The lock file is truncated and written (the holder's pid), so only a file this tool could
    have made is opened: a regular file with one link, owned by this user. A hard link to a
    user's file planted at that name would otherwise have its content replaced, and a FIFO or a
    device be written to; those are refused in one line without being opened."""
    flags = os.O_RDWR | os.O_NOFOLLOW | os.O_CLOEXEC | os.O_NONBLOCK
    try:
        return os.open(lp, flags | os.O_CREAT | os.O_EXCL, 0o644)
    except FileExistsError:
        pass  # a lock left by a live holder or by a killed one: checked below before use
    except OSError as exc:
        raise _refuse(p, f"its lock file {str(lp)!r} cannot be opened ({io.reason(exc)})") from None
    try:
        st = os.lstat(lp)
    except FileNotFoundError:  # its holder removed it meanwhile: the caller's loop tries again
        st = None
    except OSError as exc:
        raise _refuse(p, f"its lock file {str(lp)!r} cannot be opened ({io.reason(exc)})") from None
    if st is not None:
        _check_lock_stat(p, lp, st)
    try:
        fd = os.open(lp, flags | (os.O_CREAT | os.O_EXCL if st is None else 0), 0o644)
    except OSError as exc:
        raise _refuse(p, f"its lock file {str(lp)!r} cannot be opened ({io.reason(exc)})") from None
    try:  # what was opened, not what was looked at (it may have been swapped in between)
        _check_lock_stat(p, lp, os.fstat(fd))
    except ValueError:
        os.close(fd)
        raise
    return fd


def _check_lock_stat(p: Path, lp: Path, st: os.stat_result) -> None:
    import stat

    if stat.S_ISLNK(st.st_mode):
        why = "a symbolic link"
    elif not stat.S_ISREG(st.st_mode):
        why = _files._kind(st.st_mode)
    elif st.st_nlink != 1:
        why = f"a file with {st.st_nlink} links (a hard link to another file)"
    elif st.st_uid != os.geteuid():
        why = f"owned by another user (uid {st.st_uid})"
    else:
        return
    raise _refuse(p, f"its lock file {str(lp)!r} is {why}; it was not touched: remove it if "
                     "it is not yours, or choose another checkpoint name")


def _plain_holder(fd: int) -> str:
    from stochpend.text._terminal import plain

    try:
        text = os.pread(fd, 200, 0).decode("utf-8", "replace").strip()
    except OSError:
        text = ""
    return plain(text) if text else "another process"


def check_work(ckpt: Checkpoint, max_path_steps: float | None = None) -> None:
    """Refuse, before any work, resuming a run whose configuration needs more memory than is
    available or more work than the limit (``max_path_steps`` as ``stochpend simulate``'s; the
    limit the original run was given is not taken from the file, which anyone may have edited:
    a crafted ``t_max = 1e300`` must not run for ever)."""
    from stochpend.runs import resources

    resources.check(ckpt.config, backend=ckpt.state.backend, precision=ckpt.state.precision,
                    max_path_steps=max_path_steps)


def check_not_checkpoint(out: str | os.PathLike, checkpoint_path: str | os.PathLike) -> None:
    """Refuse an output that is the checkpoint itself (``resume CK --out CK --overwrite`` wrote
    the result over the checkpoint, then removed it: nothing was left)."""
    if Path(out).absolute().resolve() == Path(checkpoint_path).absolute().resolve():
        raise ValueError(f"out={str(out)!r} is not accepted: it is the checkpoint itself, which "
                         "holds the run until its result is written; choose another file")


def resume_advice(path: str | os.PathLike, out: str | os.PathLike | None = None) -> str:
    """The command that continues the run of checkpoint ``path`` whose result goes to ``out``,
    as it must be typed: ``resume`` trusts a recorded output only in the checkpoint's own
    directory (:func:`own_out`), so an ``out`` elsewhere is named with ``--out`` (the advice
    printed without it was refused); names are quoted for a POSIX shell."""
    import shlex

    command = f"stochpend resume {shlex.quote(str(path))}"
    if out is not None:
        ck_dir = Path(path).absolute().parent
        if Path(out).absolute().parent.resolve() != ck_dir.resolve():
            command += f" --out {shlex.quote(str(out))}"
    return command


def own_out(path: str | os.PathLike, recorded: Path) -> Path:
    """The output a checkpoint names for itself, trusted only as a name in the checkpoint's own
    directory: a checkpoint someone hands you must not choose where its result goes."""
    ck_dir = Path(path).absolute().parent
    if Path(recorded).absolute().parent.resolve() != ck_dir.resolve():
        raise _refuse(Path(path), f"it names out={str(recorded)!r}, outside the checkpoint's own "
                                  "directory; pass --out FILE to say where the result goes")
    return ck_dir / Path(recorded).name


def run_checkpointed(
    config: SimulationConfig,
    *,
    checkpoint_path: str | os.PathLike,
    every_s: float | None,
    out: str | os.PathLike | None = None,
    overwrite: bool = False,
    threads: int | None = None,
    chunk_paths: int | None = None,
    progress: Progress | None = None,
    command_line: str | None = None,
    checkpointer: FileCheckpointer | None = None,
    backend: str = "cpu",
    precision: str = "float64",
    _resume: Checkpoint | None = None,
    break_lock: bool = False,
    bias_paths: int | None = None,
    accuracy: str = "fixed",
    rtol: float | None = None,
    max_path_steps: float | None = None,
) -> xr.Dataset:
    """Run ``config`` saving checkpoints to ``checkpoint_path``; write ``out``; return the result.

    On Ctrl-C or SIGTERM the state is saved and :class:`CheckpointInterrupt` (a
    ``KeyboardInterrupt``) is raised; a signal after the last kernel call lets the run finish.
    On success the result is written to ``out`` (when given) and the checkpoint file is
    removed. The numbers equal those of :func:`stochpend.runs.simulate.run` with the same
    ``backend``, ``precision``, ``bias_paths``, ``accuracy`` and ``rtol`` exactly (both are
    :func:`stochpend.runs.lifecycle.execute`); ``auto``'s pilot runs first, and the checkpoint saves
    the level it chose. A resumed run (``_resume``) continues with the settings saved in its
    checkpoint (backend, precision, bias_paths, level), whatever is passed here. The run holds
    the checkpoint's lock (:func:`owned`) from start to end; ``break_lock`` as there.
    """
    with owned(checkpoint_path, break_lock=break_lock):
        return _run_owned(config, checkpoint_path=checkpoint_path, every_s=every_s, out=out,
                          overwrite=overwrite, threads=threads, chunk_paths=chunk_paths,
                          progress=progress, command_line=command_line, checkpointer=checkpointer,
                          backend=backend, precision=precision, _resume=_resume, bias_paths=bias_paths,
                          accuracy=accuracy, rtol=rtol, max_path_steps=max_path_steps)


def _run_owned(config: SimulationConfig, *, checkpoint_path: str | os.PathLike, every_s: float | None,
               out: str | os.PathLike | None, overwrite: bool, threads: int | None,
               chunk_paths: int | None, progress: Progress | None, command_line: str | None,
               checkpointer: FileCheckpointer | None, backend: str, precision: str,
               _resume: Checkpoint | None, bias_paths: int | None, accuracy: str, rtol: float | None,
               max_path_steps: float | None) -> xr.Dataset:
    out_p = None if out is None else Path(out).absolute()
    if out_p is not None:
        io.check_output_path(out_p, overwrite=overwrite)
        check_not_checkpoint(out_p, checkpoint_path)
    if _resume is not None:  # the same run: its settings are the checkpoint's
        backend, precision, bias_paths = _resume.state.backend, _resume.state.precision, _resume.bias_paths
        accuracy, rtol = ("auto", _resume.choice.rtol) if _resume.choice is not None else ("fixed", None)
    if checkpointer is None:
        checkpointer = FileCheckpointer(
            checkpoint_path, every_s, config=config, out=out_p, overwrite=overwrite, threads=threads,
            chunk_paths=chunk_paths, command_line=command_line,
            elapsed_before_s=0.0 if _resume is None else _resume.elapsed_s,
            resumed=0 if _resume is None else _resume.resumed + 1,
        )
    saving = Checkpointing(checkpointer, None if _resume is None else _resume.state,
                           None if _resume is None else _resume.choice)
    run = RunOptions.build(config, backend=backend, precision=precision, threads=threads, chunk_paths=chunk_paths,
                    bias_paths=bias_paths, accuracy=accuracy, rtol=rtol, max_path_steps=max_path_steps,
                    checkpointing=saving)
    ds, _ = execute(run, progress=progress)
    _write_result(ds, out_p, overwrite, checkpointer)
    return ds


def _write_result(ds: xr.Dataset, out_p: Path | None, overwrite: bool, checkpointer: FileCheckpointer) -> None:
    """Write a checkpointed run's result to ``out_p`` (None: nothing), then remove its
    checkpoint; a write that fails says in one line what is kept and how to finish it."""
    if out_p is not None:
        try:
            io.to_netcdf(ds, out_p, overwrite=overwrite)
        except KeyboardInterrupt:
            # A signal that lands once the result is in place: the run is done, so its checkpoint
            # goes as on success (kept, it advised a resume that then found the file written).
            if _files.placed(out_p):
                with contextlib.suppress(FileNotFoundError):
                    os.unlink(checkpointer.path)
            raise
        except (OSError, ValueError) as exc:  # a full disk, a directory gone; a file that appeared
            if checkpointer.path.is_file():  # claim only what is true now
                keep = (f"; the finished run is kept in {str(checkpointer.path)!r}: "
                        f"`{resume_advice(checkpointer.path, out_p)}` writes it (add --out FILE to write "
                        "it elsewhere)")
            else:
                keep = f"; the checkpoint {str(checkpointer.path)!r} is gone too: the run is lost"
            if isinstance(exc, ValueError):
                raise ValueError(f"{exc}{keep}") from None
            raise io.WriteError(f"{exc}{keep}", getattr(exc, "errno", None)) from None
    with contextlib.suppress(FileNotFoundError):
        os.unlink(checkpointer.path)


def run_target_checkpointed(
    config: SimulationConfig,
    target: multilevel.Target,
    *,
    checkpoint_path: str | os.PathLike,
    every_s: float | None,
    out: str | os.PathLike | None = None,
    overwrite: bool = False,
    backend: str = "cpu",
    max_path_steps: float | None = None,
    max_seconds: float | None = None,
    note: Any = None,
    command_line: str | None = None,
    checkpointer: TargetCheckpointer | None = None,
    _resume: TargetCheckpoint | None = None,
    break_lock: bool = False,
) -> xr.Dataset:
    """:func:`stochpend.runs.multilevel.target_run` saving its journal to ``checkpoint_path`` at
    round boundaries (:class:`TargetCheckpointer`); write ``out``; return the result.

    As :func:`run_checkpointed`: Ctrl-C or SIGTERM saves and raises :class:`CheckpointInterrupt`;
    the finished run is saved once more before its result is written, then the checkpoint is
    removed; the checkpoint's lock is held throughout. A resumed run (``_resume``) replays the
    saved journal and goes on: its numbers are those of the uninterrupted run, to the last bit.
    """
    with owned(checkpoint_path, break_lock=break_lock):
        out_p = None if out is None else Path(out).absolute()
        if out_p is not None:
            io.check_output_path(out_p, overwrite=overwrite)
            check_not_checkpoint(out_p, checkpoint_path)
        if checkpointer is None:
            checkpointer = TargetCheckpointer(
                checkpoint_path, every_s, config=config, target=target, backend=backend,
                max_path_steps=max_path_steps, max_seconds=max_seconds, out=out_p, overwrite=overwrite,
                command_line=command_line, elapsed_before_s=0.0 if _resume is None else _resume.elapsed_s,
                resumed=0 if _resume is None else _resume.resumed + 1)
        journal = multilevel.Journal(source=f"checkpoint={str(checkpoint_path)!r}") if _resume is None else _resume.journal
        journal.saved = checkpointer.round_done
        with checkpointer.signals():
            ds = multilevel.target_run(config, target, backend=backend, max_path_steps=max_path_steps,
                                       max_seconds=max_seconds, note=note, journal=journal)
            checkpointer.save_journal(journal)  # a result that cannot be written costs no recomputation
        ds.attrs.update(checkpointer.attrs())
        _write_result(ds, out_p, overwrite, checkpointer)
        return ds


_KEEP = object()


def resume(
    path: str | os.PathLike,
    *,
    out: Any = _KEEP,
    overwrite: bool | None = None,
    every_s: Any = _KEEP,
    threads: Any = _KEEP,
    progress: Progress | None = None,
    break_lock: bool = False,
    max_path_steps: float | None = None,
    note: Any = None,
) -> xr.Dataset:
    """Continue the run saved in ``path``; write its result where the original command would have.

    ``every_s`` and ``threads`` default to those of the original run; ``out`` to the original
    run's output only as a name in the checkpoint's own directory (``out=None`` writes
    nothing); an existing output is replaced only with ``overwrite=True`` given here, never on
    the checkpoint's say. The checkpoint is locked (:func:`owned`) while this runs. The run's
    memory and work are checked first (:func:`check_work`, ``max_path_steps``). Checkpoints keep being written to ``path`` at the same
    interval; the file is removed once the result is written. A target run's checkpoint
    (:class:`TargetCheckpoint`) goes on as :func:`run_target_checkpointed`, its notes to
    ``note``, within the smaller of ``max_path_steps`` and the limit it was started with.
    """
    with owned(path, break_lock=break_lock):
        ckpt = read(path)
        if isinstance(ckpt, TargetCheckpoint):
            return _resume_target(path, ckpt, out=out, overwrite=overwrite, every_s=every_s,
                                  max_path_steps=max_path_steps, note=note)
        check_work(ckpt, max_path_steps)
        return _resume_owned(path, ckpt, out=out, overwrite=overwrite, every_s=every_s,
                             threads=threads, progress=progress, max_path_steps=max_path_steps)


def _check_backend(path: str | os.PathLike, backend: str) -> None:
    """Continue where the run ran, or say in one line why not."""
    if backend != "cpu":
        from stochpend.runs.simulate import resolve_backend

        try:
            resolve_backend(backend)
        except ValueError as exc:
            raise _refuse(Path(path), f"it ran on backend={backend!r}, which is not usable here ({exc})") from None


def _result_path(path: str | os.PathLike, recorded: Path | None, out: Any) -> Path | None:
    """Where a resumed run's result goes: ``out`` when given (None: nowhere), else the one the
    checkpoint records, trusted only as a name in its own directory (:func:`own_out`)."""
    if out is _KEEP:
        return None if recorded is None else own_out(path, recorded)
    return None if out is None else Path(out)


def _resume_target(path: str | os.PathLike, ckpt: TargetCheckpoint, *, out: Any, overwrite: bool | None,
                   every_s: Any, max_path_steps: float | None, note: Any) -> xr.Dataset:
    from stochpend.runs import resources

    _check_backend(path, ckpt.backend)
    # The limit the run was started with, or a smaller one given now: the file may lower it, never
    # raise it (a crafted limit must not buy unbounded work).
    limit = resources.work_limit(max_path_steps)
    if ckpt.max_path_steps is not None:
        limit = min(limit, ckpt.max_path_steps)
    return run_target_checkpointed(
        ckpt.config, ckpt.target, checkpoint_path=path, every_s=ckpt.every_s if every_s is _KEEP else every_s,
        out=_result_path(path, ckpt.out, out), overwrite=bool(overwrite), backend=ckpt.backend,
        max_path_steps=limit, max_seconds=ckpt.max_seconds, note=note, command_line=ckpt.command_line,
        _resume=ckpt)


def _resume_owned(path: str | os.PathLike, ckpt: Checkpoint, *, out: Any, overwrite: bool | None,
                  every_s: Any, threads: Any, progress: Progress | None,
                  max_path_steps: float | None) -> xr.Dataset:
    _check_backend(path, ckpt.state.backend)
    if threads is _KEEP:  # the machine that resumes may have fewer threads
        threads = None if ckpt.threads is None else min(ckpt.threads, numba.config.NUMBA_NUM_THREADS)
    # The trust boundary: the checkpoint's own `out` only as a name in its own directory, and
    # never an overwrite on its say (only the caller's `overwrite`).
    out_p = _result_path(path, ckpt.out, out)
    ow = bool(overwrite)
    return run_checkpointed(
        ckpt.config, checkpoint_path=path,
        every_s=ckpt.every_s if every_s is _KEEP else every_s,
        out=out_p, overwrite=ow,
        threads=threads,
        chunk_paths=ckpt.chunk_paths, progress=progress, command_line=ckpt.command_line,
        _resume=ckpt, max_path_steps=max_path_steps,
    )
