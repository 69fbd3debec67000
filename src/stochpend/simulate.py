"""The high-level API: ``simulate(...) -> xarray.Dataset``."""

from __future__ import annotations

import platform
import time as _time
from typing import Any

import numba
import numpy as np
import xarray as xr

from stochpend import __version__, physics, schemes
from stochpend import rng as _rng
from stochpend._backends import cpu
from stochpend.params import (
    DEFAULT_H_MAX,
    DEFAULT_HIST_BINS,
    DEFAULT_N_BATCHES,
    DEFAULT_STEP_C,
    SimulationConfig,
    hist_edges,
)
from stochpend.progress import NoProgress, Progress
from stochpend.stats import EnsembleSums

#: Paths advanced together (bounded memory: about 60 bytes a path).
DEFAULT_CHUNK_PATHS = 1 << 20
#: Path-steps per kernel call, so that progress is reported every fraction of a second.
_WORK_PER_CALL = 20_000_000


def simulate(
    noise: str = "ou",
    D: float = 1.0,
    tau: float | None = 1.0,
    omega: float = 1.0,
    paths: int = 10_000,
    t_max: float = 1000.0,
    times: Any = None,
    n_times: int = 40,
    seed: int = 0,
    *,
    theta0: float | str = "uniform",
    Omega0: float = 0.0,
    xi0: float | str = "stationary",
    h_max: float = DEFAULT_H_MAX,
    step_c: float = DEFAULT_STEP_C,
    hist_bins: int = DEFAULT_HIST_BINS,
    hist_E_max: Any = None,
    n_batches: int = DEFAULT_N_BATCHES,
    potential: str = "pendulum",
    power_n: int = 2,
    coupling: str = "force",
    backend: str = "cpu",
    threads: int | None = None,
    chunk_paths: int | None = None,
    progress: Progress | None = None,
) -> xr.Dataset:
    r"""Simulate an ensemble of stochastic pendulums and return its energy statistics.

    Integrates :math:`\dot\Omega = -(\omega^2 + \xi)\sin\theta`, :math:`\dot\theta = \Omega`
    (Eqs. `dynOmega`, `dyntheta`) for ``paths`` independent realizations and accumulates the
    statistics at the output times on the fly (memory O(paths), independent of the steps).

    Parameters
    ----------
    noise : {"ou", "white"}
        Ornstein-Uhlenbeck noise (Eq. `eqOU`, stationary variance D/(2 tau)) or white noise
        (Eq. `defbruitblanc`, <xi xi'> = D delta).
    D : float
        Noise amplitude, >= 0.
    tau : float
        OU correlation time, > 0 (ignored for white noise).
    omega : float
        Pendulum frequency, >= 0.
    paths : int
        Number of realizations.
    t_max : float
        Final time.
    times : array_like, optional
        Output times in [0, t_max], strictly increasing. Default: ``n_times`` log-spaced
        times from t_max/1000 to t_max.
    n_times : int
        Number of default output times.
    seed : int
        Seed in [0, 2**64); with it every number is fixed, whatever the threads and chunks.
    theta0 : float or "uniform"
        Initial angle; default uniform on [-pi, pi).
    Omega0 : float
        Initial angular velocity (default 0).
    xi0 : float or "stationary"
        Initial OU noise; default drawn from its stationary law N(0, D/(2 tau)).
    h_max, step_c : float
        Step control: h = min(h_max, step_c/|Omega|, step_c/sqrt(|omega^2 + xi|)), landing
        exactly on the output times; ``step_c = 0`` gives a fixed step h_max.
    hist_bins : int
        Number of energy-histogram bins (uniform in sqrt(E + omega^2)).
    hist_E_max : float or array_like, optional
        Upper histogram edge per time; default far in the tail of the expected law.
    n_batches : int
        Batches for the jackknife standard errors (capped at ``paths``).
    potential, power_n, coupling
        Model beyond the pendulum: "pendulum" (default), "harmonic", or "power" (U = x^2n/2n);
        noise multiplying the force ("force") or the position ("position").
    backend : {"cpu", "auto"}
        Where to run.
    threads : int, optional
        CPU threads (default: all Numba threads). Results do not depend on it.
    chunk_paths : int, optional
        Paths advanced together (rounded to whole batches). Results do not depend on it.
    progress : Progress, optional
        Receives the work done (see :mod:`stochpend.progress`).

    Returns
    -------
    xarray.Dataset
        Coordinate ``time``; variables ``mean_E``, ``mean_E2``, ``mean_E3``, ``mean_E4``,
        ``skewness``, ``flatness``, ``mean_Omega2``, ``mean_Omega4``, ``mean_sin2theta``, each
        with ``<name>_stderr``; ``E_hist`` (time, E_bin) with ``E_bin_edges``;
        ``nonfinite_paths`` and ``n_finite_paths``. Attributes hold every parameter, the seed,
        the scheme, versions, wall time and the number of path-steps.

    Raises
    ------
    ValueError
        A parameter outside its accepted range, with a one-line message naming it.
    """
    config = SimulationConfig.build(
        noise=noise, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max, times=times,
        n_times=n_times, seed=seed, theta0=theta0, Omega0=Omega0, xi0=xi0, h_max=h_max,
        step_c=step_c, hist_bins=hist_bins, hist_E_max=hist_E_max, n_batches=n_batches,
        potential=potential, power_n=power_n, coupling=coupling,
    )
    backend = resolve_backend(backend)
    if threads is not None and (isinstance(threads, bool) or not isinstance(threads, int) or threads < 1
                                or threads > numba.config.NUMBA_NUM_THREADS):
        raise ValueError(
            f"threads={threads!r} is not accepted: an integer in [1, {numba.config.NUMBA_NUM_THREADS}]"
        )
    if chunk_paths is not None and (isinstance(chunk_paths, bool) or not isinstance(chunk_paths, int)
                                    or chunk_paths < 1):
        raise ValueError(f"chunk_paths={chunk_paths!r} is not accepted: an integer >= 1")
    return run(config, backend=backend, threads=threads, chunk_paths=chunk_paths, progress=progress)


def resolve_backend(backend: str) -> str:
    """Map "auto" to an available backend; refuse unknown names."""
    if backend in ("cpu", "auto"):
        return "cpu"
    if backend == "cuda":
        raise ValueError("backend='cuda' is not accepted: the CUDA backend is not available in this build")
    raise ValueError(f"backend={backend!r} is not accepted: one of cpu, auto, cuda")


def run(
    config: SimulationConfig,
    *,
    backend: str = "cpu",
    threads: int | None = None,
    chunk_paths: int | None = None,
    progress: Progress | None = None,
) -> xr.Dataset:
    """Run a validated configuration and build the Dataset (see :func:`simulate`)."""
    progress = progress or NoProgress()
    previous_threads = numba.get_num_threads()
    if threads is not None:
        numba.set_num_threads(threads)
    started = _time.perf_counter()
    try:
        sums, path_steps = run_batches(
            config, 0, config.n_batches, chunk_paths=chunk_paths, progress=progress
        )
    finally:
        numba.set_num_threads(previous_threads)
    wall = _time.perf_counter() - started
    attrs = provenance(config, backend=backend, threads=threads or previous_threads,
                       wall_time_s=wall, path_steps=path_steps)
    return sums.to_dataset(np.asarray(config.times), hist_edges(config), attrs)


def run_batches(
    config: SimulationConfig,
    first_batch: int,
    stop_batch: int,
    *,
    chunk_paths: int | None = None,
    progress: Progress | None = None,
) -> tuple[EnsembleSums, int]:
    """Simulate batches ``first_batch .. stop_batch - 1`` and return their sums.

    This is the unit of work that Dask tasks and checkpointed runs are made of: the numbers
    depend only on the configuration and the batch indices.
    """
    progress = progress or NoProgress()
    times = np.asarray(config.times)
    edges = hist_edges(config)
    bs = config.batch_size
    n_times = times.size
    acc = EnsembleSums.empty(config.n_batches, n_times, config.hist_bins)
    chunk_batches = max(1, (chunk_paths or DEFAULT_CHUNK_PATHS) // bs)
    key0, key1 = _rng.seed_to_key(config.seed)
    pot = physics.POTENTIALS[config.potential]
    cpl = physics.COUPLINGS[config.coupling]
    omega2 = config.omega**2
    total_paths = min(stop_batch * bs, config.paths) - first_batch * bs
    progress.start(total_paths * config.t_max, "simulating")
    done_work = 0.0
    path_steps = 0
    for b0 in range(first_batch, stop_batch, chunk_batches):
        b1 = min(b0 + chunk_batches, stop_batch)
        p0 = b0 * bs
        p1 = min(b1 * bs, config.paths)
        n = p1 - p0
        x = np.empty(n)
        Omega = np.empty(n)
        xi = np.empty(n)
        t = np.empty(n)
        k = np.empty(n, dtype=np.uint64)
        status = np.empty(n, dtype=np.uint8)
        cpu.init_paths(
            x, Omega, xi, t, k, status, key0, key1, p0,
            0.0 if config.theta0 is None else config.theta0, config.theta0 is None,
            config.Omega0, 0.0 if config.xi0 is None else config.xi0, config.xi0 is None,
            config.D, config.tau_or_zero, config.noise_code,
        )
        sums = np.empty((b1 - b0, n_times, cpu.N_SUMS))
        hist = np.empty((b1 - b0, config.hist_bins + 2), dtype=np.int64)
        hist_total = np.zeros((n_times, config.hist_bins + 2), dtype=np.int64)
        max_steps = max(1000, _WORK_PER_CALL // max(n, 1))
        for j, t_target in enumerate(times):
            while True:
                steps, unfinished = cpu.advance_paths(
                    x, Omega, xi, t, k, status, float(t_target), max_steps, config.noise_code,
                    config.D, config.tau_or_zero, omega2, config.h_max, config.step_c, pot,
                    config.power_n, cpl, key0, key1, p0,
                )
                path_steps += steps
                chunk_done = float(np.sum(t))
                progress.update(done_work + chunk_done)
                if unfinished == 0:
                    break
            cpu.accumulate_batches(x, Omega, status, omega2, pot, config.power_n, cpl, bs,
                                   edges[j], sums[:, j, :], hist)
            hist_total[j] = hist.sum(axis=0)
        done_work += n * config.t_max
        acc.add_batches(b0, sums, hist_total)
    progress.finish()
    return acc, path_steps


def provenance(config: SimulationConfig, *, backend: str, threads: int, wall_time_s: float,
               path_steps: int) -> dict[str, Any]:
    """Attributes stored with every result: enough to reproduce it."""
    attrs: dict[str, Any] = {"title": "stochpend ensemble simulation"}
    attrs.update(config.to_attrs())
    attrs.update({f"scheme_{k}": v for k, v in schemes.SCHEME.items()})
    attrs.update(
        {
            "rng": "Philox4x32-10, key = seed, counter = (draw, global path index)",
            "backend": backend,
            "threads": threads,
            "wall_time_s": wall_time_s,
            "path_steps": path_steps,
            "path_steps_per_s": path_steps / wall_time_s if wall_time_s > 0 else float("nan"),
            "stochpend_version": __version__,
            "numba_version": numba.__version__,
            "numpy_version": np.__version__,
            "python_version": platform.python_version(),
            "machine": f"{platform.machine()} {platform.processor() or platform.system()}",
            "created": _time.strftime("%Y-%m-%dT%H:%M:%SZ", _time.gmtime()),
            "reference": "K. Mallick and P. Marcq, On the stochastic pendulum with Ornstein-Uhlenbeck noise (2004)",
        }
    )
    return {k: (int(v) if isinstance(v, bool) else v) for k, v in attrs.items()}
