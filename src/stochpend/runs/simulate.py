"""The high-level API: ``simulate(...) -> xarray.Dataset``."""

from __future__ import annotations

import warnings
from typing import Any

import xarray as xr

from stochpend.model.settings import (
    DEFAULT_H_MAX,
    DEFAULT_HIST_BINS,
    DEFAULT_N_BATCHES,
    DEFAULT_STEP_C,
    SimulationConfig,
)
from stochpend.runs import bias

# Where a run runs is decided in stochpend.runs.lifecycle; the names stay importable from here.
from stochpend.runs.lifecycle import RunOptions, execute
from stochpend.runs.lifecycle import check_precision as check_precision
from stochpend.runs.lifecycle import cuda_status as cuda_status
from stochpend.runs.lifecycle import resolve_backend as resolve_backend
from stochpend.text._docs import documented
from stochpend.text.progress import Progress
from stochpend.text.progress import resolve as resolve_progress


@documented  # help() shows the signature's defaults and the paper's equation numbers
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
    omega_noise: float | None = None,
    observables: Any = (),
    joint_bins: Any = None,
    joint_x_range: Any = None,
    joint_Omega_max: Any = None,
    additive_noise: str | None = None,
    backend: str = "cpu",
    threads: int | None = None,
    chunk_paths: int | None = None,
    progress: Progress | bool | None = None,
    precision: str = "float64",
    max_path_steps: float | None = None,
    bias_paths: int | None = None,
    accuracy: str = "fixed",
    rtol: float | None = None,
    target_error: float | None = None,
    target_confidence: float = 0.95,
    target_statistics: Any = None,
    target_times: Any = None,
    max_seconds: float | None = None,
    **noise_params: float,
) -> xr.Dataset:
    r"""Simulate an ensemble of stochastic pendulums and return its energy statistics.

    Integrates :math:`\dot\Omega = -(\omega^2 + \xi)\sin\theta`, :math:`\dot\theta = \Omega`
    (Eqs. `dynOmega`, `dyntheta`) for ``paths`` independent realizations and accumulates the
    statistics at the output times on the fly (memory O(paths), independent of the steps).
    Other oscillators: ``potential``/``coupling`` below.

    Parameters
    ----------
    noise : {"ou", "white", "dichotomous", "harmonic"}
        Ornstein-Uhlenbeck noise (Eq. `eqOU`, stationary variance D/(2 tau)), white noise
        (Eq. `defbruitblanc`, <xi xi'> = D delta), dichotomous (telegraph) noise +-sqrt(D/(2 tau))
        flipping at rate 1/(2 tau) (the OU correlation D/(2 tau) exp(-|t|/tau)), or harmonic
        noise xi'' + W^2 tau xi' + W^2 xi = W^2 sqrt(D) white (spectrum D W^4/((W^2 - nu^2)^2 +
        W^4 tau^2 nu^2), variance D/(2 tau)). Every noise has spectral density D at zero
        frequency (docs/models.md).
    D : float
        Noise amplitude, >= 0.
    tau : float
        Correlation time of the colored noises, > 0 (ignored for white noise).
    omega_noise : float, optional
        Harmonic noise only: its frequency W (default 2/tau, critical damping).
    observables : sequence of str, optional
        Names of registered user observables (:func:`stochpend.observables.register`): each
        adds ``mean_<name>`` with its standard error and bias estimate, on every backend.
    **noise_params : float
        The parameters a noise declares for itself (``stochpend list`` names them), e.g.
        ``simulate(noise="two-ou", tau1=0.5, weight=0.3)``, and those the oscillator (a
        model's ``parameters``) declares, e.g. ``simulate(potential="tilted-well", a=0.2)``;
        the pieces' defaults fill the rest.
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
    joint_bins : (int, int), optional
        Also histogram (x, Omega) jointly at every output time, on (nx, nOmega) uniform bins
        (each in [1, 500]); default: no joint histogram (and the run's kernels are exactly
        those without it).
    joint_x_range : (float, float), optional
        Its x range [lo, hi) for a non-periodic oscillator (a periodic one's angle is binned
        over [-pi, pi)); default +-joint_Omega_max/omega, the harmonic turning points.
    joint_Omega_max : float or array_like, optional
        Its Omega range [-joint_Omega_max, joint_Omega_max), one number or one per time;
        default sqrt(2 (hist_E_max - E_min)), every velocity the energy histogram covers.
    additive_noise : str, optional
        The additive noise xi_a's noise (the family's ``additive_D`` > 0: docs/family.md), any
        registered noise's name ("harmonic", "dichotomous", a user's). Its intensity is
        ``additive_D``, its correlation time ``additive_tau``, its W ``additive_omega_noise``,
        its own parameters ``additive_<name>``; its random numbers are its own (independent of
        xi). Default: white when ``additive_tau`` = 0, Ornstein-Uhlenbeck when > 0.
    potential, power_n, coupling
        Model beyond the pendulum: "pendulum" (default), "harmonic", or "power" (U = x^2n/2n);
        noise multiplying the force ("force") or the position ("position").
    backend : {"cpu", "cuda", "auto"}
        Where to run: the CPU (Numba, all cores), an NVIDIA GPU (numba-cuda, one thread per
        path; the same random streams), or the GPU when one is usable.
    precision : {"float64", "float32"}
        Arithmetic of the state and the step; float32 is available on the CUDA backend
        (statistics are always accumulated in float64; see docs/gpu.md for its bias).
    threads : int, optional
        CPU threads (default: all Numba threads). Results do not depend on it.
    chunk_paths : int, optional
        Paths advanced together (rounded to whole batches). Results do not depend on it.
    progress : bool or Progress, optional
        ``True``: a progress bar (Rich's, also in a Jupyter notebook); or an object receiving
        the work done (see :mod:`stochpend.text.progress`). Default: nothing.
    bias_paths : int, optional
        Coupled coarse/fine pairs that estimate every statistic's discretisation bias
        (:mod:`stochpend.bias`); default :func:`stochpend.bias.default_bias_paths` (paths/48,
        at least 64, never more than paths); 0: no estimate.
    max_path_steps : float, optional
        Refuse, before any work, a run needing more than this many path-steps, paths x t_max /
        h_max (a lower bound of the work); default
        :data:`stochpend.runs.resources.DEFAULT_MAX_PATH_STEPS` (1e13); ``math.inf``: no limit.
    accuracy : {"fixed", "auto"}
        "fixed": the step control (h_max, step_c) as given. "auto": divide both by 2**L, L the
        smallest level at which the estimated |bias| plus its error is at most half the
        standard error (or ``rtol`` |value|) for every statistic at every output time, judged
        from a pilot of coupled pairs at the given step (:func:`stochpend.bias.choose_level`).
    rtol : float, optional
        With ``accuracy="auto"`` (implied): the accepted bias as a fraction of each value,
        instead of half a standard error.
    target_error : float, optional
        Ask for an accuracy instead of paths and a step: the relative total error (statistical
        half-width plus a bound on the discretisation bias) of each of ``target_statistics`` at
        each of ``target_times``, at confidence ``target_confidence``, met by
        multilevel Monte Carlo on coupled levels with fixed steps h_max/2**l
        (:mod:`stochpend.runs.multilevel`, docs/numerics.md). ``paths``, ``step_c``, ``bias_paths``
        are then not used; the result is the multilevel Dataset (below).
    target_confidence : float
        Confidence of the total error, in (0.5, 1); default 0.95.
    target_statistics : sequence of str, optional
        Statistics to control (default ``("mean_E", "mean_E2")``): any ``mean_*`` of the table or
        of a user observable, and the paper's ``"skewness"`` and ``"flatness"`` (functions of
        means, errors by the jackknife).
    target_times : array_like, optional
        Output times to control, among the run's ``times`` (default all of them).
    max_seconds : float, optional
        With ``target_error``: the wall-time budget (s). A target whose pilot or plan would take
        longer, at the rate measured on this machine (then the run's own), is refused before
        that work, with what it would take; ``max_path_steps`` bounds the work as ever.

    Returns
    -------
    xarray.Dataset
        Coordinate ``time``; variables ``mean_E``, ``mean_E2``, ``mean_E3``, ``mean_E4``,
        ``skewness``, ``flatness``, ``mean_Omega2``, ``mean_Omega4``, ``mean_sin2theta``, each
        with ``<name>_stderr``; ``E_hist`` (time, E_bin) with ``E_bin_edges``; with
        ``joint_bins``, ``joint_hist`` (time, x_bin, Omega_bin), ``joint_hist_outside``,
        ``joint_density`` and ``joint_density_stderr``, ``x_bin_edges`` and ``Omega_bin_edges``;
        ``nonfinite_paths`` and ``n_finite_paths``; ``<name>_bias`` and ``<name>_bias_stderr``
        (the estimated discretisation bias, value minus zero-step limit) unless
        ``bias_paths=0``. Attributes hold every parameter, the seed,
        the scheme, versions, wall time and the number of path-steps.
        With ``target_error``: coordinates ``time`` (the target times) and ``level``; per
        statistic ``<name>``, ``<name>_stat_error``, ``<name>_bias_bound``,
        ``<name>_total_error``, ``<name>_relative_total_error``, ``<name>_certified``,
        ``<name>_cost_to_certify`` (time), the per-level ``<name>_level_mean``,
        ``<name>_level_variance``, ``<name>_level_decorrelation``, ``<name>_level_kurtosis``
        (of the pairs' differences, Giles' check), ``<name>_consistency`` (level, time), the
        rates ``<name>_alpha``, ``<name>_beta``; ``n_samples``, ``cost_per_sample``, ``h`` (level);
        attributes ``target_*`` and the path-steps spent.

    Raises
    ------
    ValueError
        A parameter outside its accepted range, with a one-line message naming it.
    """
    config = SimulationConfig.build(
        noise=noise, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max, times=times,
        n_times=n_times, seed=seed, theta0=theta0, Omega0=Omega0, xi0=xi0, h_max=h_max,
        step_c=step_c, hist_bins=hist_bins, hist_E_max=hist_E_max, n_batches=n_batches,
        potential=potential, power_n=power_n, coupling=coupling, omega_noise=omega_noise,
        observables=observables, noise_params=noise_params, joint_bins=joint_bins,
        joint_x_range=joint_x_range, joint_Omega_max=joint_Omega_max, additive_noise=additive_noise,
    )
    if target_error is not None:
        return _target(config, target_error, target_confidence, target_statistics, target_times,
                       backend=backend, precision=precision, accuracy=accuracy, rtol=rtol,
                       max_path_steps=max_path_steps, max_seconds=max_seconds)
    if max_seconds is not None:
        raise ValueError(f"max_seconds={max_seconds!r} is not accepted without target_error: the "
                         "wall-time budget is a target run's (bound other runs' work with max_path_steps)")
    # Refused here, before any work (run validates again what it is handed: a few checks).
    settings = RunOptions.build(config, backend=backend, precision=precision, threads=threads,
                         chunk_paths=chunk_paths, bias_paths=bias_paths, accuracy=accuracy, rtol=rtol,
                         max_path_steps=max_path_steps)
    ds = run(config, backend=settings.backend, threads=threads, chunk_paths=chunk_paths,
             progress=resolve_progress(progress), precision=precision, bias_paths=settings.bias_paths,
             accuracy=settings.accuracy, rtol=settings.rtol, max_path_steps=max_path_steps)
    warn_about(ds)
    return ds


def _target(config: SimulationConfig, target_error: Any, target_confidence: Any, target_statistics: Any,
            target_times: Any, *, backend: str, precision: str, accuracy: Any, rtol: Any,
            max_path_steps: Any, max_seconds: Any) -> xr.Dataset:
    """``simulate(target_error=...)``: validated before any work, then
    :func:`stochpend.runs.multilevel.target_run`."""
    from stochpend.runs import multilevel
    from stochpend.text._warnings import StochpendWarning

    target = multilevel.check_run(config, target_error, target_confidence, target_statistics, target_times,
                                  accuracy=accuracy, rtol=rtol, precision=precision,
                                  max_path_steps=max_path_steps, max_seconds=max_seconds)
    ds = multilevel.target_run(config, target, backend=resolve_backend(backend), max_path_steps=max_path_steps,
                               max_seconds=max_seconds)
    missed = int(ds.attrs["target_entries"]) - int(ds.attrs["target_certified"])
    if missed:
        warnings.warn(f"{missed} of {ds.attrs['target_entries']} (statistic, time) entries are not "
                      "certified to the target (their <name>_cost_to_certify says what it would take)",
                      StochpendWarning, stacklevel=3)
    return ds


def warn_about(ds: xr.Dataset, stacklevel: int = 3) -> None:
    """Raise what the command line prints about a result as :class:`stochpend.StochpendWarning`:
    each significant discretisation bias (:func:`stochpend.bias.warnings_for`) and the paths
    that went non-finite."""
    from stochpend.text._notation import ve
    from stochpend.text._warnings import StochpendWarning

    for line in bias.warnings_for(ds, ve):
        warnings.warn(line, StochpendWarning, stacklevel=stacklevel)
    lost = int(ds["nonfinite_paths"].values[-1]) if "nonfinite_paths" in ds else 0
    if lost:
        warnings.warn(f"{lost} paths went non-finite (or ran away) and are excluded from every "
                      "statistic", StochpendWarning, stacklevel=stacklevel)


def run(
    config: SimulationConfig,
    *,
    backend: str = "cpu",
    threads: int | None = None,
    chunk_paths: int | None = None,
    progress: Progress | None = None,
    precision: str = "float64",
    bias_paths: int | None = None,
    accuracy: str = "fixed",
    rtol: float | None = None,
    max_path_steps: float | None = None,
) -> xr.Dataset:
    """Run a configuration and build the Dataset (see :func:`simulate`): the settings are
    validated (:meth:`stochpend.runs.lifecycle.RunOptions.build`) and run by :func:`stochpend.runs.lifecycle.execute`.

    ``bias_paths``: pairs for the bias estimate (0: none; None: the default,
    :func:`stochpend.bias.default_bias_paths`).
    """
    settings = RunOptions.build(config, backend=backend, precision=precision, threads=threads,
                         chunk_paths=chunk_paths, bias_paths=bias_paths, accuracy=accuracy, rtol=rtol,
                         max_path_steps=max_path_steps)
    return execute(settings, progress=progress)[0]
