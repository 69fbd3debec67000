"""Estimates from what this machine measured: compile times and rates, kept with the kernel cache.

Every estimate stochpend prints (the compile notice, ``estimate:`` of simulate, reduced, bfpe and
sweep, ``cost:`` of reproduce) divides work by a rate and adds compile seconds. Fixed figures
were off by 4 to 14 times on a busy 2-core machine (issue 36: "first use: ~6 s" compiled in 82
s), for two reasons this module removes:

* the machine: after each run, the measured compile time (against the built-in figure for the
  kernels it compiled) and the measured rate (lower-bound work per wall second, so that the
  estimate's ``work / rate`` is the wall time itself) are stored, per host, in a small JSON file
  beside Numba's kernel cache (:func:`path`; written atomically, a few recent samples per kind);
  an estimate uses the median of the samples, else the built-in figure;
* the load: each sample is stored as it would be on an idle machine, dividing out
  :func:`slowdown` (other processes' share of the cores, from the 1-minute load average at the
  start), and an estimate multiplies the slowdown of now back in.

Nothing here imports Numba; a file that cannot be read or written is ignored (no calibration:
the built-in figures).
"""

from __future__ import annotations

import json
import math
import os
import statistics
import tempfile
from pathlib import Path
from typing import Any

__all__ = ["FILE_NAME", "compile_scale", "path", "rate", "read", "record_compile", "record_rate", "slowdown"]

FILE_NAME = "stochpend-calibration.json"
#: Samples kept per kind (the most recent): the median of a few runs follows a machine that changes.
KEEP = 7
#: Compiles shorter than this (seconds) are noise and are not stored.
MIN_SECONDS = 0.5
#: Runs shorter than this (seconds) are not stored as rates: their fixed costs (threads, the bias
#: estimate's set-up) would make a long run look slower than it is; only runs estimated beyond
#: resources.LONG_RUN_S print an estimate.
MIN_RATE_SECONDS = 2.0
_FORMAT = 1


def path() -> Path:
    """The calibration file: in ``NUMBA_CACHE_DIR`` when set (Numba caches every kernel there),
    else in the package's ``__pycache__`` (Numba's default cache sits beside the sources)."""
    cache = os.environ.get("NUMBA_CACHE_DIR", "").strip()
    if cache:
        return Path(cache) / FILE_NAME
    return Path(__file__).resolve().parents[1] / "__pycache__" / FILE_NAME


def _host() -> str:
    import platform

    return platform.node() or "unknown"


def cores() -> int:
    """CPUs this process may use."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def current_load() -> float:
    """The 1-minute load average (0 where unknown)."""
    try:
        return float(os.getloadavg()[0])
    except (AttributeError, OSError):  # pragma: no cover - no getloadavg
        return 0.0


def slowdown(threads: int, load: float | None = None, n_cores: int | None = None) -> float:
    """How much longer ``threads`` busy threads take than on an idle machine, with ``load``
    other runnable threads (the load average; default: now) on ``n_cores`` cores (default:
    this process's): ``(load + threads) / cores`` when the cores are oversubscribed, else 1."""
    load = current_load() if load is None else load
    n_cores = cores() if n_cores is None else n_cores
    if not (math.isfinite(load) and load > 0):
        load = 0.0
    return max(1.0, (load + max(1, threads)) / max(1, n_cores))


def read(file: Path | None = None) -> dict[str, Any]:
    """This host's samples: ``{"compile": [...], "rate": {kind: [...]}}`` (empty where none)."""
    file = path() if file is None else file
    try:
        data = json.loads(file.read_text())
        host = data["hosts"][_host()] if data.get("format") == _FORMAT else {}
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return {}
    return host if isinstance(host, dict) else {}


def _update(change: Any, file: Path | None = None) -> None:
    """Read the file, apply ``change(host_dict)``, write it back atomically (a temporary file in
    the same directory, then ``os.replace``: a reader never sees half a file). Concurrent
    writers may lose one another's sample, never corrupt the file; any OSError is ignored."""
    file = path() if file is None else file
    try:
        data = json.loads(file.read_text())
        if not isinstance(data, dict) or data.get("format") != _FORMAT or not isinstance(data.get("hosts"), dict):
            raise ValueError
    except (OSError, ValueError):
        data = {"format": _FORMAT, "hosts": {}}
    host = data["hosts"].get(_host())
    if not isinstance(host, dict):
        host = data["hosts"][_host()] = {}
    change(host)
    tmp = None
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{FILE_NAME}.", suffix=".tmp", dir=file.parent)
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=1, sort_keys=True)
        os.replace(tmp, file)
        tmp = None
    except OSError:
        pass  # a read-only install: estimates keep the built-in figures
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass


def _push(samples: Any, value: float) -> list[float]:
    good = [float(v) for v in samples if isinstance(v, int | float) and math.isfinite(v) and v > 0] \
        if isinstance(samples, list) else []
    return [*good, value][-KEEP:]


def _median(samples: Any) -> float | None:
    good = [float(v) for v in samples if isinstance(v, int | float) and math.isfinite(v) and v > 0] \
        if isinstance(samples, list) else []
    return statistics.median(good) if good else None


def record_compile(measured_s: float, builtin_s: float, *, load: float, n_cores: int | None = None,
                   file: Path | None = None) -> None:
    """Store one compile: ``measured_s`` seconds for kernels the built-in figures put at
    ``builtin_s`` (idle machine), while the 1-minute load was ``load``. Compiling runs on one
    thread."""
    if not (measured_s >= MIN_SECONDS and builtin_s > 0 and math.isfinite(measured_s)):
        return
    scale = measured_s / (builtin_s * slowdown(1, load, n_cores))
    _update(lambda host: host.__setitem__("compile", _push(host.get("compile"), scale)), file)


def compile_scale(file: Path | None = None) -> float:
    """This machine's compile time over the built-in figures, on an idle machine (1.0 unmeasured)."""
    return _median(read(file).get("compile")) or 1.0


def record_rate(kind: str, work: float, wall_s: float, threads: int, *, load: float,
                n_cores: int | None = None, file: Path | None = None) -> None:
    """Store one run of ``kind`` ("cpu", "reduced", "bfpe"): ``work`` units (the estimate's own
    count: the lower-bound path-steps, cell-steps) in ``wall_s`` seconds on ``threads`` threads,
    with the 1-minute load ``load`` at its start; stored per thread, as on an idle machine."""
    if not (wall_s >= MIN_RATE_SECONDS and work > 0 and math.isfinite(wall_s) and math.isfinite(work)):
        return
    per_thread = work / wall_s * slowdown(threads, load, n_cores) / max(1, threads)

    def change(host: dict) -> None:
        rates = host.get("rate")
        if not isinstance(rates, dict):
            rates = {}
        rates[kind] = _push(rates.get(kind), per_thread)
        host["rate"] = rates

    _update(change, file)


def rate(kind: str, builtin_per_thread: float, threads: int, *, load: float | None = None,
         n_cores: int | None = None, file: Path | None = None) -> tuple[float, bool]:
    """The expected rate (work units per wall second) of ``kind`` on ``threads`` threads now,
    and whether it was measured here (else the built-in ``builtin_per_thread``)."""
    rates = read(file).get("rate")
    measured = _median(rates.get(kind)) if isinstance(rates, dict) else None
    per_thread = measured if measured is not None else builtin_per_thread
    return per_thread * max(1, threads) / slowdown(threads, load, n_cores), measured is not None
