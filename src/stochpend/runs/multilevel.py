"""A total-error target met by multilevel Monte Carlo on coupled levels (issue 35, items 1-3).

``simulate(..., target_error=eps)`` asks for a statistic P (a mean: ``mean_E``, ``mean_E2``, any
``mean_<name>`` of a state observable, of a time average or of a running sum (each coupled member
then carries its own accumulators: :func:`tracked_statistics`), not of a first passage; or the
paper's skewness S or flatness F, functions of means, see below) at the
output times with a relative *total* error below eps, statistical and
discretisation together, at a stated confidence (default 95 %). It is met by the multilevel
estimator of Giles (2008) on the step ladder h_l = h_max / 2**l, l = 0 .. L (fixed steps:
step_c = 0, see below):

    E[P_{h_L}] = E[P_{h_0}] + sum_{l=1}^{L} E[Y_l],     Y_l = P_{h_l} - P_{h_{l-1}}     (telescope)

Level 0 is an ordinary ensemble at h_0 (the run's own kernel, :func:`stochpend.engine.runner.run_batches`);
level l >= 1 is an ensemble of coupled pairs (:func:`stochpend.engine.integrator.Integrator.advance_pair`
through :mod:`stochpend.bias`'s pair drivers on ``refined(config, l - 1)``): a coarse member at
h_{l-1} and a fine member taking each coarse step as two half steps, driven by one noise
realization, so that V_l = Var Y_l falls with h while the levels stay coupled. Per level and
output time: the mean m_l and the per-sample variance V_l of the difference, the cost C_l per
sample (path-steps measured, fine half steps counted as steps); the samples per level that meet
a statistical half-width s at least cost (Lagrange, Giles' Eq. (12)):

    N_l = ceil((z/s)**2 sqrt(V_l/C_l) sum_k sqrt(V_k C_k))                             (plan)

the largest over the statistics and times asked for (each constraint is then met; not the joint
optimum). The discretisation bias of P_{h_L} is the tail of the telescope; with the weak
expansion E[Y_l] ~ K h_l**alpha,

    |E P_{h_L} - P_0| <= (|m_L| + z_b se(m_L)) / (2**alpha - 1)                             (bias)

(or the same from level L-1 scaled by 2**-alpha, the smaller of the two, each at half the bias's
error probability), alpha the fitted rate over the levels whose mean is resolved (> 3 se), at
most 2 (the scheme's weak order; a faster fitted decay is pre-asymptotic), 2 where the fit cannot
tell. The statistical half-width is Student's t at the Welch-Satterthwaite degrees of freedom
of the levels' batch variances. The error probability 1 - confidence is split in halves between
the statistical interval and the bias bound (Bonferroni), so total = half-width + bias bound holds
at the stated confidence for each (statistic, time); it is not family-wise over them.

The loop (:func:`target_run`): a pilot of PILOT_SAMPLES on levels 0, 1, 2; the pair levels topped
up to the plan for half the target (the whole plan refused first if over ``max_path_steps``); a
level added while one more (or two, extrapolated at the fitted rates) makes the least-cost plan
cheaper; rounds of that plan while it asks for more. The least-cost plan (:func:`_least_cost`)
splits the target between the bias bound and the statistical half-width at the share of
:data:`BIAS_SHARES` that costs least: the finest level's samples for its bound at theta eps |P|,
Giles' samples for (1 - theta) eps |P|, level 0 taking the variance the pair levels leave. A
fixed half for the bias (Giles' own choice) costs level 0, the dearest in variance, up to four
times the samples: on the OU pendulum at t = 1 and eps = 3e-3 the half-and-half loop spent
5.0e8 path-steps, this one 2.7e8 (same seed, both certified). Samples are counted per output
time, and a round runs only as far as the latest time that needs it (:func:`staircase`): a
relative target at an early time, where <E> is small, does not send its many paths on to t_max.

Honest at late times: where the finest level's pairs have decorrelated (sqrt(1 - r) > 1/2,
:data:`stochpend.bias.DECORRELATED`: V_l no longer falls with h) the time is left out of the plan
and reported *not certified*, with the cost that certifying it by this estimator would take
(``<name>_cost_to_certify``), unless independent ensembles at two steps certify it within
what the budget leaves (:func:`_certify_by_independent_runs`, the time's ``<name>_route``). A
time is certified only when its total error is at most eps |estimate|, no path went non-finite
and the bias bound is finite.

Budget: ``max_path_steps`` and, when given, the wall time ``max_seconds`` (:class:`Budget`: the
seconds become path-steps at the rate measured here, then at the run's own). The pilot and every
round's plan are checked against it first: a target the budget cannot buy is refused, saying
what it would take, before the work it could not finish. Without a wall-time budget, a
statistic that is 0 within its error once level 0 has had a round beyond its pilot is refused
(:func:`_refuse_zero`): a relative error of it has no plan, and the rounds would grow without end.

Nonlinear statistics. S = <E^3>/<E^2>^(3/2) and F = <E^4>/<E^2>^2 are g(means): level 0's
value is g of its paths' means, level l's difference Y_l = g(fine means) - g(coarse means) of
its coupled samples, and every variance is the delete-one-batch jackknife's of those values
(:func:`statistics_of`), so the plan, the rates and the bias bound are the means' machinery
unchanged. g of a sample mean is biased by O(Var/N), a factor 1/sqrt(N) below its standard
error (N >= 256 samples a level): not in the bound.

Random streams: level l's samples of round k draw from the seed
``SeedSequence(seed, spawn_key=(SPAWN, l, k))`` (NumPy's, a fixed function), never the run's own
seed: every level and round has its own Philox key, so they are independent of each other and of
an ordinary run with the same seed, and the result is a fixed function of (seed, configuration,
target) whatever the threads or chunks.

Fixed steps. The coupled pair's fine member takes the coarse member's steps halved; an adaptive
step control at half (h_max, c) chooses other steps, so level l's fine member and level l+1's
coarse member would differ in law (by O(h**3)) and the telescope would not close. With step_c = 0
every member is the fixed-step scheme at its h_l and the telescope is exact (up to the landing
step before each output time, which both take but split differently: O(h**3) each); the
consistency check (Giles: level l-1's fine mean against level l's coarse mean, in sigma) reports
it. The kurtosis of each pair level's differences (Giles' check of the variances the plan rests
on, ``<name>_level_kurtosis``, above :data:`KURTOSIS_WARN` named by ``show``) comes from the raw
power sums of the members' differences, summed on the host beside the pairs' statistics
(``bias.pair_sums(differences=...)``), for the statistics that are means of the table or of
a user's observable of the state; for S and F, no per-sample means, of their difference
linearised at the pair's means, w . d (w the gradient of S or F in <E^2>, <E^3>, <E^4>, d the
pair's differences of E^2, E^3, E^4), from the summed products of d (its variance agrees with
the jackknife's V_l: tests/unit/test_multilevel.py); each round's at its own pairs' means. A
running sum's variance and diffusion likewise, in the sum and its square.
What this version does not do: the Richardson-extrapolated
(multilevel Richardson-Romberg) estimate: the least-cost plan gives the bias bound 1-3 % of the
total error on the OU pendulum at t = 1 and 10, so it could save level 0 at most ~6 % of its
samples (benchmarks/RESULTS_ACCURACY.md). A sweep (:func:`stochpend.sweep.sweep`) runs
every set as this run; a checkpointed run saves its :class:`Journal` at round boundaries and
replays it when resumed (:func:`stochpend.runs.checkpoint.run_target_checkpointed`).
"""

from __future__ import annotations

import math
import textwrap
import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from functools import partial
from typing import TYPE_CHECKING, Any

import numpy as np

from stochpend.model import observables, power_sums
from stochpend.runs import bias

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

    from stochpend.model.settings import SimulationConfig
    from stochpend.text.progress import Progress

__all__ = ["DEFAULT_STATISTICS", "check_target", "level_seed", "plan_samples", "target_run"]

#: What ``target_error`` controls when no ``target_statistics`` are named.
DEFAULT_STATISTICS = ("mean_E", "mean_E2")
#: The paper's nonlinear statistics a target may name beside the means: functions of means
#: (:func:`statistics_of`), S = <E^3>/<E^2>^(3/2) and F = <E^4>/<E^2>^2.
NONLINEAR = ("skewness", "flatness")
#: Batches of each level's round (the jackknife's units; its variance has batches - 1 degrees of
#: freedom, the Student t of the half-width accounts for them).
LEVEL_BATCHES = 256
#: Samples of each level's pilot round.
PILOT_SAMPLES = 256
#: Levels piloted at the start (0, 1, 2: two differences, enough for a first rate).
PILOT_LEVELS = 3
#: The finest level tried: h_max / 2**MAX_LEVEL.
MAX_LEVEL = 10
#: Rounds of planning and topping up.
MAX_ROUNDS = 32
#: Rounds of the independent runs of one late time (issue 35, item 3).
ROUTE_ROUNDS = 4
#: Part of the spawn key of every level's seed (issue 35): no other SeedSequence in stochpend uses it.
SPAWN = 35
#: A level's mean counts as resolved for the rate fit beyond this many standard errors.
RESOLVED_SE = 3.0
#: Seconds of computing (compiling left out) after which a target run's own rate, not the
#: machine's calibrated one, converts its wall-time budget into path-steps: a pilot of ~1e4
#: path-steps lasts a fraction of a second, most of it loading kernels and starting calls, and
#: its rate (1.8e4 path-steps/s measured, against ~2e7 in a run) would refuse targets that fit.
RATE_MEASURED_AFTER_S = 2.0
#: Giles' kurtosis check: a level's differences with a kurtosis above this have a variance
#: estimate that rests on a few rare pairs (reported by ``show``; the plan is made from it).
KURTOSIS_WARN = 100.0
#: Giles' consistency check: |fine mean of level l-1 - coarse mean of level l| in sigma.
CONSISTENCY_SIGMA = 3.0


# -- validation -----------------------------------------------------------------------------------
@dataclass(frozen=True)
class Target:
    """A validated target: relative total error ``error`` at ``confidence`` for ``statistics``
    at the output times ``times`` (indices ``index`` into the run's)."""

    error: float
    confidence: float
    statistics: tuple[str, ...]
    times: np.ndarray
    index: np.ndarray


def _number(name: str, value: Any, accepted: str, ok: Any) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError, OverflowError):
        v = math.nan
    if isinstance(value, bool) or not ok(v):
        raise ValueError(f"{name}={value!r} is not accepted: {accepted}")
    return v


def check_target(config: SimulationConfig, target_error: Any, target_confidence: Any = 0.95,
                 target_statistics: Any = None, target_times: Any = None) -> Target:
    """Validate a target against ``config`` (one-line ``ValueError`` naming the parameter)."""
    eps = _number("target_error", target_error, "a number in (0, 1), the relative total error "
                  "(statistical and discretisation) of each statistic", lambda v: 0.0 < v < 1.0)
    conf = _number("target_confidence", target_confidence, "a number in (0.5, 1), e.g. 0.95",
                   lambda v: 0.5 < v < 1.0)
    known = [s.name for s in observables.STATISTICS if s.name.startswith("mean_")] + list(NONLINEAR)
    # A time average's or a running sum's mean is carried by the coupled levels' members, each
    # tracking its own steps (tracked_statistics). A first passage is not: its step error is
    # O(sqrt h) (a crossing within a step goes unseen) and its mean is conditional on having
    # passed, so no weak expansion in h**alpha bounds its bias. With a noise that has events
    # the members do not carry them (cpu.LevelEngine).
    accs = observables.accumulators(observables.objects(config.observables))
    events = _has_events(config)
    not_carried = {s.name: (a.name, "a first passage, whose step error is O(sqrt h)"
                            if isinstance(a, observables.FirstPassage) else
                            "a per-path accumulator, which the coupled levels do not carry with a "
                            f"noise that has events ({config.noise})")
                   for a in accs if isinstance(a, observables.FirstPassage) or events for s in a.statistics(0)}
    known += [f"mean_{u}" for u in config.observables if f"mean_{u}" not in not_carried]
    # A running sum's variance, and with its rates its mean and variance per time (the
    # displacement's mean velocity and effective diffusion): functions of its two columns'
    # means, as the skewness and flatness are of the energy's.
    known += [s.name for a in accs if isinstance(a, observables.RunningSum)
              for s in a.statistics(0) if not s.name.startswith("mean_") and s.name not in not_carried]
    if target_statistics is None:
        names: tuple[str, ...] = DEFAULT_STATISTICS
    else:
        given = ([s for s in target_statistics.split(",") if s.strip()] if isinstance(target_statistics, str)
                 else target_statistics)
        try:
            names = tuple(str(s).strip() for s in given)
        except TypeError:
            names = ()
        for s in names:
            if s in not_carried:
                raise ValueError(f"target_statistics={target_statistics!r} is not accepted: {s} is a statistic of "
                                 f"{not_carried[s][0]!r}, {not_carried[s][1]}, so no bias bound of it can be "
                                 "made; a target takes the means of the table, of observables of the state, of "
                                 f"time averages and running sums, skewness and flatness ({', '.join(known)})")
        bad = [s for s in names if s not in known]
        if not names or bad or len(set(names)) != len(names):
            raise ValueError(f"target_statistics={target_statistics!r} is not accepted: distinct names "
                             f"among {', '.join(known)}")
    run_times = np.asarray(config.times, dtype=float)
    if target_times is None:
        index = np.arange(run_times.size)
    else:
        try:
            want = np.atleast_1d(np.asarray(target_times, dtype=float))
        except (TypeError, ValueError):
            want = np.array([math.nan])
        index_list = []
        for t in want:
            hit = np.flatnonzero(np.isclose(run_times, t, rtol=1e-12, atol=0.0))
            if want.ndim != 1 or hit.size != 1:
                raise ValueError(f"target_times={target_times!r} is not accepted: times among the "
                                 f"run's output times ({run_times.size} from {run_times[0]:g} to "
                                 f"{run_times[-1]:g}; set them with times=)")
            index_list.append(int(hit[0]))
        index = np.array(sorted(set(index_list)), dtype=np.int64)
        if index.size != want.size:
            raise ValueError(f"target_times={target_times!r} is not accepted: distinct times among "
                             "the run's output times")
    # A time average has no value until its window has begun, a rate or a diffusion none at t = 0.
    starts = {f"mean_{a.name}": (a.window[0], f"a time average from t = {a.window[0]:g}") for a in accs
              if isinstance(a, observables.TimeAverage)}
    starts.update({f"{kind}_{a.name}": (0.0, f"a running sum's {kind} per time") for a in accs
                   if isinstance(a, observables.RunningSum) for kind in ("rate", "diffusion")})
    for name in names:
        if name in starts and run_times[index[0]] <= starts[name][0]:
            later = run_times[run_times > starts[name][0]]
            raise ValueError(f"target_times={target_times!r} is not accepted: {name} is {starts[name][1]}, with no "
                             f"value at t = {run_times[index[0]]:g}; "
                             + (f"give target_times after it (from {later[0]:g})" if later.size else
                                "no output time is after it"))
    return Target(eps, conf, names, run_times[index], index)


def _has_events(config: SimulationConfig) -> bool:
    """Whether the run's noise (or its additive channel's) has events (the dichotomous noise)."""
    from stochpend.engine.integrator import KernelSpec

    spec = KernelSpec.of(config)
    return spec.noise.has_events or (spec.additive is not None and spec.additive.has_events)


def tracked_statistics(config: SimulationConfig, names: Sequence[str]) -> bool:
    """Whether the target ``names`` include a statistic of a per-path accumulator (a time
    average's mean, a running sum's mean, variance, rate or diffusion): then every level's
    members carry the run's accumulators, each its own (``runner.run_batches(tracked=True)``:
    on the CPU a pair in SIMD lanes where the KernelSpec has them, else one set of members at a
    time; one a thread on CUDA)."""
    accs = {s.name for a in observables.accumulators(observables.objects(config.observables))
            for s in a.statistics(0)}
    return any(name in accs for name in names)


# -- streams ----------------------------------------------------------------------------------------
def check_max_seconds(max_seconds: Any) -> float | None:
    """A target run's wall-time budget ``max_seconds`` (None: none), validated."""
    if max_seconds is None:
        return None
    return _number("max_seconds", max_seconds, "a number of seconds > 0 (the target run's wall-time "
                   "budget; None or inf: none)", lambda v: v > 0.0)


def check_run(config: SimulationConfig, target_error: Any, target_confidence: Any, target_statistics: Any,
              target_times: Any, *, accuracy: Any, rtol: Any, precision: Any, max_path_steps: Any,
              max_seconds: Any = None, cli: bool = False) -> Target:
    """Everything a target run is refused for, before any work (one line each): the target
    (:func:`check_target`), an accuracy setting beside it, a precision other than float64, a bad
    work limit or wall-time budget. ``cli``: name the options as the command line spells them."""
    from stochpend.runs import resources

    check_max_seconds(max_seconds)
    target = check_target(config, target_error, target_confidence, target_statistics, target_times)
    if accuracy != "fixed" or rtol is not None:
        leave = "leave --accuracy fixed and --rtol unset" if cli else "leave accuracy='fixed' and rtol unset"
        raise ValueError(f"accuracy={accuracy!r} is not accepted with {'--target-error' if cli else 'target_error'}: "
                         f"the target chooses the steps itself; {leave}")
    if precision != "float64":
        raise ValueError(f"precision={precision!r} is not accepted with "
                         f"{'--target-error' if cli else 'target_error'}: float64")
    resources.work_limit(max_path_steps)
    return target


def level_seed(seed: int, level: int, round_: int) -> int:
    """The seed of level ``level``'s samples of round ``round_``: a fixed function of the run's
    seed, distinct (with probability 1 - 2**-64 per pair) from the run's seed and from every other
    level's and round's, so that their Philox streams are independent."""
    words = np.random.SeedSequence(int(seed), spawn_key=(SPAWN, int(level), int(round_))).generate_state(
        2, np.uint32)
    return int(words[0]) | (int(words[1]) << 32)


# -- one round of one level ---------------------------------------------------------------------
@dataclass
class Round:
    """One round of samples of one level, run to the output time ``stop`` (index): ``n`` samples
    at each time, shape (T,) (0 after ``stop``), ``path_steps`` spent, and per (statistic, time)
    the means of the fine (``f``) and coarse (``c``; level 0: none) members and of their
    difference (``y``; level 0: the fine mean), each with the variance of that mean (jackknife
    over the round's batches, ``batches - 1`` degrees of freedom); NaN after ``stop``."""

    n: np.ndarray
    stop: int
    t_stop: float
    path_steps: int
    seed: int
    batches: int
    f: np.ndarray
    f_var: np.ndarray
    c: np.ndarray
    c_var: np.ndarray
    y: np.ndarray
    y_var: np.ndarray
    nonfinite: int
    #: Per-sample raw moments E[Y^k], k = 1..4, of the pairs' difference Y of each statistic that
    #: is a mean of the statistics table or of a user's observable (for the kurtosis of the
    #: level's differences), (S, T); for the skewness S and flatness F, of their difference
    #: linearised at the round's means (:func:`run_level`); NaN at level 0.
    d1: np.ndarray | None = None
    d2: np.ndarray | None = None
    d3: np.ndarray | None = None
    d4: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in _MOMENTS:
            if getattr(self, name) is None:
                setattr(self, name, np.full_like(self.f, np.nan))


#: The raw moments of a round's differences (:class:`Round`).
_MOMENTS = ("d1", "d2", "d3", "d4")


def _jackknife(sums: np.ndarray, g: Any) -> tuple[np.ndarray, np.ndarray]:
    """(value, variance of the value) of g(means) by the delete-one-batch jackknife; ``sums``
    (B, n_times, ..., n_sums) with the count in column S_COUNT."""
    def means(s: np.ndarray) -> np.ndarray:
        count = s[..., power_sums.S_COUNT]
        return s / np.where(count > 0, count, np.nan)[..., None]

    total = sums.sum(axis=0)
    value = g(means(total))
    n_b = sums.shape[0]
    if n_b < 2:
        return value, np.full_like(value, np.nan)
    jk = g(means(total[None] - sums))
    dev = jk - jk.mean(axis=0)
    return value, (n_b - 1) / n_b * np.sum(dev * dev, axis=0)


def _st(x: np.ndarray) -> np.ndarray:
    """(..., time, statistic) -> (..., statistic, time)."""
    return np.swapaxes(x, -1, -2)


def _user_column(config: SimulationConfig, name: str) -> int:
    """The first column of the run's sums of the user observable whose mean is ``name``."""
    c = power_sums.N_SUMS
    for u in config.observables:
        if f"mean_{u}" == name:
            return c
        c += observables._columns(observables._REGISTRY[u])
    raise KeyError(name)


def statistics_of(config: SimulationConfig, names: Sequence[str]) -> Callable[[np.ndarray], np.ndarray]:
    """The target statistics ``names`` as one function of the means ``m[..., column]`` (sums
    over count, the run's columns): ``of(m)`` has shape ``(..., S)``. Each is the run's own
    statistic of that name (:data:`observables.STATISTICS`, a user observable's
    :func:`observables.user_statistics`): a mean is its column; the paper's skewness and
    flatness, and a function of the energy's mean over the paths where it is finite
    (:class:`observables.EnergyObservable`), their functions of the means. So a level's
    difference of them is g(fine means) - g(coarse means) of its coupled samples and every error
    of the multilevel estimate is the jackknife's of those values."""
    table = {s.name: s.of for s in observables.STATISTICS}
    table.update({s.name: s.of for s in observables.user_statistics(tuple(config.observables), config.times)})
    parts = [table[name] for name in names]

    def of(m: np.ndarray) -> np.ndarray:
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.stack([part(m) for part in parts], axis=-1)

    return of


#: :func:`_difference_columns`' entry for a statistic whose level differences have no measured
#: moments (none of the statistics a target accepts now): its kurtosis is NaN.
NO_MOMENTS = -1


def _difference_columns(config: SimulationConfig, names: Sequence[str]) -> list[int | tuple[int, int] | None]:
    """Each target statistic's column in the run's sums whose pairs' differences the difference
    kernel sums (``cpu.difference_kernel``): a mean of the table (``mean_E``, ``mean_E2``, ...)
    or of a user observable (the value column; for a function of the energy, its sum over the
    paths where it is finite, counted as 0 elsewhere), a running sum's rate too (its mean over
    t: the same kurtosis); None for the skewness and flatness, which are no per-sample mean
    (their differences are linearised in E^2, E^3, E^4: :func:`run_level`); ``(column, r)`` for
    the variance and diffusion of running sum r (``power_sums.running_sums``), linearised in its
    two columns (the sum and its square, from ``column``) likewise."""
    table = {s.name for s in observables.SUMS}
    users = {f"mean_{u}" for u in config.observables}
    running = [o.name for o in power_sums.running_sums(config.observables)]
    out: list[int | tuple[int, int] | None] = []
    for n in names:
        kind, _, of_name = n.partition("_")
        if n.startswith("mean_") and n[5:] in table:
            out.append(observables.column(n[5:]))
        elif n in users:
            out.append(_user_column(config, n))
        elif n.startswith("rate_") and f"mean_{n[5:]}" in users:
            out.append(_user_column(config, f"mean_{n[5:]}"))
        elif n in NONLINEAR:
            out.append(None)
        elif kind in ("var", "diffusion") and of_name in running:
            out.append((_user_column(config, f"mean_{of_name}"), running.index(of_name)))
        else:
            out.append(NO_MOMENTS)
    return out


def _batches(n: int) -> tuple[int, int]:
    b = min(LEVEL_BATCHES, n)
    size = -(-n // b)
    return -(-n // size), size


def run_level(config: SimulationConfig, level: int, n: int, round_: int, of: Callable[[np.ndarray], np.ndarray],
              stop: int,
              *, backend: str = "cpu", progress: Progress | None = None,
              columns: Sequence[int | tuple[int, int] | None] = (), tracked: bool = False) -> Round:
    """``n`` samples of ``level`` (0: an ordinary ensemble at ``config``'s step; l >= 1: coupled
    pairs at ``refined(config, l - 1)``) with the seed :func:`level_seed`, run to the output time
    of index ``stop`` only, reduced to the statistics ``of`` (:func:`statistics_of`) of the means.
    ``columns``: each statistic's column in the run's sums, or None (:func:`_difference_columns`):
    a pair level's raw moments of the differences of those (``Round.d1`` .. ``d4``); for a
    statistic with None (S, F: functions of means), of its difference linearised at the pairs'
    means (both members pooled), w . d, from the products of the differences of E^2, E^3, E^4
    (``power_sums.linearised_moments``); for ``(column, r)`` (a running sum's variance or
    diffusion), likewise of the differences of its sum and its square. ``tracked``: a pair level's members carry the run's
    per-path accumulators (:func:`tracked_statistics`; a level 0 run always does)."""
    seed = level_seed(config.seed, level, round_)
    n_b, _ = _batches(n)
    T = len(config.times)
    cfg = _truncated(config, stop + 1)
    if level == 0:
        from stochpend.engine import runner

        cfg = replace(cfg, seed=seed, paths=n, n_batches=n_b)
        ens, path_steps = runner.run_batches(cfg, 0, n_b, backend=backend, progress=progress)
        sums = ens.sums  # (B, T', n_sums)
        f, f_var = _jackknife(sums, lambda m: _st(of(m)))
        nonfinite = int(sums[:, -1, power_sums.S_NONFINITE].sum())
        f, f_var = _pad(f, T), _pad(f_var, T)
        nan = np.full_like(f, np.nan)
        return Round(_counts(n, stop, T), stop, cfg.t_max, int(path_steps), seed, n_b, f, f_var,
                     nan, nan.copy(), f, f_var, nonfinite)
    cfg = replace(bias.refined(cfg, level - 1), seed=seed)
    # S, F or a running sum's variance asked for: their linearised differences need the products
    products = any(col is None or isinstance(col, tuple) for col in columns)
    dsums = np.zeros((len(cfg.times), 4, observables.n_sums(cfg)
                      + (power_sums.product_columns(cfg.observables) if products else 0)))
    sums, path_steps = bias.pair_sums(cfg, n, n_b, backend=backend, progress=progress, what=f"level {level}",
                                      differences=dsums, products=products, tracked=tracked)  # (B, T', 2, n_sums)
    f, f_var = _jackknife(sums, lambda m: _st(of(m[..., 1, :])))
    c, c_var = _jackknife(sums, lambda m: _st(of(m[..., 0, :])))
    y, y_var = _jackknife(sums, lambda m: _st(of(m[..., 1, :]) - of(m[..., 0, :])))
    nonfinite = int(sums[:, -1, 0, power_sums.S_NONFINITE].sum())
    moments = np.full((4, f.shape[0], dsums.shape[0]), np.nan)
    n_sums = sums.shape[-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        total = sums.sum(axis=0)  # (T', 2, n_sums)
        pooled = (total / total[..., power_sums.S_COUNT:power_sums.S_COUNT + 1]).mean(axis=1)  # (T', n_sums)
        for i, col in enumerate(columns):
            if col == NO_MOMENTS:
                continue  # not measured: NaN
            if isinstance(col, tuple):  # a running sum's variance or diffusion: w . (dS, dS^2)
                column, r = col  # (not c: the coarse members' statistics above)
                w = _gradient(partial(_one_of, of, i), pooled, (column, column + 1))
                first = n_sums + power_sums.N_CROSS + power_sums.N_SUM_PRODUCTS * r
                moments[:, i, :] = power_sums.linearised_moments(
                    dsums[:, :, first:first + power_sums.N_SUM_PRODUCTS], dsums[:, 0, 0], w, power_sums.SUM_MONOMIALS)
            elif col is not None:
                moments[:, i, :] = (dsums[:, :, col] / dsums[:, :, 0]).T
            else:  # a function of means: its difference linearised at the pair's means, w . d
                w = _gradient(partial(_one_of, of, i), pooled, power_sums.CROSS)
                moments[:, i, :] = power_sums.linearised_moments(
                    dsums[:, :, n_sums:n_sums + power_sums.N_CROSS], dsums[:, 0, 0], w)
    return Round(_counts(n, stop, T), stop, cfg.t_max, int(path_steps), seed, n_b, _pad(f, T), _pad(f_var, T),
                 _pad(c, T), _pad(c_var, T), _pad(y, T), _pad(y_var, T), nonfinite,
                 *(_pad(moments[k], T) for k in range(4)))


def _one_of(of: Callable[[np.ndarray], np.ndarray], i: int, m: np.ndarray) -> np.ndarray:
    return of(m)[..., i]


def _gradient(g: Callable[[np.ndarray], np.ndarray], m: np.ndarray, columns: Sequence[int]) -> np.ndarray:
    """The partial derivatives of ``g`` (a statistic of the means) at ``m`` (..., n_sums) in the
    means of ``columns``, by central differences (a relative step of 1e-6): (..., len(columns))."""
    out = []
    for c in columns:
        step = 1e-6 * np.where(m[..., c] != 0, np.abs(m[..., c]), 1.0)
        up, down = m.copy(), m.copy()
        up[..., c] += step
        down[..., c] -= step
        with np.errstate(invalid="ignore", divide="ignore"):
            out.append((g(up) - g(down)) / (2.0 * step))
    return np.stack(out, axis=-1)


def _counts(n: int, stop: int, T: int) -> np.ndarray:
    out = np.zeros(T, dtype=np.int64)
    out[:stop + 1] = n
    return out


def _pad(a: np.ndarray, T: int) -> np.ndarray:
    """(S, T') -> (S, T), NaN after T'."""
    out = np.full((a.shape[0], T), np.nan)
    out[:, :a.shape[1]] = a
    return out


def _truncated(config: SimulationConfig, k: int) -> SimulationConfig:
    """``config`` with its first ``k`` output times only (t_max the last of them)."""
    if k == len(config.times):
        return config
    return replace(config, times=tuple(config.times[:k]), t_max=float(config.times[k - 1]),
                   hist_E_max=tuple(config.hist_E_max[:k]),
                   joint_Omega_max=tuple(config.joint_Omega_max[:k]) if config.joint_Omega_max else ())


def _target_config(config: SimulationConfig, target: Target) -> SimulationConfig:
    """The ladder's base: ``config`` at fixed steps (step_c = 0), its target times only, one
    energy-histogram bin, and only the user observables a target statistic is of: the levels
    report the target's statistics alone, binning each path's energy at each time cost level 0
    a sixth of its time (14 of 85 ns a path of one step, measured), and an accumulator no
    target reads would make level 0's lanes update its slots after every step (1.1 to 1.3
    times the work with the displacement on the OU pendulum; 3 times when level 0 went one
    path at a time; its other numbers are the same to the bit either way)."""
    idx = [int(i) for i in target.index]
    needed = tuple(u for u in config.observables if any(
        s.name in target.statistics for s in observables.user_statistics((u,), config.times)))
    return replace(config, step_c=0.0, paths=PILOT_SAMPLES, hist_bins=1, times=tuple(float(t) for t in target.times),
                   t_max=float(target.times[-1]), hist_E_max=tuple(config.hist_E_max[i] for i in idx),
                   joint_Omega_max=tuple(config.joint_Omega_max[i] for i in idx) if config.joint_Omega_max else (),
                   observables=needed)


# -- a level's rounds together ----------------------------------------------------------------------
@dataclass
class Level:
    """All rounds of one level, combined at each time: a round's mean weighted by its samples
    there, the variance of the combined mean sum (n_k/N)**2 var_k with Satterthwaite's degrees
    of freedom."""

    level: int
    rounds: list[Round] = field(default_factory=list)

    @property
    def n(self) -> np.ndarray:
        """Samples at each time, (T,)."""
        return np.sum([r.n for r in self.rounds], axis=0)

    @property
    def path_steps(self) -> int:
        return sum(r.path_steps for r in self.rounds)

    @property
    def rate(self) -> float:
        """Path-steps a sample per unit of time, measured (fixed steps: the cost to t is
        proportional to t, up to the landing steps)."""
        return self.path_steps / sum(int(r.n[r.stop]) * r.t_stop for r in self.rounds)

    def _weights(self) -> list[np.ndarray]:
        n = self.n
        with np.errstate(invalid="ignore", divide="ignore"):
            return [np.where(r.n > 0, r.n / n, 0.0) for r in self.rounds]

    def combined(self, what: str) -> tuple[np.ndarray, np.ndarray]:
        mean = np.zeros_like(self.rounds[0].f)
        var = np.zeros_like(mean)
        for w, r in zip(self._weights(), self.rounds, strict=True):
            a, v = getattr(r, what), getattr(r, f"{what}_var")
            mean = mean + np.where(w > 0, w * a, 0.0)
            var = var + np.where(w > 0, w * w * v, 0.0)
        return np.asarray(mean), np.asarray(var)

    def kurtosis(self) -> np.ndarray:
        """The kurtosis of the level's differences Y, E[(Y - m)^4] / V^2 from the rounds' raw
        moments combined (weights: samples), (S, T); NaN at level 0."""
        w = self._weights()
        zero = np.zeros_like(self.rounds[0].f)
        m1, m2, m3, m4 = (sum((np.where(wk > 0, wk * getattr(r, name), 0.0)
                               for wk, r in zip(w, self.rounds, strict=True)), start=zero) for name in _MOMENTS)
        with np.errstate(invalid="ignore", divide="ignore"):
            var = m2 - m1 * m1
            return np.asarray((m4 - 4.0 * m1 * m3 + 6.0 * m1 * m1 * m2 - 3.0 * m1**4) / (var * var))

    def dof(self, what: str = "y") -> np.ndarray:
        """Satterthwaite's degrees of freedom of the combined variance, (S, T)."""
        num = np.zeros_like(self.rounds[0].f)
        den = np.zeros_like(num)
        for w, r in zip(self._weights(), self.rounds, strict=True):
            p = np.where(w > 0, w * w * getattr(r, f"{what}_var"), 0.0)
            num = num + p
            den = den + p * p / max(r.batches - 1, 1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.asarray(num * num / den)

    @property
    def nonfinite(self) -> int:
        return sum(r.nonfinite for r in self.rounds)


# -- planning ---------------------------------------------------------------------------------------
def plan_samples(V: np.ndarray, C: np.ndarray, half_width: float, z: float) -> np.ndarray:
    """Giles' samples per level (Eq. (plan) of the module): the least total cost sum N_l C_l
    with z sqrt(sum V_l/N_l) <= ``half_width``. ``V``: per-sample variances (L+1,), ``C``: costs
    per sample (L+1,). Returns integers >= 1 (shape (L+1,))."""
    V = np.maximum(np.asarray(V, dtype=float), 0.0)
    C = np.asarray(C, dtype=float)
    total = float(np.sum(np.sqrt(V * C)))
    n = np.ceil((z / half_width) ** 2 * np.sqrt(V / C) * total)
    return np.maximum(n, 1).astype(np.int64)


def _fit_rate(levels: np.ndarray, values: np.ndarray) -> float:
    """Minus the slope of log2(values) over ``levels`` (NaN below two points)."""
    ok = np.isfinite(values) & (values > 0)
    if np.count_nonzero(ok) < 2:
        return math.nan
    return float(-np.polyfit(levels[ok], np.log2(values[ok]), 1)[0])


def _quantile(p_two_sided: float, dof: Any = math.inf) -> Any:
    """The two-sided Student t (normal for infinite dof) quantile of error probability p."""
    from scipy.special import ndtri, stdtrit

    dof = np.asarray(dof, dtype=float)
    z = -ndtri(p_two_sided / 2.0)
    with np.errstate(invalid="ignore"):
        t = -stdtrit(np.where(np.isfinite(dof) & (dof > 0), dof, 1e9), p_two_sided / 2.0)
    return np.where(np.isfinite(dof) & (dof > 0), t, z)


@dataclass
class State:
    """What the levels say now, per (statistic, time): arrays of shape (S, T) unless noted."""

    estimate: np.ndarray
    stat_var: np.ndarray
    stat_dof: np.ndarray
    m: np.ndarray        # (L+1, S, T) means of Y_l (level 0: P_0)
    m_var: np.ndarray    # (L+1, S, T) variances of those means
    V: np.ndarray        # (L+1, S, T) per-sample variances
    C: np.ndarray        # (L+1, T) path-steps a sample run to each time
    N: np.ndarray        # (L+1, T) samples at each time
    decorrelation: np.ndarray  # (L+1, S, T) sqrt(1 - r) of each pair level (NaN at level 0)
    consistency: np.ndarray    # (L+1, S, T) |F_{l-1} - C_l| / sigma (NaN at level 0)
    alpha: np.ndarray
    beta: np.ndarray
    gamma: float
    alpha_used: np.ndarray
    bias_bound: np.ndarray
    coupled: np.ndarray
    kurtosis: np.ndarray | None = None  # (L+1, S, T) of the level differences (Level.kurtosis)


def _state(levels: list[Level], conf: float, cfg: SimulationConfig) -> State:
    L = len(levels) - 1
    m, m_var = zip(*(lv.combined("y") for lv in levels), strict=True)
    m_a, m_var_a = np.array(m), np.array(m_var)
    N = np.array([lv.n for lv in levels], dtype=np.int64)
    rates = np.array([lv.rate for lv in levels])
    # the exact path-steps of a sample to each time (measured rate x t put a sample to
    # t = 1e-3 < h_0 at a thousandth of its one step, and the plan bought millions of them)
    C = steps_per_sample(cfg, L + 1)
    V = m_var_a * N[:, None, :]
    estimate = m_a.sum(axis=0)
    stat_var = m_var_a.sum(axis=0)
    dofs = np.array([lv.dof("y") for lv in levels])
    with np.errstate(invalid="ignore", divide="ignore"):
        stat_dof = stat_var**2 / np.sum(m_var_a**2 / np.maximum(dofs - 0.0, 1.0), axis=0)
    decor = np.full(m_a.shape, np.nan)
    consist = np.full(m_a.shape, np.nan)
    for lv in levels[1:]:
        l = lv.level
        _, fv = lv.combined("f")
        c, cv = lv.combined("c")
        with np.errstate(invalid="ignore", divide="ignore"):
            decor[l] = np.sqrt(m_var_a[l] / (fv + cv))
            prev, prev_v = levels[l - 1].combined("f")
            consist[l] = np.abs(prev - c) / np.sqrt(prev_v + cv)
    ls = np.arange(1, L + 1, dtype=float)
    S, T = estimate.shape
    alpha = np.full((S, T), np.nan)
    beta = np.full((S, T), np.nan)
    gamma = -_fit_rate(ls, rates[1:]) if L >= 2 else math.nan
    # The bias bound's error probability: half of 1 - conf, shared by two candidate bounds.
    z_b = float(_quantile((1.0 - conf) / 4.0))
    alpha_used = np.full((S, T), 2.0)
    bound = np.full((S, T), np.inf)
    with np.errstate(invalid="ignore", divide="ignore"):
        se = np.sqrt(m_var_a)
        for s in range(S):
            for t in range(T):
                if L >= 1:
                    resolved = np.abs(m_a[1:, s, t]) > RESOLVED_SE * se[1:, s, t]
                    if np.count_nonzero(resolved) >= 2:
                        alpha[s, t] = _fit_rate(ls[resolved], np.abs(m_a[1:, s, t][resolved]))
                    beta[s, t] = _fit_rate(ls, V[1:, s, t])
                a = alpha[s, t]
                a = 2.0 if not math.isfinite(a) else min(a, 2.0)
                alpha_used[s, t] = a
                if L >= 1 and a > 0.0:
                    cands = [(abs(m_a[L, s, t]) + z_b * se[L, s, t]) / (2.0**a - 1.0)]
                    if L >= 2:
                        cands.append((abs(m_a[L - 1, s, t]) + z_b * se[L - 1, s, t]) * 2.0**-a / (2.0**a - 1.0))
                    finite = [c for c in cands if math.isfinite(c)]
                    bound[s, t] = min(finite) if finite else math.inf
    coupled = ~(decor[L] > bias.DECORRELATED) if L >= 1 else np.ones((S, T), bool)
    return State(estimate, stat_var, stat_dof, m_a, m_var_a, V, C, N, decor, consist, alpha, beta,
                 gamma, alpha_used, bound, coupled, np.array([lv.kurtosis() for lv in levels]))


def _extra_levels(st: State, budget: np.ndarray) -> np.ndarray:
    """Levels beyond L that the bias bound asks for, per (statistic, time), from its rate."""
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = st.bias_bound / budget
        need = np.ceil(np.log2(ratio) / st.alpha_used - 1e-9)
    return np.where(ratio <= 1.0, 0, np.where(np.isfinite(need), need, MAX_LEVEL))


def _projected(st: State, extra: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(V, C, bound) with ``extra`` more levels, extrapolated from the finest with the fitted
    rates (beta at least 1, gamma 1: a pair level doubles the steps)."""
    if extra <= 0:
        return st.V, st.C, st.bias_bound
    beta = np.where(np.isfinite(st.beta), np.clip(st.beta, 0.0, 4.0), 1.0)
    k = np.arange(1, extra + 1)[:, None, None]
    V = np.concatenate([st.V, st.V[-1][None] * 2.0 ** (-beta[None] * k)])
    C = np.concatenate([st.C, st.C[-1][None] * 2.0 ** np.arange(1, extra + 1)[:, None]])
    bound = st.bias_bound * 2.0 ** (-st.alpha_used * extra)
    return V, C, bound


def _plan(st: State, eps: float, conf: float, active: np.ndarray, *, slack: bool = False,
          magnitude: np.ndarray | None = None) -> np.ndarray:
    """Samples N_l needed at each time, shape (L+1, T): at each time the largest over the
    active statistics. Without ``slack``: Giles' plan (costs to that time) for a statistical
    half-width of half the target (the pair levels resolved before the levels are chosen).
    With ``slack``: the least-cost split of the target between the bias bound and the
    statistical error (:func:`_least_cost`, the levels as they are); the pair levels keep at
    least their present samples. ``magnitude``: |P| to aim at (default |estimate|)."""
    L = st.N.shape[0] - 1
    # Student t at the current degrees of freedom: the run's will be more, its t smaller
    z = _quantile((1.0 - conf) / 2.0, st.stat_dof)
    z_b = float(_quantile((1.0 - conf) / 4.0))
    S, T = st.estimate.shape
    N = np.zeros((L + 1, T), dtype=np.int64)
    for s in range(S):
        for t in range(T):
            if not active[s, t]:
                continue
            aim = eps * (abs(st.estimate[s, t]) if magnitude is None else magnitude[s, t])
            zz = float(z[s, t])
            if slack:
                # the cheapest with the levels as they are or one or two more (whose samples the
                # rounds after their pilot plan): a pilot's three levels may not reach a small
                # target's bias at all, and half and half then asked 30x the work (OU pendulum,
                # t = 1, eps = 3e-4: 1.7e12 path-steps for a 3e10 job, refused)
                plans = [_least_cost(st, s, t, aim, zz, z_b, k) for k in range(EXTRA_LEVELS + 1)]
                n = min(plans, key=lambda p: p[0])[1]
                if n is None:  # no split meets the target even so: half and half
                    n = plan_samples(st.V[:, s, t], st.C[:, t], 0.5 * aim, zz)
                n = n[:L + 1]
            else:
                n = plan_samples(st.V[:, s, t], st.C[:, t], 0.5 * aim, zz)
            N[:, t] = np.maximum(N[:, t], n)
    return N


#: The bias bound's shares of the target that the plan weighs (issue 35, "at least cost"): a
#: fixed half for the bias leaves the statistical error half the target and costs level 0 four
#: times the samples of an (almost) bias-free plan, while a finer level's pairs cost little.
BIAS_SHARES = tuple(float(x) for x in np.linspace(0.02, 0.5, 25))
#: Levels beyond the finest that the least-cost plan weighs (each extrapolated at the fitted rates).
EXTRA_LEVELS = 2


def _least_cost(st: State, s: int, t: int, aim: float, z: float, z_b: float,
                extra: int) -> tuple[float, np.ndarray | None]:
    """(path-steps still to spend, samples (L+1+extra,)) of the cheapest plan for statistic s at
    time t with ``extra`` levels beyond the finest, over the bias bound's shares theta of the
    target ``aim`` (:data:`BIAS_SHARES`): the finest level's samples for its bias bound
    (Eq. (bias) of the module) at theta aim, Giles' samples for the statistical half-width
    (1 - theta) aim, the pair levels at least at their present samples and level 0 taking the
    variance they leave. Extra levels are extrapolated (:func:`_projected`; the finest mean
    scaled by 2**-alpha a level) and pay a pilot. (inf, None) where no share meets the target."""
    V, C, _ = _projected(st, extra)
    V, C = V[:, s, t], C[:, t]
    L = st.N.shape[0] - 1
    n_now = np.concatenate([st.N[:, t], np.zeros(extra, dtype=np.int64)]).astype(float)
    a = float(st.alpha_used[s, t])
    if not (np.all(np.isfinite(V)) and a > 0.0 and math.isfinite(aim) and aim > 0):
        return math.inf, None
    shrink = 2.0**a - 1.0
    m_last = abs(float(st.m[L, s, t])) * 2.0 ** (-a * extra)
    bound_now = float(st.bias_bound[s, t]) if extra == 0 else math.inf
    best, best_n = math.inf, None
    for theta in BIAS_SHARES:
        half = (1.0 - theta) * aim
        n = plan_samples(V, C, half, z).astype(float)
        n[1:] = np.maximum(n[1:], n_now[1:])
        if bound_now > theta * aim:
            room = theta * aim * shrink - m_last
            if room <= 0.0:
                continue
            n[-1] = max(n[-1], math.ceil((z_b * math.sqrt(max(V[-1], 0.0)) / room) ** 2))
        if n.size > 1:  # level 0 takes the variance the pair levels leave
            rest = (half / z) ** 2 - float(np.sum(np.maximum(V[1:], 0.0) / n[1:]))
            if rest <= 0.0:
                continue
            n[0] = max(1.0, math.ceil(max(V[0], 0.0) / rest))
        cost = float(np.sum(np.maximum(n - n_now, 0.0) * C)) + extra * PILOT_SAMPLES * float(C[-1])
        if cost < best:
            best, best_n = cost, n
    return best, (None if best_n is None else best_n.astype(np.int64))


def _levels_wanted(st: State, eps: float, conf: float, active: np.ndarray) -> bool:
    """Whether a level more is cheaper for some active (statistic, time): its least-cost plan
    with one or two levels beyond the finest (extrapolated) costs less than with the levels as
    they are, or these cannot meet the target and the bias bound is over half of it (a
    pre-asymptotic ladder, whose fitted rate promises nothing from the next level either)."""
    z = _quantile((1.0 - conf) / 2.0, st.stat_dof)
    z_b = float(_quantile((1.0 - conf) / 4.0))
    S, T = st.estimate.shape
    for s in range(S):
        for t in range(T):
            if not active[s, t]:
                continue
            aim = eps * abs(float(st.estimate[s, t]))
            here = _least_cost(st, s, t, aim, float(z[s, t]), z_b, 0)[0]
            more = min(_least_cost(st, s, t, aim, float(z[s, t]), z_b, k)[0]
                       for k in range(1, EXTRA_LEVELS + 1))
            if more < here or (math.isinf(here) and st.bias_bound[s, t] > 0.5 * aim):
                return True  # cheaper with a level more, or not possible without one
    return False


def _level0_floor(st: State, eps: float, conf: float, active: np.ndarray) -> np.ndarray:
    """Level 0's samples at each time, (T,), that no plan goes below: V_0 (z / (eps |P|))**2 with
    |P| two standard errors up and V_0 at its lower bound (level 0's variance alone taking the
    whole target), the largest over the active statistics; 0 where none is active."""
    from scipy.special import chdtri

    z = _quantile((1.0 - conf) / 2.0, st.stat_dof)
    dof = np.where(np.isfinite(st.stat_dof) & (st.stat_dof > 1), st.stat_dof, 1.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        aim = eps * (np.abs(st.estimate) + 2.0 * np.sqrt(np.maximum(st.stat_var, 0.0)))
        # V_0 at its lower 97.5 % bound (chi-square at the estimate's degrees of freedom): a
        # batch variance is itself noisy (+-18 % at 63 degrees of freedom), and a floor drawn
        # from a high one overshoots (the OU pendulum's first round put V_0 at 0.88 for 0.66).
        low = chdtri(dof, 0.975) / dof
        n = np.ceil(np.maximum(st.V[0], 0.0) * low * (z / aim) ** 2)
    n = np.where(active & np.isfinite(n), n, 0.0)
    return np.max(n, axis=0).astype(np.int64)


def _guarded_plan(st: State, eps: float, conf: float, active: np.ndarray, *,
                  slack: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_plan`, approached from below: a relative target planned from a few hundred pilot
    samples can ask for many times the samples it needs (|P| underestimated by a standard error
    or two: the pilot of the OU pendulum's <E> at t = 1 asked for 5x, 2.1e9 path-steps for a
    1.6e8 job). So each round plans for |P| one step up, |estimate| + 2 se (it asks no more than
    the target needs, at about 97.5 %), and where that plan is already met but the plan at
    |estimate| is not, at most doubles the samples; the loop then plans again with the better
    estimate. The stopping rule is unchanged: the loop ends when the plan at |estimate| is met.

    Returns (this round's samples, the plan at |estimate|, the plan one step up), each (L+1, T):
    a refusal needs the last over the limit too (the run cannot be known to be too costly from
    a plan that may ask for several times what it needs), and names the middle one's cost."""
    need = _plan(st, eps, conf, active, slack=slack)
    optimistic = _plan(st, eps, conf, active, slack=slack,
                       magnitude=np.abs(st.estimate) + 2.0 * np.sqrt(np.maximum(st.stat_var, 0.0)))
    step = np.maximum(optimistic, np.minimum(need, 2 * st.N))
    return np.minimum(need, step), need, optimistic


def staircase(deficit: np.ndarray) -> list[tuple[int, int]]:
    """Rounds ``(stop, n)`` that give one level at least ``deficit[j]`` more samples at each
    time j at least cost: samples run to time j serve every earlier time, so R_j = max over
    j' >= j of deficit[j'] samples must reach time j, and n_j = R_j - R_{j+1} stop there."""
    d = np.maximum(np.asarray(deficit, dtype=np.int64), 0)
    reach = np.maximum.accumulate(d[::-1])[::-1]
    nxt = np.append(reach[1:], 0)
    return [(j, int(reach[j] - nxt[j])) for j in range(d.size) if reach[j] > nxt[j]]


def _staircase_cost(deficits: np.ndarray, C: np.ndarray) -> float:
    return float(sum(n * C[level, j] for level in range(deficits.shape[0])
                     for j, n in staircase(deficits[level])))


def _cost_to_certify(st: State, eps: float, conf: float) -> np.ndarray:
    """Path-steps that this estimator would spend in all for each (statistic, time) alone:
    the levels its bias asks for (extrapolated) and Giles' samples for the rest of the error."""
    S, T = st.estimate.shape
    out = np.full((S, T), np.inf)
    z = float(_quantile((1.0 - conf) / 2.0))
    extra = _extra_levels(st, 0.5 * eps * np.abs(st.estimate))
    for s in range(S):
        for t in range(T):
            k = int(min(extra[s, t], MAX_LEVEL))
            V, C, bound = _projected(st, k)
            half = 0.5 * eps * abs(st.estimate[s, t])
            if bound[s, t] <= half and np.all(np.isfinite(V[:, s, t])):
                N = plan_samples(V[:, s, t], C[:, t], half, z)
                out[s, t] = float(np.sum(N * C[:, t]))
    return out


def _cost_independent(st: State, eps: float, conf: float) -> tuple[np.ndarray, np.ndarray]:
    """Path-steps of the cheapest route that does not need coupling (issue 35, item 3): two
    *independent* ordinary ensembles of N paths each at h_k and h_(k+1) = h_k/2, the finer one
    the estimate and their difference d_k (Richardson's) its bias bound,

        total = z sqrt(V/N) + (|d_k| + z_b sqrt(2 V/N))/(2^alpha - 1) <= eps |P|,

    so sqrt(N) = (z + z_b sqrt(2)/(2^alpha - 1)) sqrt(V) / (eps |P| - |d_k|/(2^alpha - 1)) and the
    cost N (C_k + 2 C_k), minimised over k. V is level 0's per-sample variance (an ordinary
    ensemble's: it hardly depends on h), |d_k| the measured mean difference of level k + 1 where
    there is one (a pair's mean is unbiased whatever its coupling) less two of its standard
    errors, beyond it the last one scaled by 2^(-alpha) a level, C_k = C_0 2^k (fixed steps). Returns (cost, k) of shape
    (S, T); inf where no k up to MAX_LEVEL meets the target."""
    S, T = st.estimate.shape
    L = st.m.shape[0] - 1
    z = float(_quantile((1.0 - conf) / 2.0))
    z_b = float(_quantile((1.0 - conf) / 4.0))
    cost = np.full((S, T), np.inf)
    best_k = np.full((S, T), -1)
    for s in range(S):
        for t in range(T):
            V0, P, a = float(st.V[0, s, t]), abs(float(st.estimate[s, t])), float(st.alpha_used[s, t])
            if L < 1 or not (math.isfinite(V0) and V0 >= 0 and P > 0 and a > 0):
                continue
            shrink = 2.0**a - 1.0
            # |d| two standard errors down (0 where unresolved): a decorrelated level's mean from a
            # few hundred pairs is mostly noise, and the route measures d itself. So the cost is a
            # lower bound ("at least"), never an overstatement.
            low_d = np.maximum(np.abs(st.m[:, s, t]) - 2.0 * np.sqrt(st.m_var[:, s, t]), 0.0)
            for k in range(MAX_LEVEL):
                d = low_d[k + 1] if k + 1 <= L else low_d[L] * 2.0 ** (-a * (k + 1 - L))
                room = eps * P - d / shrink
                if not (room > 0 and math.isfinite(d)):
                    continue
                n = math.ceil(((z + z_b * math.sqrt(2.0) / shrink) * math.sqrt(V0) / room) ** 2)
                c = n * 3.0 * float(st.C[0, t]) * 2.0**k
                if c < cost[s, t]:
                    cost[s, t], best_k[s, t] = c, k
    return cost, best_k


# -- the run ------------------------------------------------------------------------------------
#: The work of starting a path and summing its statistics, in path-steps: a level-0 path of one
#: fixed step took 77 ns, of 5 steps 100 ns, of 50 steps 335 ns (4e6 paths, 2 threads, this
#: 2-core Zen 4), so 5.2 ns a step and 72 ns, 14 steps' worth, a path. It is no path-step, but a
#: round of many short paths (a target at t = 1e-3 < h) is mostly this: counted in the work the
#: wall-time budget converts (:class:`Budget`), not in the plan's costs.
PATH_OVERHEAD_STEPS = 14.0


def steps_to(times: np.ndarray, h: float) -> np.ndarray:
    """Fixed steps of ``h`` that a path takes to each output time, landing on every one, (T,):
    at least one step a time (a target run's levels take exactly these)."""
    gaps = np.diff(np.concatenate([[0.0], np.asarray(times, dtype=float)]))
    return np.cumsum(np.maximum(np.ceil(gaps / h - 1e-9), 1.0))


def steps_per_sample(cfg: SimulationConfig, n_levels: int) -> np.ndarray:
    """The path-steps of one sample of each level to each output time, (n_levels, T): level 0 a
    path at h_0; level l a coarse member at h_{l-1} and a fine one at h_l (three path-steps a
    coarse step). Exact (the levels' rounds spend these to the step); the plan's cost C."""
    times = np.asarray(cfg.times, dtype=float)
    rows = [steps_to(times, cfg.h_max)]
    rows += [3.0 * steps_to(times, cfg.h_max * 0.5 ** (level - 1)) for level in range(1, n_levels)]
    return np.array(rows)


def work_per_sample(cfg: SimulationConfig, n_levels: int) -> np.ndarray:
    """:func:`steps_per_sample` and :data:`PATH_OVERHEAD_STEPS` a member started: the work the
    wall-time budget converts, (n_levels, T)."""
    members = np.where(np.arange(n_levels) == 0, 1.0, 2.0)[:, None]
    return steps_per_sample(cfg, n_levels) + PATH_OVERHEAD_STEPS * members


@dataclass
class Budget:
    """What a target run may spend: ``path_steps`` (``max_path_steps``) and, when given, the
    wall time ``seconds`` (``max_seconds``), counted from ``started`` (``time.perf_counter``).
    The wall time becomes work (path-steps and :data:`PATH_OVERHEAD_STEPS` a path started,
    ``work_spent`` so far) at the run's rate: the rate earlier target runs of its kernel
    measured on this machine (:func:`rate_kind`) until the run has computed for
    :data:`RATE_MEASURED_AFTER_S`, then the run's own (its work over the seconds spent outside
    compiling), and the compiling expected (``compile_s``) is set aside before the first. Every
    plan is checked (:meth:`exceeded`), so a target that the budget cannot buy is refused before
    the work it would not finish. Before the paths' start was counted, a round of short paths
    was converted at the rate of long ones: ``max_seconds=5`` ran 176 s."""

    path_steps: float
    seconds: float | None = None
    rate: float = math.inf
    compile_s: float = 0.0
    started: float = 0.0
    work_spent: float = 0.0

    def _rate(self, compiling_s: float) -> float:
        computing = _time.perf_counter() - self.started - compiling_s
        if self.work_spent > 0 and computing >= RATE_MEASURED_AFTER_S:
            return self.work_spent / computing
        return self.rate

    def work_left(self, compiling_s: float = 0.0) -> float:
        """The work the wall-time budget leaves (inf without one), ``compiling_s`` of the seconds
        since the start spent compiling."""
        if self.seconds is None:
            return math.inf
        elapsed = _time.perf_counter() - self.started
        left = self.seconds - elapsed - (self.compile_s if self.work_spent == 0 else 0.0)
        return max(left, 0.0) * self._rate(compiling_s)

    def limit(self, spent: float = 0.0, compiling_s: float = 0.0) -> float:
        """The path-steps the run may reach in all, ``spent`` so far (the work left counted as
        path-steps: what the late-time route, of long paths, may spend)."""
        return min(self.path_steps, spent + self.work_left(compiling_s))

    def seconds_for(self, work: float, compiling_s: float = 0.0) -> float:
        """Seconds that ``work`` more take at the rate :meth:`work_left` uses (NaN: unknown)."""
        rate = self._rate(compiling_s)
        return work / rate if 0.0 < rate < math.inf else math.nan

    def exceeded(self, total: float, spent: float = 0.0, compiling_s: float = 0.0,
                 work: float | None = None) -> str | None:
        """None when ``total`` path-steps in all, and ``work`` more (default: the path-steps
        beyond ``spent``), fit; else the limit that they break, for a message."""
        more = total - spent if work is None else work
        if total <= self.path_steps and more <= self.work_left(compiling_s):
            return None
        if total > self.path_steps:
            return (f"above the limit of {self.path_steps:.3g} path-steps; raise it with max_path_steps= "
                    "(--max-path-steps)")
        return (f"more than the wall-time budget max_seconds={self.seconds:g} leaves (about "
                f"{self.seconds_for(more, compiling_s):.3g} s of work at this machine's rate, "
                f"{self.seconds_for(self.work_left(compiling_s), compiling_s):.3g} s left); "
                "raise it with max_seconds= (--max-seconds)")


def check_pilot(config: SimulationConfig, target: Target, *, backend: str = "cpu", max_path_steps: Any = None,
                max_seconds: Any = None, started: float | None = None) -> Budget:
    """The :class:`Budget` of a target run of ``config`` (its wall time counted from ``started``,
    default now), refusing (``ValueError``, one line) a pilot that it cannot buy: what
    :func:`target_run` checks first, and a sweep of targets for every set before any work."""
    from stochpend.runs import resources

    cfg = _target_config(config, target)
    budget = Budget(resources.work_limit(max_path_steps), check_max_seconds(max_seconds),
                    started=_time.perf_counter() if started is None else started)
    budget.rate = resources._rate(backend == "cuda", None, rate_kind(cfg))[0]
    if budget.seconds is not None:
        budget.compile_s = resources.compile_seconds(cfg, backend=backend)
    pilot_cost = float(np.sum(steps_per_sample(cfg, PILOT_LEVELS)[:, -1])) * PILOT_SAMPLES
    pilot_work = float(np.sum(work_per_sample(cfg, PILOT_LEVELS)[:, -1])) * PILOT_SAMPLES
    broken = budget.exceeded(pilot_cost, work=pilot_work)
    if broken is not None:
        raise ValueError(f"target_error={target.error:g} is not accepted: its pilot alone ({PILOT_SAMPLES} "
                         f"samples on each of levels 0..{PILOT_LEVELS - 1}) needs about {pilot_cost:.3g} "
                         f"path-steps, {broken}; or use a larger h_max or a shorter t_max")
    return budget


def rate_kind(cfg: SimulationConfig) -> str:
    """The calibration's name (:mod:`stochpend.numerics._calibration`) of target runs of
    ``cfg``'s kernel: their rate is their own, their work (every path-step, the pairs' fine half
    steps counted, and :data:`PATH_OVERHEAD_STEPS` a path started) over their computing seconds,
    recorded by each target run. Not the ordinary
    run's rate of the same kernel, which counts only its lower-bound work against a wall time
    that holds its bias pairs and histograms: on this 2-core machine that rate was 3.3-3.9e6
    path-steps/s a thread against the target run's 8e7, and a wall-time budget converted at it
    refused targets that fit (the run's own rate takes over only after 2 s). A target on an
    accumulator whose KernelSpec has lanes runs its coupled pairs in lanes too (" and pairs"),
    2.3 to 4.1 times faster than the one set at a time that the kind without it measured."""
    from stochpend.runs import resources

    kind = resources.kernel_kind(cfg)
    return f"target {kind} and pairs" if kind.endswith(" tracked lanes") else f"target {kind}"


def _record_rate(cfg: SimulationConfig, backend: str, path_steps: float, computing_s: float, load: float) -> None:
    """Store a finished target run's rate for the next one's budget (:func:`rate_kind`)."""
    if backend != "cpu":
        return
    from stochpend.numerics import _calibration
    from stochpend.runs import resources

    _calibration.record_rate(rate_kind(cfg), path_steps, computing_s, resources._cores(None), load=load)


@dataclass
class Ensemble:
    """One ensemble of the independent route (:func:`_ensemble`): ``n`` paths at step ``h``
    with ``seed`` to the output time of index ``stop``; the statistics' means and their
    variances, (S, stop + 1), the path-steps and the non-finite paths."""

    seed: int
    h: float
    n: int
    stop: int
    f: np.ndarray
    f_var: np.ndarray
    path_steps: int
    nonfinite: int


@dataclass
class Journal:
    """The work of a target run in the order it was done: every level's round and every
    ensemble of the independent route. The loop is a fixed function of these (the plan of each
    round is made from the rounds before it), so a run handed the journal of an interrupted
    one replays it, taking each recorded round where the loop asks for that round (checked:
    the same level, seed, samples and last time, else a ``ValueError`` of one line naming
    ``source``) instead of running it, and goes on from where it stopped with the numbers an
    uninterrupted run has, to the last bit. ``saved`` is called after each new round or
    ensemble (a checkpointed run's round boundary, :mod:`stochpend.runs.checkpoint`);
    ``elapsed_s``: the seconds of the sessions before, counted in the wall time and the
    wall-time budget."""

    rounds: list[tuple[int, Round]] = field(default_factory=list)
    ensembles: list[Ensemble] = field(default_factory=list)
    saved: Callable[[Journal], None] | None = None
    source: str = "journal"
    elapsed_s: float = 0.0
    _next: list[int] = field(default_factory=lambda: [0, 0])

    def _refuse(self, what: str) -> ValueError:
        return ValueError(f"{self.source} is not accepted: its {what} is not the one this run makes "
                          "(the configuration or the target differs from the run that wrote it)")

    def round(self, level: int, n: int, round_: int, stop: int, seed: int, run: Callable[[], Round]) -> Round:
        """Level ``level``'s round ``round_`` of ``n`` samples to time ``stop``: the recorded
        one while there are, else ``run()`` (recorded, then ``saved``)."""
        i = self._next[0]
        self._next[0] += 1
        if i < len(self.rounds):
            lv, r = self.rounds[i]
            if (lv, r.seed, r.stop, int(r.n[stop])) != (level, seed, stop, n):
                raise self._refuse(f"round {i} (level {lv}, seed {r.seed}, {int(r.n[r.stop])} samples to "
                                   f"time index {r.stop})")
            return r
        r = run()
        self.rounds.append((level, r))
        if self.saved is not None:
            self.saved(self)
        return r

    def ensemble(self, seed: int, h: float, n: int, stop: int, run: Callable[[], Ensemble]) -> Ensemble:
        """An ensemble of the independent route: the recorded one while there are, else ``run()``."""
        i = self._next[1]
        self._next[1] += 1
        if i < len(self.ensembles):
            e = self.ensembles[i]
            if (e.seed, e.h, e.n, e.stop) != (seed, h, n, stop):
                raise self._refuse(f"ensemble {i} (seed {e.seed}, h = {e.h!r}, {e.n} paths to time index {e.stop})")
            return e
        e = run()
        self.ensembles.append(e)
        if self.saved is not None:
            self.saved(self)
        return e


def target_run(config: SimulationConfig, target: Target, *, backend: str = "cpu",
               max_path_steps: Any = None, max_seconds: Any = None, progress: Progress | None = None,
               note: Any = None, journal: Journal | None = None) -> xr.Dataset:
    """Meet ``target`` (:func:`check_target`) for ``config`` by multilevel Monte Carlo (module
    docstring) and return the Dataset (see :func:`stochpend.simulate`, ``target_error``).

    ``config.paths`` is not used (the plan sets the samples); ``step_c`` is set to 0 (fixed
    steps h_max / 2**l). Refuses (``ValueError``, one line) before the pilot when the pilot alone
    exceeds ``max_path_steps`` or the wall-time budget ``max_seconds`` (:class:`Budget`), and
    before each round when the plan does. ``journal``: where the rounds are recorded, and
    replayed from when it holds an interrupted run's (:class:`Journal`).
    """
    from stochpend.numerics._jitcache import CompileClock

    note = note or (lambda _msg: None)
    journal = journal or Journal()
    cfg = _target_config(config, target)
    started = _time.perf_counter() - journal.elapsed_s  # the budget and the wall time span the sessions
    resumed = journal.elapsed_s > 0 or bool(journal.rounds)
    from stochpend.numerics import _calibration

    load = _calibration.current_load()  # before this run adds its own threads
    tracked = tracked_statistics(cfg, target.statistics)
    budget = check_pilot(config, target, backend=backend, max_path_steps=max_path_steps, max_seconds=max_seconds,
                         started=started)
    # Of the levels' sums: cfg's times (the target's), cfg's observables (the target's).
    of = statistics_of(cfg, target.statistics)
    columns = _difference_columns(cfg, target.statistics)
    levels: list[Level] = []
    spent = 0

    T = len(cfg.times)
    times = np.asarray(cfg.times, dtype=float)

    def add(level: int, n: int, stop: int = T - 1) -> None:
        nonlocal spent
        if level == len(levels):
            levels.append(Level(level))
        round_ = len(levels[level].rounds)
        r = journal.round(level, n, round_, stop, level_seed(cfg.seed, level, round_),
                          lambda: run_level(cfg, level, n, round_, of, stop, backend=backend,
                                                            columns=columns, tracked=tracked))
        levels[level].rounds.append(r)
        spent += r.path_steps
        budget.work_spent += r.path_steps + PATH_OVERHEAD_STEPS * (1 if level == 0 else 2) * int(r.n[r.stop])

    eps, conf = target.error, target.confidence
    with CompileClock() as clock:
        for level in range(PILOT_LEVELS):
            add(level, PILOT_SAMPLES)
        note(f"target: pilot of {PILOT_SAMPLES} samples on levels 0..{PILOT_LEVELS - 1} ({spent:.3g} path-steps)")
        for _ in range(MAX_ROUNDS):
            # Giles' loop: (a) the pair levels' samples for a statistical half-width of half
            # the target (so that the finest level's mean, and with it the bias bound, is
            # resolved), refused if the whole plan is over the limit; (b) a level more while it
            # makes the least-cost plan cheaper (or the target needs it); (c) the least-cost
            # plan's samples (its split of the target between bias and statistics).
            st = _state(levels, conf, cfg)
            active = st.coupled & np.isfinite(st.estimate) & (st.estimate != 0)
            if budget.seconds is None:
                _refuse_zero(target, st, conf, active, times)
            L = len(levels) - 1
            step, need, least = _guarded_plan(st, eps, conf, active)
            more = np.maximum(step - st.N, 0)
            # refused on the least-cost plan (the half-and-half one may ask four times the work)
            _, need_lc, least_lc = _guarded_plan(st, eps, conf, active, slack=True)
            W = work_per_sample(cfg, L + 1)
            low = (spent + _staircase_cost(np.maximum(least_lc - st.N, 0), st.C),
                   _staircase_cost(np.maximum(least_lc - st.N, 0), W))
            if budget.exceeded(low[0], spent, clock.seconds, work=low[1]):
                _refuse(target, spent, spent + _staircase_cost(np.maximum(need_lc - st.N, 0), st.C), budget,
                        "the plan", clock.seconds, _staircase_cost(np.maximum(need_lc - st.N, 0), W), low=low)
            # Level 0 up to the samples that every plan gives it (its variance alone filling the
            # target at |P| two standard errors up): a relative target needs |P|, and the pilot's
            # 256 paths may put it at a fifth of its value (OU pendulum, t = 1: 0.019 for 0.085),
            # so that the pair levels' plan, made for that |P|, grew round after round while
            # level 0, never sampled, kept the estimate where it was.
            more[0] = np.maximum(_level0_floor(st, eps, conf, active) - st.N[0], 0)
            # a round adds at least a tenth of a level's samples: fewer rounds, each worth its start
            more = np.where(more > 0.1 * st.N, more, 0)
            if np.any(more):
                _top_up(add, more, st, note, times, budget.seconds_for(_staircase_cost(more, W), clock.seconds))
                continue
            if L < MAX_LEVEL and _levels_wanted(st, eps, conf, active):
                guess = float(steps_per_sample(cfg, L + 2)[-1, -1]) * PILOT_SAMPLES
                guess_work = float(work_per_sample(cfg, L + 2)[-1, -1]) * PILOT_SAMPLES
                if budget.exceeded(spent + guess, spent, clock.seconds, work=guess_work):
                    _refuse(target, spent, spent + guess, budget, f"level {L + 1}'s pilot", clock.seconds, guess_work)
                add(L + 1, PILOT_SAMPLES)
                note(f"target: level {L + 1} added (h = {cfg.h_max * 0.5 ** (L + 1):.3g})")
                continue
            step, need, least = _guarded_plan(st, eps, conf, active, slack=True)
            more = np.maximum(step - st.N, 0)
            more = np.where((more > 0) & (more < 0.05 * st.N), np.ceil(0.05 * st.N), more).astype(np.int64)
            if not np.any(more):
                break
            low = (spent + _staircase_cost(np.maximum(least - st.N, 0), st.C),
                   _staircase_cost(np.maximum(least - st.N, 0), W))
            if budget.exceeded(max(spent + _staircase_cost(more, st.C), low[0]), spent, clock.seconds,
                               work=max(_staircase_cost(more, W), low[1])):
                _refuse(target, spent, spent + _staircase_cost(np.maximum(need - st.N, 0), st.C), budget,
                        "the plan", clock.seconds, _staircase_cost(np.maximum(need - st.N, 0), W), low=low)
            _top_up(add, more, st, note, times, budget.seconds_for(_staircase_cost(more, W), clock.seconds))
        st = _state(levels, conf, cfg)
        per_step = budget.seconds_for(1.0, clock.seconds)  # the levels' rate, for the notes
        route = _certify_by_independent_runs(cfg, target, st, sum(lv.nonfinite for lv in levels),
                                             budget.limit(spent, clock.seconds) - spent, of, backend, note,
                                             journal, seconds_for=lambda n: n * per_step)
        if route is not None:
            spent += route.path_steps
    wall = _time.perf_counter() - started
    if not resumed:  # a resumed run's rounds ran in other sessions, under other loads
        _record_rate(cfg, backend, budget.work_spent + (route.path_steps if route is not None else 0),
                     wall - clock.seconds, load)
    return _dataset(config, cfg, target, levels, st, spent, wall, clock.seconds, backend, route)


def _top_up(add: Any, more: np.ndarray, st: State, note: Any, times: np.ndarray, seconds: float = math.nan) -> None:
    """Run ``more`` (L+1, T) samples as rounds of :func:`staircase`; ``seconds``: their expected
    wall time, announced when known; ``times``: the output times, (T,)."""
    # the samples at the latest time this round reaches (the last output time may need none)
    j = int(np.flatnonzero(np.any(more > 0, axis=0))[-1]) if np.any(more > 0) else more.shape[1] - 1
    note(f"target: samples per level at t = {times[j]:g}: {', '.join(str(int(n)) for n in st.N[:, j] + more[:, j])}"
         f" ({_staircase_cost(more, st.C):.3g} more path-steps{_about(seconds)})")
    for level in range(more.shape[0]):
        for stop, n in staircase(more[level]):
            add(level, n, stop)


def _about(seconds: float) -> str:
    """``", about 12 min here"`` (at the rate measured on this machine), or nothing where it is not known."""
    return f", about {_duration(seconds)} here" if math.isfinite(seconds) else ""


def _duration(seconds: float) -> str:
    """``seconds`` as a person reads a wait: 4 s, 12 min, 3.2 h, 5.1 days."""
    if seconds < 60:
        return f"{seconds:.2g} s"
    if seconds < 3600:
        return f"{seconds / 60:.2g} min"
    if seconds < 86400:
        return f"{seconds / 3600:.2g} h"
    return f"{seconds / 86400:.2g} days"


def _refuse_zero(target: Target, st: State, conf: float, active: np.ndarray, times: np.ndarray) -> None:
    """Refuse (``ValueError``, one line) a relative target of a statistic that is 0 within its
    statistical error at a time where level 0 has had more than its pilot: a relative error of
    a value that may be 0 has no number of samples that is known to reach it, and the plan,
    made from |estimate| two standard errors up, grows round after round without end (<E> of
    the pendulum from a uniform angle at rest is 0 at t = 0 and about 1e-6 at t = 1e-3: at
    eps = 0.01 the second round planned 3.6e9 path-steps, and the run went on). Called only
    without a wall-time budget: with one, the plan is refused when it no longer fits it."""
    z = _quantile((1.0 - conf) / 2.0)
    with np.errstate(invalid="ignore"):
        se = np.sqrt(np.maximum(st.stat_var, 0.0))
        zero = active & (st.N[0][None, :] > PILOT_SAMPLES) & (np.abs(st.estimate) <= z * se)
    if not np.any(zero):
        return
    s, t = (int(i[0]) for i in np.nonzero(zero))
    raise ValueError(f"target_error={target.error:g} is not accepted for {target.statistics[s]} at t = "
                     f"{times[t]:g}: it is 0 within its statistical error ({st.estimate[s, t]:.3g} +- "
                     f"{z * se[s, t]:.2g} at {100 * conf:g} % from {int(st.N[0, t])} paths), so no number "
                     "of paths is known to reach a relative error of it; ask for statistics or times away "
                     "from 0 (target_statistics= (--target-statistics), target_times= (--target-times)), or "
                     "give a wall-time budget (max_seconds= (--max-seconds)) to try within it")


def _refuse(target: Target, spent: int, total: float, budget: Budget, what: str, compiling_s: float,
            work: float | None = None, low: tuple[float, float] | None = None) -> None:
    """Refuse (``ValueError``, one line) naming the work ``total`` would bring. ``low``: (total
    path-steps, work units left) of the plan with each target statistic two standard errors
    larger than its estimate (the plan that decided the refusal), named where it is below
    0.9 ``total``, with its time at the measured rate: a relative target's
    cost goes as 1/|P|^2, and after the pilot |P| may be a fraction of its value (the OU
    pendulum at t = 1, eps = 3e-4: 1.71e12 path-steps named, where eps = 1e-3 had run in 2.2e9,
    about 2.4e10 at 3e-4), so the one number read as a cost 70 times too high."""
    broken = (budget.exceeded(total, spent, compiling_s, work)
              or f"above the limit of {budget.path_steps:.3g} path-steps")
    span = ""
    if low is not None and low[0] < 0.9 * total:
        span = (f" at the estimates so far and to {low[0]:.3g}{_about(budget.seconds_for(low[1], compiling_s))} "
                "if each target statistic is two standard errors larger")
    raise ValueError(f"target_error={target.error:g} is not accepted: {what} would bring the work to "
                     f"{total:.3g} path-steps{span} ({spent:.3g} already spent), {broken}; or ask for a larger "
                     "target_error= (--target-error), fewer target_times= (--target-times) or "
                     "target_statistics= (--target-statistics)")


@dataclass
class Verdict:
    """Per (statistic, time), shape (S, T): the statistical half-width, whether certified, the
    cost of the cheaper route to certify (NaN where certified) and, where that route is two
    independent ensembles, its coarser step (else NaN) and index k."""

    half: np.ndarray
    certified: np.ndarray
    cost: np.ndarray
    route_h: np.ndarray
    route_k: np.ndarray
    independent: np.ndarray


def _verdict(st: State, eps: float, conf: float, nonfinite: int, h0: float | None = None) -> Verdict:
    z = _quantile((1.0 - conf) / 2.0, st.stat_dof)
    half = z * np.sqrt(st.stat_var)
    total = half + st.bias_bound
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = total / np.abs(st.estimate)
    certified = st.coupled & (rel <= eps) & np.isfinite(st.bias_bound) & (nonfinite == 0)
    ml_cost = _cost_to_certify(st, eps, conf)
    ind_cost, ind_k = _cost_independent(st, eps, conf)
    # The cheaper of the two routes: this estimator, or two independent ensembles (issue 35,
    # item 3: where the levels decorrelate the coupling buys nothing and the pairs' variance is
    # that of two ensembles, so the telescope's cost is far above the plain route's).
    independent = ind_cost < ml_cost
    cost = np.where(certified, np.nan, np.minimum(ml_cost, ind_cost))
    h = 1.0 if h0 is None else h0
    route_h = np.where(certified | ~np.isfinite(cost), np.nan,
                       np.where(independent, h * 0.5 ** np.maximum(ind_k, 0), np.nan))
    return Verdict(half, certified, cost, route_h, ind_k, independent & ~certified & np.isfinite(cost))


@dataclass
class Route:
    """What the independent ensembles gave, per (statistic, time), shape (S, T): ``ran`` where
    they replaced the multilevel entry, the finer ensemble's mean (``estimate``), its half-width
    and the bias bound from the two ensembles' difference; the path-steps, seeds and non-finite
    paths they took."""

    ran: np.ndarray
    estimate: np.ndarray
    half: np.ndarray
    bound: np.ndarray
    path_steps: int = 0
    seeds: tuple[int, ...] = ()
    nonfinite: int = 0


def _ensemble(cfg: SimulationConfig, h: float, n: int, seed: int, stop: int,
              of: Callable[[np.ndarray], np.ndarray], backend: str) -> Ensemble:
    """An ordinary fixed-step ensemble of ``n`` paths at step ``h`` with ``seed`` to the output
    time of index ``stop``: the statistics' means and their variances (jackknife), (S, T')."""
    from stochpend.engine import runner

    n_b, _ = _batches(n)
    c = replace(_truncated(cfg, stop + 1), h_max=float(h), step_c=0.0, seed=seed, paths=n, n_batches=n_b)
    ens, path_steps = runner.run_batches(c, 0, n_b, backend=backend)
    f, f_var = _jackknife(ens.sums, lambda m: _st(of(m)))
    return Ensemble(seed, float(h), n, stop, f, f_var, int(path_steps), int(ens.sums[:, -1, power_sums.S_NONFINITE].sum()))


def _certify_by_independent_runs(cfg: SimulationConfig, target: Target, st: State, nonfinite: int,
                                 room: float, of: Callable[[np.ndarray], np.ndarray], backend: str,
                                 note: Any, journal: Journal, *,
                                 seconds_for: Callable[[float], float] = lambda _steps: math.nan) -> Route | None:
    """Issue 35, item 3: each time that the levels could not certify and for which two
    independent ensembles at h_k and h_k/2 are the cheaper route (:func:`_cost_independent`) is
    run that way while the route fits in ``room`` path-steps: N paths at each step, the finer
    ensemble the estimate with its half-width, the bias bound (|d| + z_b se_d)/(2^alpha - 1) from
    their difference d. As the levels' plan, approached from below: the first N is planned for
    |P| two standard errors up (the pilot's few hundred samples say little of a late time), then
    up to :data:`ROUTE_ROUNDS` rounds top both ensembles up to the N the measured variances,
    mean and difference ask for. Seeds ``SeedSequence(seed, spawn_key=(35, 1000 + j, 64 t +
    round))``, j = 0, 1 the two steps: independent of the levels, of each other and across rounds.
    ``seconds_for``: the expected seconds of a number of path-steps, for the notes."""
    eps, conf = target.error, target.confidence
    v = _verdict(st, eps, conf, nonfinite, cfg.h_max)
    S, T = st.estimate.shape
    route = Route(np.zeros((S, T), bool), np.full((S, T), np.nan), np.full((S, T), np.nan),
                  np.full((S, T), np.nan))
    z = float(_quantile((1.0 - conf) / 2.0))
    z_b = float(_quantile((1.0 - conf) / 4.0))
    seeds: list[int] = []
    eligible = [t for t in range(T) if np.any(v.independent[:, t])]
    if eligible:  # said first: a late time's route may take far longer than the levels did
        least = sum(float(np.max(v.cost[v.independent[:, t], t])) for t in eligible)
        note(f"target: {len(eligible)} time(s) from t = {cfg.times[eligible[0]]:g} to be certified by "
             f"independent runs: at least {least:.3g} path-steps{_about(seconds_for(least))}")
    for t in range(T):
        todo = v.independent[:, t]
        if not np.any(todo):
            continue
        k = int(np.max(v.route_k[todo, t]))
        h = cfg.h_max * 0.5**k
        shrink = 2.0 ** st.alpha_used[todo, t] - 1.0
        per_path = 3.0 * float(st.C[0, t]) * 2.0**k  # a path at h_k and one at h_k/2
        P_hi = np.abs(st.estimate[todo, t]) + 2.0 * np.sqrt(np.maximum(st.stat_var[todo, t], 0.0))
        lead = (z + z_b * math.sqrt(2.0) / shrink) * np.sqrt(np.maximum(st.V[0, todo, t], 0.0))
        with np.errstate(invalid="ignore", divide="ignore"):
            want = np.ceil((lead / (eps * P_hi)) ** 2)
        n_plan = int(np.nanmax(want)) if np.any(np.isfinite(want)) else 0
        if float(np.max(v.cost[todo, t])) > room:  # even the least the route may cost: none of it
            note(f"target: t = {cfg.times[t]:g} left uncertified: its independent runs need at least "
                 f"{float(np.max(v.cost[todo, t])):.3g} path-steps, over what the limit leaves ({room:.3g})")
            continue
        parts: list[list[tuple[int, np.ndarray, np.ndarray]]] = [[], []]
        n_done = 0
        for round_ in range(ROUTE_ROUNDS):
            n_more = max(n_plan - n_done, 0)
            if n_more == 0 or n_more * per_path > room:
                if n_more:
                    note(f"target: t = {cfg.times[t]:g}: the independent runs need about "
                         f"{n_more * per_path:.3g} more path-steps than the limit leaves")
                break
            note(f"target: t = {cfg.times[t]:g} by two independent runs at h = {h:.3g}, {h / 2:.3g}: "
                 f"{n_more} more paths each ({n_more * per_path:.3g} path-steps{_about(seconds_for(n_more * per_path))})")
            for j, hh in enumerate((h, 0.5 * h)):
                seed = level_seed(cfg.seed, 1000 + j, 64 * t + round_)
                seeds.append(seed)
                e = journal.ensemble(seed, float(hh), n_more, t,
                                     partial(_ensemble, cfg, hh, n_more, seed, t, of, backend))
                parts[j].append((n_more, e.f[:, t], e.f_var[:, t]))
                route.path_steps += e.path_steps
                route.nonfinite += e.nonfinite
                room -= e.path_steps
            n_done += n_more
            (mc, vc), (mf, vf) = (_pooled(p) for p in parts)
            d = mc - mf
            half = z * np.sqrt(vf)
            bound = (np.abs(d) + z_b * np.sqrt(vc + vf)) / (2.0 ** st.alpha_used[:, t] - 1.0)
            route.ran[todo, t] = True
            route.estimate[:, t] = np.where(todo, mf, np.nan)
            route.half[:, t] = np.where(todo, half, np.nan)
            route.bound[:, t] = np.where(todo, bound, np.nan)
            if np.all((half + bound)[todo] <= eps * np.abs(mf[todo])):
                break
            # the N the measured numbers ask for (per-path variances n var), at least 1.2 N
            with np.errstate(invalid="ignore", divide="ignore"):
                Vf, Vc = vf * n_done, vc * n_done
                room_e = eps * np.abs(mf) - np.abs(d) / (2.0 ** st.alpha_used[:, t] - 1.0)
                need = ((z * np.sqrt(Vf) + z_b * np.sqrt(Vf + Vc) / (2.0 ** st.alpha_used[:, t] - 1.0))
                        / room_e) ** 2
            need = np.where(todo & (room_e > 0), need, np.nan)
            if not np.any(np.isfinite(need)):
                break  # the bias alone is beyond the target at this step: no N certifies it
            n_plan = max(int(math.ceil(float(np.nanmax(need)))), int(1.2 * n_done))
    route.seeds = tuple(seeds)
    return route if np.any(route.ran) else None


def _pooled(parts: list[tuple[int, np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Rounds of one ensemble pooled: the mean weighted by paths, the variance of that mean."""
    n = sum(p[0] for p in parts)
    mean = sum(p[0] * p[1] for p in parts) / n
    var = sum((p[0] / n) ** 2 * p[2] for p in parts)
    return np.asarray(mean), np.asarray(var)


def _dataset(config: SimulationConfig, cfg: SimulationConfig, target: Target, levels: list[Level],
             st: State, spent: int, wall: float, compile_s: float, backend: str,
             route: Route | None = None) -> xr.Dataset:
    import xarray as xr

    from stochpend.runs.lifecycle import provenance

    eps, conf = target.error, target.confidence
    nonfinite = sum(lv.nonfinite for lv in levels)
    v = _verdict(st, eps, conf, nonfinite, cfg.h_max)
    estimate, half, bound = st.estimate.copy(), v.half.copy(), st.bias_bound.copy()
    by_route = np.zeros(estimate.shape, dtype=bool)
    if route is not None:  # the times the independent ensembles certified, or tried to
        by_route = route.ran
        estimate = np.where(by_route, route.estimate, estimate)
        half = np.where(by_route, route.half, half)
        bound = np.where(by_route, route.bound, bound)
        nonfinite += route.nonfinite
    total = half + bound
    with np.errstate(invalid="ignore", divide="ignore"):
        rel = total / np.abs(estimate)
    certified = np.where(by_route, (rel <= eps) & np.isfinite(bound) & (route is not None and route.nonfinite == 0),
                         v.certified)
    cost = np.where(certified, np.nan, v.cost)
    route_h = np.where(certified | ~np.isfinite(cost), np.nan, v.route_h)
    L = len(levels) - 1
    data: dict[str, Any] = {}
    for s, name in enumerate(target.statistics):
        data[name] = ("time", estimate[s], {"long_name": f"{name}, multilevel estimate (telescope), or where "
                                            f"{name}_route is 1 the finer of two independent ensembles"})
        data[f"{name}_route"] = ("time", by_route[s].astype(np.int8), {
            "long_name": "0: the multilevel estimate; 1: two independent ensembles at h and h/2, the "
                         "finer the estimate, their difference the bias bound"})
        data[f"{name}_stat_error"] = ("time", half[s], {
            "long_name": f"statistical half-width of {name} at confidence 1 - (1 - c)/2 (Student t, "
                         "Satterthwaite dof)"})
        data[f"{name}_bias_bound"] = ("time", bound[s], {
            "long_name": f"bound on |discretisation bias| of {name} at the finest level, at "
                         "confidence 1 - (1 - c)/2 (Eq. (bias) of stochpend.runs.multilevel)"})
        data[f"{name}_total_error"] = ("time", total[s], {
            "long_name": f"stat_error + bias_bound of {name}: its total error at confidence c"})
        data[f"{name}_relative_total_error"] = ("time", rel[s], {"long_name": "total_error / |estimate|"})
        data[f"{name}_certified"] = ("time", certified[s].astype(np.int8), {
            "long_name": "1: coupled levels and relative total error <= target; 0: not certified"})
        data[f"{name}_cost_to_certify"] = ("time", cost[s], {
            "long_name": "path-steps the cheaper route would spend in all to certify this time alone: "
                         "this estimator, or two independent ensembles at h and h/2 (see "
                         f"{name}_certify_h) (NaN: certified; inf: no route up to the finest level)"})
        data[f"{name}_certify_h"] = ("time", route_h[s], {
            "long_name": "coarser step h of the two independent ensembles (h, h/2) where that route is "
                         "the cheaper; NaN where the multilevel estimator is (or the time is certified)"})
        data[f"{name}_level_mean"] = (("level", "time"), st.m[:, s], {
            "long_name": f"mean of Y_l = P_l - P_(l-1) for {name} (level 0: P_0)"})
        data[f"{name}_level_variance"] = (("level", "time"), st.V[:, s], {
            "long_name": f"per-sample variance V_l of Y_l for {name}"})
        data[f"{name}_level_decorrelation"] = (("level", "time"), st.decorrelation[:, s], {
            "long_name": "sqrt(1 - r) of the level's pairs (0 coupled, 1 independent)"})
        kurtosis = st.kurtosis if st.kurtosis is not None else np.full_like(st.m, np.nan)
        data[f"{name}_level_kurtosis"] = (("level", "time"), kurtosis[:, s], {
            "long_name": f"kurtosis E[(Y_l - m_l)^4]/V_l^2 of the level's differences for {name} (NaN: "
                         f"level 0; a running sum's variance and diffusion: not measured; the skewness and "
                         f"flatness: of their linearised difference); above {KURTOSIS_WARN:g} the variance "
                         "V_l, and the plan made from it, rest on rare pairs (Giles)"})
        data[f"{name}_consistency"] = (("level", "time"), st.consistency[:, s], {
            "long_name": "|fine mean of level l-1 - coarse mean of level l| in sigma (Giles' check, "
                         f"fails above {CONSISTENCY_SIGMA:g})"})
        data[f"{name}_alpha"] = ("time", st.alpha[s], {"long_name": "fitted weak rate alpha (NaN: "
                                                       "fewer than two resolved levels)"})
        data[f"{name}_alpha_used"] = ("time", st.alpha_used[s], {"long_name": "alpha in the bias bound"})
        data[f"{name}_beta"] = ("time", st.beta[s], {"long_name": "fitted variance rate beta"})
    data["n_samples"] = (("level", "time"), st.N, {
        "long_name": "samples N_l reaching each time (level 0: paths; l >= 1: coupled pairs)"})
    data["cost_per_sample"] = (("level", "time"), st.C, {
        "long_name": "path-steps a sample run to each time (measured rate x time)"})
    data["level_path_steps"] = ("level", np.array([lv.path_steps for lv in levels], dtype=np.int64))
    data["h"] = ("level", cfg.h_max * 0.5 ** np.arange(L + 1), {"long_name": "fine step h_l"})
    import numba

    attrs = provenance(cfg, backend=backend, threads=numba.get_num_threads(), wall_time_s=wall - compile_s,
                       path_steps=spent)
    attrs.pop("paths", None)
    fails = int(np.count_nonzero(st.consistency > CONSISTENCY_SIGMA))
    attrs.update({
        "title": "stochpend multilevel estimate to a total-error target",
        "target_error": eps,
        "target_confidence": conf,
        "target_statistics": ",".join(target.statistics),
        "target_method": "multilevel Monte Carlo on coupled levels, fixed steps h_max/2**l "
                         "(stochpend.runs.multilevel; docs/numerics.md)",
        "target_levels": L + 1,
        "target_gamma": st.gamma,
        "target_certified": int(np.count_nonzero(certified)),
        "target_entries": int(certified.size),
        "target_consistency_failures": fails,
        "target_nonfinite_paths": nonfinite,
        "target_level_seeds": ";".join(",".join(str(r.seed) for r in lv.rounds) for lv in levels),
        "target_route_path_steps": 0 if route is None else route.path_steps,
        "target_route_seeds": "" if route is None else ",".join(str(x) for x in route.seeds),
        "target_seeds": f"SeedSequence(seed, spawn_key=({SPAWN}, level, round))",
        "compile_time_s": compile_s,
        "total_wall_time_s": wall,
    })
    return xr.Dataset(data, coords={"time": target.times, "level": np.arange(L + 1)}, attrs=attrs)



def _labels(names: list[str]) -> dict[str, str]:
    """Each statistic's name as the table prints it: a file's text, so control characters are
    written as visible escapes and a name longer than a statistic's (64) is shortened
    (:mod:`stochpend.text._terminal`)."""
    from stochpend.text._terminal import plain, short

    return {name: plain(short(name, 64)) for name in names}


def _certify_text(ds: Any, name: str, i: int) -> str:
    """What certifying an uncertified entry would take, and by which route."""
    cost = float(ds[f"{name}_cost_to_certify"].values[i])
    h = float(ds[f"{name}_certify_h"].values[i]) if f"{name}_certify_h" in ds else math.nan
    if not math.isfinite(cost):
        return "not certified; no route up to the finest level meets the target"
    if math.isfinite(h):
        return (f"not certified; certifying takes at least {cost:.3g} path-steps (two "
                f"independent runs at h = {h:.3g} and {h / 2:.3g})")
    return f"not certified; certifying takes about {cost:.3g} path-steps (this multilevel estimator)"


def summary_lines(ds: Any) -> list[str]:
    """The table of a target result: per statistic and time the estimate, statistical error,
    bias bound, total and whether it is certified; then the cost (stdout lines)."""
    names = [n for n in str(ds.attrs.get("target_statistics", "")).split(",") if n and n in ds]
    eps = float(ds.attrs.get("target_error", math.nan))
    label = _labels(names)
    conf = float(ds.attrs.get("target_confidence", math.nan))
    lines = [f"target: relative total error {eps:g} at {100 * conf:g} % confidence, "
             f"{int(ds.attrs.get('target_levels', 0))} levels"]
    # Each column as wide as its header and values (at least the widths a table of the
    # built-in statistics has): an accumulator's or an observable's longer name still fits 80
    # columns.
    header = ("statistic", "t", "estimate", "stat err", "bias bound", "total", "rel")
    rows: list[tuple[str, ...]] = []
    notes = []
    for name in names:
        for i, t in enumerate(ds.time.values):
            cert = int(ds[f"{name}_certified"].values[i])
            if not cert:
                notes += textwrap.wrap(f"{label[name]} at t = {t:.4g}: {_certify_text(ds, name, i)}", 78,
                                       initial_indent="  ", subsequent_indent="    ", break_on_hyphens=False)
            rows.append((label[name], f"{t:.4g}", f"{float(ds[name].values[i]):.6g}",
                         f"{float(ds[f'{name}_stat_error'].values[i]):.3g}",
                         f"{float(ds[f'{name}_bias_bound'].values[i]):.3g}",
                         f"{float(ds[f'{name}_total_error'].values[i]):.3g}",
                         f"{float(ds[f'{name}_relative_total_error'].values[i]):.2e}", "yes" if cert else "no"))
    widths = [max(len(header[c]), *(len(r[c]) for r in rows)) for c in range(len(header))]
    lines.append(" ".join([header[0].ljust(widths[0]), *(h.rjust(w) for h, w in zip(header[1:], widths[1:],
                                                                                      strict=True))]) + "  cert")
    lines += [" ".join([r[0].ljust(widths[0]), *(v.rjust(w) for v, w in zip(r[1:-1], widths[1:], strict=True))])
              + f"  {r[-1]}" for r in rows]
    n_s = np.asarray(ds["n_samples"].values).reshape(len(ds["level"]), -1)
    first, last = (", ".join(str(int(v)) for v in n_s[:, k]) for k in (0, -1))
    compiling = float(ds.attrs.get("compile_time_s", 0.0) or 0.0)
    lines += notes
    lines.append(f"cost: {float(ds.attrs.get('path_steps', math.nan)):.4g} path-steps, "
                 f"{float(ds.attrs.get('wall_time_s', math.nan)):.3g} s"
                 + (f" (+ {compiling:.3g} s compiling)" if compiling > 0 else ""))
    lines += textwrap.wrap(f"samples per level: {first} at the first time, {last} at the last", 78,
                           subsequent_indent="  ")
    worst = [(float(np.nanmax(ds[f"{name}_level_kurtosis"].values)), name) for name in names
             if f"{name}_level_kurtosis" in ds and np.any(np.isfinite(ds[f"{name}_level_kurtosis"].values))]
    if worst:
        k, name = max(worst)
        lines += textwrap.wrap(f"kurtosis of the level differences: at most {k:.3g} ({label[name]})"
                               + (f", above {KURTOSIS_WARN:g}: the levels' variances rest on rare pairs"
                                  if k > KURTOSIS_WARN else ""), 78, subsequent_indent="  ")
    fails = int(ds.attrs.get("target_consistency_failures", 0))
    if fails:
        lines.append(f"consistency check: {fails} (level, statistic, time) entries beyond "
                     f"{CONSISTENCY_SIGMA:g} sigma (the telescope's levels disagree in law there)")
    return lines + level_lines(ds, names)


def level_lines(ds: Any, names: list[str]) -> list[str]:
    """The levels of a target result at its last output time, as Giles' MLMC drivers print
    them: per statistic its fitted rates alpha (weak) and beta (variance), then per level l the
    fine step h_l, the samples N_l, the path-steps a sample costs, the mean and variance of Y_l
    = P_l - P_(l-1) (Y_0 = P_0), its kurtosis, the pairs' decorrelation sqrt(1 - r) and the
    consistency check in sigma (a block per statistic, so that a long name does not widen the
    rows past 80 columns). Values the run could not measure are '-'; no lines for a file that
    lacks them (one written before they were recorded)."""
    parts = ("level_mean", "level_variance", "level_kurtosis", "level_decorrelation", "consistency", "alpha",
             "alpha_used", "beta")
    if not names or any(f"{name}_{part}" not in ds for name in names for part in parts) \
            or any(v not in ds for v in ("n_samples", "cost_per_sample", "h")):
        return []
    label = _labels(names)
    j = len(ds.time.values) - 1
    t = float(ds.time.values[j])
    n_s = np.asarray(ds["n_samples"].values).reshape(len(ds["level"]), -1)[:, j]
    cost = np.asarray(ds["cost_per_sample"].values).reshape(len(ds["level"]), -1)[:, j]
    steps = np.asarray(ds["h"].values)

    def num(value: float, spec: str) -> str:
        return format(value, spec) if math.isfinite(value) else "-"

    header = ("l", "h_l", "N_l", "cost", "mean Y_l", "var Y_l", "kurt", "decor", "check")
    blocks: list[tuple[str, list[tuple[str, ...]]]] = []
    for name in names:
        columns = [np.asarray(ds[f"{name}_{part}"].values)[:, j]
                   for part in ("level_mean", "level_variance", "level_kurtosis", "level_decorrelation",
                                "consistency")]
        rows: list[tuple[str, ...]] = []
        for level in range(len(steps)):
            m, v, k, d, c = (float(col[level]) for col in columns)
            rows.append((str(level), f"{float(steps[level]):.4g}", str(int(n_s[level])),
                         num(float(cost[level]), ".4g"), num(m, ".3g"), num(v, ".3g"), num(k, ".3g"),
                         num(d, ".2g"), num(c, ".2g")))
        alpha, used, beta = (float(ds[f"{name}_{rate}"].values[j]) for rate in ("alpha", "alpha_used", "beta"))
        blocks.append((f"{label[name]}: alpha {num(alpha, '.3g')} (bias bound with {num(used, '.3g')}), "
                       f"beta {num(beta, '.3g')}", rows))
    widths = [max(len(header[c]), *(len(r[c]) for _, rows in blocks for r in rows)) for c in range(len(header))]
    lines = textwrap.wrap(f"levels at t = {t:.4g} (Y_l = P_l - P_(l-1), Y_0 = P_0; cost: path-steps a sample; "
                          f"check: Giles' consistency in sigma, fails above {CONSISTENCY_SIGMA:g}; gamma "
                          f"{num(float(ds.attrs.get('target_gamma', math.nan)), '.3g')}):", 78,
                          subsequent_indent="  ")
    lines.append("  " + " ".join(h.rjust(w) for h, w in zip(header, widths, strict=True)))
    for title, block in blocks:
        lines += textwrap.wrap(title, 78, subsequent_indent="  ")
        lines += ["  " + " ".join(v.rjust(w) for v, w in zip(r, widths, strict=True)) for r in block]
    routed = [label[name] for name in names if f"{name}_route" in ds and int(ds[f"{name}_route"].values[j]) == 1]
    if routed:
        lines += textwrap.wrap(f"at t = {t:.4g} the estimate of {', '.join(routed)} is two independent runs' "
                               "(their pairs decorrelate there), not these levels'", 78, subsequent_indent="  ")
    return lines


def is_target_result(ds: Any) -> bool:
    """Whether ``ds`` is a :func:`target_run` result."""
    return "target_error" in getattr(ds, "attrs", {}) and "n_samples" in ds
