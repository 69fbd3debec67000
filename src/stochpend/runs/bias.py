"""The discretisation bias of every statistic, estimated from coupled coarse/fine paths.

A statistic A computed with the step control (h_max, c) differs from its zero-step limit A_0 by
the weak error of the scheme, A_h - A_0 = K h**2 + o(h**2) (weak order 2, measured in
tests/statistical). Halving every step gives A_{h/2} - A_0 = K h**2/4 + ..., hence the
Richardson (Talay-Tubaro) estimate

    bias(A_h) = A_h - A_0 ~= (4/3) (A_h - A_{h/2}).

The difference A_h - A_{h/2} is estimated on a subsample of *coupled pairs*
(:func:`stochpend.engine.integrator.Integrator.advance_pair`): a coarse path, which takes exactly the
steps an ordinary path of the run would take (its own step control, landing, noise events), and
a fine path that takes each of those steps as two half steps, both driven by one realization of
the noise (the half steps draw it; the coarse kick uses the exact integral over the whole step,
the sum of the halves). The law of the coarse member is the run's; the difference of the two
members is O(h) path by path, so the difference of the two averages has a far smaller variance
than either (multilevel Monte Carlo's coupling, Giles 2008, on two levels). Its error bar is the
delete-one-batch jackknife over the subsample's batches, like every other error bar here.

The pairs are global paths ``BIAS_PATH0 + i`` of the run's seed: streams disjoint from the
run's own paths (which are below 2**63), so the estimate is independent of the run's values,
and a fixed function of (seed, configuration, subsample size), whatever the threads or chunks.

What this does not see: terms of the weak error beyond h**2 (the estimate is the leading
term; docs/numerics.md shows it against brute-force refinement), and the fine member's steps
are the coarse member's halves rather than the step control's own choice at half c and half
h_max (the same leading term: the two step sequences differ by O(h) along a path).
"""

from __future__ import annotations

import math
import time as _time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

# The kernels' modules (Numba, seconds to import) load where an estimate runs: reading a
# result's verdicts (assess_dataset, warnings_for, summary_line; 'stochpend show') needs NumPy only.
from stochpend.model import observables, power_sums
from stochpend.model.power_sums import STATISTICS
from stochpend.text.progress import NoProgress, Progress

if TYPE_CHECKING:  # pragma: no cover
    from stochpend.engine.integrator import KernelSpec
    from stochpend.model.settings import SimulationConfig
    from stochpend.numerics._jitcache import CompileClock

__all__ = ["BIAS_PATH0", "Assessment", "BiasEstimate", "RICHARDSON", "assess", "assess_dataset",
           "default_bias_paths", "estimate", "summary_line", "warnings_for"]

#: Global index of the first coupled pair: the run's own paths are below it (the coupled
#: levels' streams, ``stochpend.numerics.rng.COUPLED_PATH0``).
BIAS_PATH0 = 1 << 63
#: bias = RICHARDSON * (coarse - fine) for a scheme of weak order 2 and fine = coarse/2.
RICHARDSON = 4.0 / 3.0
#: Batches of the subsample (the jackknife's units).
BIAS_BATCHES = 32
#: Pairs advanced together (memory: about 90 bytes a pair).
CHUNK_PAIRS = 1 << 18

#: Statistics whose bias ``accuracy="auto"`` controls (declared in stochpend.observables: every
#: moment of E and Omega and the two shape ratios).
CONTROLLED = tuple(s.name for s in observables.STATISTICS if s.controlled)
#: Family-wise false-alarm probability of the bias verdicts: the chance that a run whose
#: every bias is zero has *any* (statistic, time) called significant (Bonferroni over them all).
FAMILY_ALPHA = 0.05
#: The verdict of one (statistic, time), stored in ``<name>_bias_verdict``.
CERTIFIED_SMALL, SIGNIFICANT, INCONCLUSIVE = 0, 1, 2
VERDICT_MEANINGS = "certified_small significant inconclusive"
#: The pairs count as decorrelated where the estimate's error is above half what independent
#: coarse and fine ensembles of the same size would give: ``bias_pair_decorrelation`` =
#: sqrt(1 - r) > 1/2, r the coarse/fine correlation (r < 3/4).
DECORRELATED = 0.5
#: ``accuracy="auto"`` refines at most this many times (2**6 = 64 times the steps).
MAX_LEVEL = 6
ACCURACIES = ("fixed", "auto")


#: The default subsample is a 48th of the run (at least MIN_PAIRS): a pair costs about three
#: path-steps (one coarse, two fine half steps) for each step of a path, in the same SIMD lanes,
#: so about 6 % of the run's path-steps. What it resolves: while the pairs stay coupled the
#: estimate's error is about (4/3) sqrt(2 paths/pairs) sqrt(1 - r) = 13 sqrt(1 - r) standard
#: errors of the run (r the coarse/fine correlation), so it certifies |bias| < SE/2 wherever
#: sqrt(1 - r) < 0.008 or so; more pairs buy little (the error shrinks as the square root), and
#: beyond the horizon (r < 3/4) even pairs = paths could not certify (docs/numerics.md).
PAIRS_FRACTION = 48
MIN_PAIRS = 64


def default_bias_paths(paths: int) -> int:
    """The subsample size when none is given: ``paths // PAIRS_FRACTION``, at least
    ``MIN_PAIRS`` (two a jackknife batch), at most the run itself."""
    return int(max(2, min(paths, max(MIN_PAIRS, paths // PAIRS_FRACTION))))


def check_bias_paths(bias_paths: Any, paths: int) -> int:
    """The number of pairs to use: ``None`` gives the default, 0 none; else an integer >= 2."""
    if bias_paths is None:
        return default_bias_paths(paths)
    if (isinstance(bias_paths, bool) or not isinstance(bias_paths, (int, np.integer))
            or (bias_paths != 0 and bias_paths < 2) or bias_paths > 1 << 40):
        raise ValueError(f"bias_paths={bias_paths!r} is not accepted: an integer >= 2 (coupled "
                         "pairs for the bias estimate), or 0 for no estimate")
    return int(bias_paths)


def check_accuracy(accuracy: Any, rtol: Any) -> tuple[str, float | None]:
    """Validate ``accuracy`` and ``rtol`` (which implies ``auto``)."""
    if accuracy not in ACCURACIES:
        raise ValueError(f"accuracy={accuracy!r} is not accepted: one of {', '.join(ACCURACIES)}")
    if rtol is None:
        return accuracy, None
    try:
        r = float(rtol)
    except (TypeError, ValueError):
        r = math.nan
    if isinstance(rtol, bool) or not (0.0 < r < 1.0):
        raise ValueError(f"rtol={rtol!r} is not accepted: a number in (0, 1), the accepted bias "
                         "as a fraction of each statistic")
    return "auto", r


# -- kernels ------------------------------------------------------------------------------------
def pair_spec(config: SimulationConfig, backend: str = "cpu") -> KernelSpec:
    """The KernelSpec the pairs run with: the run's own kernel on ``backend`` (``spec_for`` of
    :mod:`stochpend.engine.cpu` or ``.cuda``), so the coarse member has the law of the run's
    paths, and on the CPU the pairs run in SIMD lanes with the run's fast math wherever the run
    does. Always float64, also for a float32 GPU run: in float32 the difference of the members
    would chase the rounding floor (eps_32 ~ 1e-7 a step, amplified by the dynamics) rather than
    the step's bias; the estimate is then that of the float64 scheme at the run's steps."""
    from stochpend.engine import runner

    return runner.spec_for(config, backend, "float64")


# -- the estimate -------------------------------------------------------------------------------
@dataclass
class BiasEstimate:
    """The estimated bias of each statistic at each output time, with its jackknife error.

    ``bias[name] = (value, stderr)``, arrays of shape (n_times,); ``coarse[name]`` the coarse
    members' statistic and its error (what the run itself would give with this many paths);
    ``paths`` the pairs used, ``path_steps`` the steps both members took (fine half steps
    counted as steps), ``wall_time_s`` the estimate's cost, ``batches`` the jackknife's.
    """

    times: np.ndarray
    bias: dict[str, tuple[np.ndarray, np.ndarray]]
    coarse: dict[str, tuple[np.ndarray, np.ndarray]]
    paths: int
    path_steps: int
    wall_time_s: float
    nonfinite: np.ndarray
    h_max: float
    step_c: float
    batches: int = BIAS_BATCHES
    #: sqrt(1 - r) of the pairs at each output time (:func:`_decorrelation`).
    decorrelation: np.ndarray | None = None

    def data_vars(self) -> dict[str, tuple]:
        """``<name>_bias`` and ``<name>_bias_stderr`` for the result Dataset."""
        out: dict[str, tuple] = {}
        for name, (value, se) in self.bias.items():
            out[f"{name}_bias"] = ("time", value, {
                "long_name": f"estimated discretisation bias of {name}: its value minus the "
                             "zero-step limit (Richardson, weak order 2, coupled half-step pairs)"})
            out[f"{name}_bias_stderr"] = ("time", se, {
                "long_name": f"standard error of {name}_bias (jackknife over the pairs' batches)"})
        out["bias_pair_decorrelation"] = ("time", self.decorrelation, {
            "long_name": "sqrt(1 - r), r the coupled pairs' coarse/fine correlation: 0 coupled, "
                         f"1 independent; beyond {DECORRELATED:g} the pairs have decorrelated"})
        return out

    def attrs(self) -> dict[str, Any]:
        return {
            "bias_method": "richardson-coupled-half-step (bias = 4/3 (coarse - fine), "
                           "docs/numerics.md)",
            "bias_paths": self.paths,
            "bias_path_steps": self.path_steps,
            "bias_wall_time_s": self.wall_time_s,
            "bias_nonfinite_pairs": int(self.nonfinite[-1]) if self.nonfinite.size else 0,
            "bias_batches": self.batches,
        }


def estimate(config: SimulationConfig, n_paths: int, *, progress: Progress | None = None,
             chunk_pairs: int = CHUNK_PAIRS, backend: str = "cpu") -> BiasEstimate:
    """Estimate the bias of ``config``'s statistics from ``n_paths`` coupled pairs, in float64,
    on the run's ``backend``: the CPU's SIMD lanes (or one pair at a time where the run goes one
    path at a time), or one GPU thread per pair (``"cuda"``), with the run's own KernelSpec.

    The numbers depend on (config, n_paths, backend) only: not on ``chunk_pairs`` or the threads.
    """
    if isinstance(n_paths, bool) or not isinstance(n_paths, int) or n_paths < 2:
        raise ValueError(f"bias_paths={n_paths!r} is not accepted: an integer >= 2 (or 0: no "
                         "bias estimate)")
    progress = progress or NoProgress()
    from stochpend.numerics._jitcache import CompileClock

    with CompileClock() as compile_clock:  # bias_wall_time_s leaves compiling out
        return _estimate(config, n_paths, progress, chunk_pairs, backend, compile_clock)


def _estimate(config: SimulationConfig, n_paths: int, progress: Progress, chunk_pairs: int,
              backend: str, compile_clock: CompileClock) -> BiasEstimate:
    started = _time.perf_counter()
    batch_size = -(-n_paths // min(BIAS_BATCHES, n_paths))
    n_batches = -(-n_paths // batch_size)  # the batches that hold pairs
    sums, path_steps = pair_sums(config, n_paths, n_batches, backend=backend, progress=progress,
                                 chunk_pairs=chunk_pairs)
    bias, coarse = _statistics(sums, observables.STATISTICS + observables.user_statistics(config.observables))
    nonfinite = sums[:, :, 0, power_sums.S_NONFINITE].sum(axis=0).astype(np.int64)
    return BiasEstimate(np.asarray(config.times, dtype=np.float64), bias, coarse, n_paths, path_steps,
                        _time.perf_counter() - started - compile_clock.seconds, nonfinite, config.h_max,
                        config.step_c, n_batches, _decorrelation(bias, coarse, len(config.times)))


def pair_sums(config: SimulationConfig, n_pairs: int, n_batches: int, *, backend: str = "cpu",
              progress: Progress | None = None, chunk_pairs: int = CHUNK_PAIRS,
              what: str = "bias estimate", differences: np.ndarray | None = None,
              products: bool = False, tracked: bool = False) -> tuple[np.ndarray, int]:
    """The coarse and fine members' per-batch sums, shape (n_batches, n_times, 2, n_sums)
    (member 0 coarse, 1 fine; batches of ceil(n_pairs / n_batches) pairs), of ``n_pairs``
    coupled pairs of ``config`` (pairs ``BIAS_PATH0 + i`` of its seed), and the path-steps they
    took, for the bias estimate and the multilevel target's levels
    (:mod:`stochpend.runs.multilevel`): the runner's host loop (``runner.run_batches`` with 2
    levels, the backend's ``LevelEngine``), with :func:`pair_spec`;
    the numbers do not depend on ``chunk_pairs`` or the threads. ``what``: the progress bar's
    label. ``differences``: (n_times, 4, n_sums) float64, where the raw power sums of the
    members' differences are added (``cpu.difference_kernel``; the kurtosis of a level's
    differences), from the host arrays on every backend; with ``products``, (n_times, 4, n_sums
    + power_sums.product_columns(observables)), the products of those of E^2, E^3, E^4 and of
    each running sum's two columns after them. ``tracked``: each
    member carries the run's per-path accumulators (the multilevel target on an accumulator's
    mean; without it their columns are 0)."""
    from stochpend.engine import runner

    pairs = replace(config, paths=n_pairs, n_batches=n_batches)
    acc, draws = runner.run_batches(pairs, 0, n_batches, backend=backend, precision="float64",  # pair_spec
                                    chunk_paths=chunk_pairs, progress=progress, levels=2,
                                    differences=0 if differences is None else 2 if products else 1,
                                    tracked=tracked, what=what)
    if differences is not None:
        differences += acc.differences
    # A coarse step is one draw, each fine half step one: draws count the fine steps, and
    # the coarse steps are half as many.
    return acc.sums, draws + draws // 2


def _decorrelation(bias: dict[str, tuple[np.ndarray, np.ndarray]],
                   coarse: dict[str, tuple[np.ndarray, np.ndarray]], n_times: int) -> np.ndarray:
    """sqrt(1 - r) of the coupled pairs at each output time (r the coarse/fine correlation): 0
    for members that move together, 1 for independent ones. Measured as the bias's error over
    what independent members would give, (4/3) sqrt(2) times the coarse member's error; the
    median over the statistics (they decorrelate together, and the median is not led by one
    noisy ratio). Shape (n_times,)."""
    ratios = []
    with np.errstate(invalid="ignore", divide="ignore"):
        for name, (_, b_se) in bias.items():
            if name not in STATISTICS:
                continue  # a user observable: the horizon is the dynamics', the table's statistics
            ratios.append(b_se / (RICHARDSON * math.sqrt(2.0) * coarse[name][1]))
    r = np.array(ratios).reshape(len(ratios), n_times)
    out = np.full(n_times, np.nan)
    ok = np.isfinite(r)
    for j in range(n_times):
        if np.any(ok[:, j]):
            out[j] = float(np.median(r[ok[:, j], j]))
    return out


def _statistics(sums: np.ndarray, statistics: Sequence[observables.Statistic]):
    """(bias, coarse): each statistic's RICHARDSON * (coarse - fine) and the coarse value, with
    delete-one-batch jackknife errors. ``sums``: (n_batches, n_times, 2, n_sums) (the table's
    columns, then the user observables')."""
    n_b = sums.shape[0]
    total = sums.sum(axis=0)
    loo = total[None] - sums

    def means(s: np.ndarray) -> np.ndarray:
        count = s[..., power_sums.S_COUNT]
        return s / np.where(count > 0, count, np.nan)[..., None]

    m_all = means(total)
    m_loo = means(loo)
    bias: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    coarse: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    with np.errstate(invalid="ignore", divide="ignore"):
        for statistic in statistics:
            name, f = statistic.name, statistic.of
            if not statistic.richardson:  # a per-path accumulator: no estimate (see Statistic)
                nan = np.full(m_all.shape[:-2], np.nan)
                bias[name] = (nan, nan.copy())
                coarse[name] = (nan.copy(), nan.copy())
                continue
            for out, g in ((bias, lambda m, f=f: RICHARDSON * (f(m[..., 0, :]) - f(m[..., 1, :]))),
                           (coarse, lambda m, f=f: f(m[..., 0, :]))):
                value = g(m_all)
                if n_b >= 2:
                    jk = g(m_loo)
                    dev = jk - jk.mean(axis=0)
                    se = np.sqrt((n_b - 1) / n_b * np.sum(dev * dev, axis=0))
                else:
                    se = np.full_like(value, np.nan)
                out[name] = (value, se)
    return bias, coarse


# -- what the estimate can say ------------------------------------------------------------------
def interval_width(n_tests: int, batches: int, alpha: float = FAMILY_ALPHA) -> float:
    """The half-width, in bias standard errors, of the simultaneous intervals b +- w sigma_b
    over ``n_tests`` (statistic, time) entries: Bonferroni at family-wise level ``alpha``, with
    Student's t of ``batches - 1`` degrees of freedom (the jackknife's error is itself estimated
    from the batches). 32 batches, 40 times x 9 statistics: w = 4.6."""
    # Student's t upper quantile from scipy.special (what scipy.stats.t.isf computes, the same
    # number): importing scipy.stats costs ~0.6 s, a third of a cached run's start.
    from scipy.special import stdtrit

    if n_tests < 1 or batches < 2:
        return math.inf
    return float(-stdtrit(batches - 1, alpha / (2.0 * n_tests)))


@dataclass
class Assessment:
    """What the bias estimate says at every (statistic, output time).

    ``verdict[name]``: int8 array (n_times,) of CERTIFIED_SMALL (|bias| + w sigma_b below half
    the statistic's standard error), SIGNIFICANT (|bias| - w sigma_b above the standard error),
    INCONCLUSIVE (neither: the estimate cannot tell, or the bias lies between SE/2 and SE);
    ``width`` w (:func:`interval_width`) over the ``n_tests`` finite entries examined;
    ``certified_until``: the last output time up to which every entry is resolved (certified
    small or significant), NaN if the first is not; ``horizon``: the first output time at which
    the pairs have decorrelated (``bias_pair_decorrelation`` > DECORRELATED), NaN if none.
    """

    times: np.ndarray
    verdict: dict[str, np.ndarray]
    width: float
    n_tests: int
    certified_until: float
    horizon: float

    def significant(self) -> dict[str, np.ndarray]:
        return {k: v == SIGNIFICANT for k, v in self.verdict.items()}


def assess(times: np.ndarray, bias: dict[str, tuple[np.ndarray, np.ndarray]],
           stderr: dict[str, np.ndarray], batches: int,
           decorrelation: np.ndarray | None = None, known_width: tuple[int, float] | None = None) -> Assessment:
    """The verdicts of an estimate against the run's standard errors (see :class:`Assessment`).

    ``bias[name] = (b, sigma_b)`` and ``stderr[name]``, arrays of shape (n_times,). The family
    is every finite entry: with FAMILY_ALPHA = 0.05, a run whose biases are all zero has a
    significant verdict anywhere with probability at most 5 % (Bonferroni is conservative for
    the strongly correlated output times; calibrated in tests/statistical/test_bias_calibration.py).
    ``known_width``: ``(n_tests, w)`` as :func:`interval_width` gave them for these ``batches``
    (a result file's ``bias_tests`` and ``bias_interval_width``), used where the count matches.
    """
    times = np.asarray(times, dtype=float)
    finite = {}
    n_tests = 0
    for name, (b, b_se) in bias.items():
        ok = np.isfinite(b) & np.isfinite(b_se) & np.isfinite(stderr[name])
        finite[name] = ok
        n_tests += int(np.sum(ok))
    if known_width is not None and known_width[0] == n_tests and known_width[1] > 0:
        w = float(known_width[1])  # the same number, without SciPy (0.4 s of 'stochpend show')
    else:
        w = interval_width(n_tests, batches)
    verdict: dict[str, np.ndarray] = {}
    resolved = np.ones(times.shape, dtype=bool)
    for name, (b, b_se) in bias.items():
        se = np.asarray(stderr[name], dtype=float)
        v = np.full(times.shape, INCONCLUSIVE, dtype=np.int8)
        ok = finite[name]
        with np.errstate(invalid="ignore"):
            v[ok & (np.abs(b) - w * b_se > se)] = SIGNIFICANT
            v[ok & (np.abs(b) + w * b_se < 0.5 * se)] = CERTIFIED_SMALL
        verdict[name] = v
        resolved &= v != INCONCLUSIVE
    bad = np.flatnonzero(~resolved)
    upto = times.size if bad.size == 0 else int(bad[0])
    certified_until = float(times[upto - 1]) if upto > 0 else math.nan
    horizon = math.nan
    if decorrelation is not None:
        with np.errstate(invalid="ignore"):
            gone = np.flatnonzero(np.asarray(decorrelation) > DECORRELATED)
        if gone.size:
            horizon = float(times[gone[0]])
    return Assessment(times, verdict, w, n_tests, certified_until, horizon)


def assess_dataset(ds: Any) -> Assessment | None:
    """:func:`assess` of a result Dataset from its stored variables (None without an
    estimate): what the table, the warnings and ``show`` report, also for files written before
    the verdicts were stored."""
    # The table's statistics, then the run's user observables (named in its attrs).
    user = ds.attrs.get("observables")
    user_names = [f"mean_{u.strip()}" for u in user.split(",") if u.strip()] if isinstance(user, str) else []
    names = [n for n in [*STATISTICS, *user_names] if f"{n}_bias" in ds and f"{n}_stderr" in ds]
    if not names:
        return None
    bias = {n: (np.asarray(ds[f"{n}_bias"].values, dtype=float),
                np.asarray(ds[f"{n}_bias_stderr"].values, dtype=float)) for n in names}
    stderr = {n: np.asarray(ds[f"{n}_stderr"].values, dtype=float) for n in names}
    try:
        batches = int(ds.attrs.get("bias_batches", BIAS_BATCHES))
    except (TypeError, ValueError):
        batches = BIAS_BATCHES
    decorrelation = (np.asarray(ds["bias_pair_decorrelation"].values, dtype=float)
                     if "bias_pair_decorrelation" in ds else None)
    known = None
    try:  # what the run computed for its own batches (attach() stores both)
        if (int(ds.attrs["bias_batches"]) == max(batches, 2)
                and float(ds.attrs["bias_family_alpha"]) == FAMILY_ALPHA):
            known = (int(ds.attrs["bias_tests"]), float(ds.attrs["bias_interval_width"]))
    except (KeyError, TypeError, ValueError):
        pass
    return assess(np.asarray(ds.time.values, dtype=float), bias, stderr, max(batches, 2),
                  decorrelation, known_width=known)


def independent_paths_to_certify(paths: int, width: float) -> int:
    """Paths that each of two *independent* ensembles, at the run's step and at half of it,
    would need to certify |bias| < SE/2 of a run of ``paths`` (the only way beyond the
    horizon): (4/3) sqrt(2/N) sigma w < sigma / (2 sqrt(paths)), N = (8 sqrt(2) w / 3)**2 paths."""
    return int(math.ceil((8.0 * math.sqrt(2.0) * width / 3.0) ** 2 * paths))


@dataclass
class LevelChoice:
    """What ``accuracy="auto"`` decided: the refinement ``level`` (h_max and c divided by
    2**level), the refined ``config``, the ``pilot`` estimate at the given step, the
    ``needed`` ratio (worst (|bias| + error) / target at level 0), whether the target
    was ``reached`` within MAX_LEVEL, and the pilot's ``horizon``."""

    level: int
    config: SimulationConfig
    pilot: BiasEstimate
    needed: float
    reached: bool
    target: str
    #: The first output time at which the pilot's pairs have decorrelated (NaN: none): the
    #: level is chosen from the times before it only, and nothing beyond it is certified.
    horizon: float = math.nan
    #: The ``rtol`` it was chosen for (None: half a standard error).
    rtol: float | None = None

    def extrapolated(self) -> BiasEstimate:
        """The pilot's bias scaled to the chosen level (weak order 2: 4**-level): the run's
        own bias, more precisely than a new estimate at the fine step could give it."""
        f = 0.25**self.level
        bias = {k: (v * f, se * f) for k, (v, se) in self.pilot.bias.items()}
        return replace(self.pilot, bias=bias, h_max=self.config.h_max, step_c=self.config.step_c)


def choose_level(config: SimulationConfig, pilot_paths: int, *, rtol: float | None = None,
                 progress: Progress | None = None, backend: str = "cpu") -> LevelChoice:
    """``accuracy="auto"``: the smallest refinement level L for which every controlled
    statistic's bias, bounded at one sigma by (|b| + se_b) 4**-L from a pilot of coupled pairs
    at the given step, is at most half the run's standard error (predicted from the pilot:
    se sqrt(pilot / paths)), or ``rtol`` |value|, at every output time before the pilot's
    horizon.

    The pilot runs at the coarsest step, where the bias is largest and best resolved; a
    refined level changes the bias by the known factor 4**-L (weak order 2), which the
    validation in docs/numerics.md checks. From the horizon on (the pairs have decorrelated:
    ``bias_pair_decorrelation`` > DECORRELATED) the pilot's error is that of independent
    ensembles, and a level bought there would buy noise: those times are left out of the choice
    and reported as not certified (:func:`independent_paths_to_certify` says what certifying
    them would take). Before it, a poorly resolved pilot makes L larger, never smaller.
    """
    pilot = estimate(config, pilot_paths, progress=progress, backend=backend)
    level, worst, level_se = _needed_level(pilot, config.paths, rtol)
    # A pilot too small to resolve the bias (twice its error alone asks for the level): four
    # times more pairs halve that error; worth it while they cost less than the level they
    # may save (a pair costs about 3 paths at the coarse step, a level doubles the run).
    while (level_se >= level and level >= 2 and 4 * pilot.paths <= config.paths
           and 3 * 4 * pilot.paths < config.paths * 2 ** (level - 1)):
        pilot = estimate(config, 4 * pilot.paths, progress=progress, backend=backend)
        level, worst, level_se = _needed_level(pilot, config.paths, rtol)
    return level_choice(config, pilot, rtol)


def level_choice(config: SimulationConfig, pilot: BiasEstimate, rtol: float | None) -> LevelChoice:
    """The :class:`LevelChoice` that ``pilot`` (coupled pairs at ``config``'s step) gives for a
    run of ``config``: :func:`choose_level`'s last step, and how a resumed run rebuilds the
    choice from the pilot saved in its checkpoint (same numbers, no pilot run again)."""
    level, worst, _ = _needed_level(pilot, config.paths, rtol)
    reached = level <= MAX_LEVEL
    level = min(level, MAX_LEVEL)
    what = f"|bias| <= {rtol:g} |value|" if rtol is not None else "|bias| <= stderr/2"
    return LevelChoice(level, refined(config, level), pilot, worst, reached, what,
                       _horizon(pilot), rtol)


def _horizon(pilot: BiasEstimate) -> float:
    """The first output time at which the pilot's pairs have decorrelated, NaN if none."""
    if pilot.decorrelation is None:
        return math.nan
    with np.errstate(invalid="ignore"):
        gone = np.flatnonzero(pilot.decorrelation > DECORRELATED)
    return float(pilot.times[gone[0]]) if gone.size else math.nan


def _needed_level(pilot: BiasEstimate, paths: int, rtol: float | None) -> tuple[int, float, int]:
    """(L, worst ratio, the L that twice the pilot's error alone asks for), over the output
    times before the pilot's horizon: see :func:`choose_level`."""
    scale = math.sqrt(pilot.paths / paths)
    horizon = _horizon(pilot)
    coupled = pilot.times < horizon if math.isfinite(horizon) else np.ones(pilot.times.shape, bool)
    worst = worst_se = 0.0
    for name in CONTROLLED:
        b, b_se = pilot.bias[name]
        value, se = pilot.coarse[name]
        target = rtol * np.abs(value) if rtol is not None else 0.5 * se * scale
        with np.errstate(invalid="ignore", divide="ignore"):
            r = (np.abs(b) + b_se) / target
            r_se = 2.0 * b_se / target
        ok = np.isfinite(r) & coupled
        if np.any(ok):
            worst = max(worst, float(np.max(r[ok])))
            worst_se = max(worst_se, float(np.max(r_se[ok])))

    def level(x: float) -> int:
        return 0 if x <= 1.0 else math.ceil(math.log(x, 4.0) - 1e-12)

    return level(worst), worst, level(worst_se)


def attach(ds: Any, est: BiasEstimate, choice: LevelChoice | None = None) -> None:
    """Add the estimate's variables, its verdicts (:func:`assess` against the run's standard
    errors) and its attributes to a result Dataset (in place)."""
    # One update per group of variables, not one assignment each: every assignment merges and
    # copies the whole Dataset (a run's some 30 bias variables cost 40 ms that way).
    ds.update(est.data_vars())
    ds.attrs.update(est.attrs())
    verdicts = assess_dataset(ds)
    if verdicts is not None:
        ds.update({f"{name}_bias_verdict": ("time", v, {
            "long_name": f"what {name}_bias says at each time (bias_interval_width sigma "
                         "intervals, family-wise over every statistic and time)",
            "flag_values": np.array([CERTIFIED_SMALL, SIGNIFICANT, INCONCLUSIVE], np.int8),
            "flag_meanings": VERDICT_MEANINGS}) for name, v in verdicts.verdict.items()})
        ds.attrs.update({
            "bias_family_alpha": FAMILY_ALPHA,
            "bias_tests": verdicts.n_tests,
            "bias_interval_width": verdicts.width,
            "bias_certified_until": verdicts.certified_until,
            "bias_horizon": verdicts.horizon,
        })
    if choice is None:
        ds.attrs["accuracy"] = "fixed"
        return
    ds.attrs.update({
        "accuracy": "auto",
        "accuracy_target": choice.target,
        "accuracy_level": choice.level,
        "accuracy_reached": int(choice.reached),
        "accuracy_pilot_h_max": choice.pilot.h_max,
        "accuracy_pilot_step_c": choice.pilot.step_c,
        "accuracy_needed_ratio": choice.needed,
        "accuracy_horizon": choice.horizon,
        "bias_method": ds.attrs["bias_method"] + f"; pilot at h_max={choice.pilot.h_max:g}, "
                       f"c={choice.pilot.step_c:g}, scaled by 4**-{choice.level}",
    })


def refined(config: SimulationConfig, level: int) -> SimulationConfig:
    """``config`` with h_max and c divided by 2**level (the refinement ladder of ``auto``)."""
    factor = 0.5**level
    return replace(config, h_max=config.h_max * factor, step_c=config.step_c * factor)


# -- what the tool says about it ------------------------------------------------------------------
#: Labels of the statistics in warnings and tables.
LABELS = {s.name: s.short for s in observables.STATISTICS}


def warnings_for(ds: Any, fmt: Callable[[float, float], str],
                 shown: Sequence[int] | None = None) -> list[str]:
    """One line per statistic with a *significant* bias somewhere (:func:`assess_dataset`):
    the bias with its error, as a fraction of the value and in standard errors, at the worst
    such time among the output times ``shown`` (indices; all if None), or at the worst time
    with a pointer to it when no shown time has one. ``fmt(value, error)`` writes v(e).
    Nothing is said of inconclusive entries: noise is not a finding."""
    verdicts = assess_dataset(ds)
    if verdicts is None:
        return []
    times = verdicts.times
    shown_set = set(range(times.size) if shown is None else shown)
    lines = []
    for name, v in verdicts.verdict.items():
        hits = np.flatnonzero(v == SIGNIFICANT)
        if hits.size == 0:
            continue
        b = np.asarray(ds[f"{name}_bias"].values, dtype=float)
        b_se = np.asarray(ds[f"{name}_bias_stderr"].values, dtype=float)
        se = np.asarray(ds[f"{name}_stderr"].values, dtype=float)
        value = np.asarray(ds[name].values, dtype=float)
        visible = [i for i in hits if i in shown_set]
        pool = visible or list(hits)
        with np.errstate(invalid="ignore", divide="ignore"):
            # the lowest excess over the standard error; a run without spread (D = 0) has SE 0
            excess = (np.abs(b) - verdicts.width * b_se) / se
            i = max(pool, key=lambda j: excess[j] if np.isfinite(excess[j]) else math.inf)
            frac = abs(b[i] / value[i]) if value[i] != 0 else math.inf
        size = f"{100 * frac:.2g} % of the value, " if math.isfinite(frac) else ""
        where = "" if visible else " (not among the rows shown)"
        n_se = (f"{abs(b[i]) / se[i]:.2g} standard errors" if se[i] > 0
                else "the run has no spread: its standard error is 0")
        lines.append(
            f"{LABELS.get(name, name)} at t={times[i]:.4g}{where}: discretisation bias "
            f"{fmt(float(b[i]), float(b_se[i]))} ({size}{n_se}; "
            f"significant in {hits.size} of {times.size} times at a {100 * FAMILY_ALPHA:g} % "
            f"family-wise level over {verdicts.n_tests} tests): rerun with --accuracy auto "
            "(or a smaller --h-max/--step-c)")
    return lines


def summary_line(ds: Any, paths: int | None = None, shown: Sequence[int] | None = None) -> str | None:
    """One sentence for under a table: how far the estimate certifies the bias, and where the
    pairs decorrelate (None without an estimate). With ``shown`` (the indices of the table's
    rows), a time that is not a row says between which rows it lies (a footer cited t = 11.94
    under a table without that row)."""
    verdicts = assess_dataset(ds)
    if verdicts is None:
        return None
    times = verdicts.times

    def at(t: float) -> str:
        rows = sorted(float(times[i]) for i in shown or () if 0 <= i < len(times))
        if not rows or any(f"{r:.4g}" == f"{t:.4g}" for r in rows):
            return f"t = {t:.4g}"
        before = [r for r in rows if r < t]
        after = [r for r in rows if r > t]
        if before and after:
            return f"t = {t:.4g} (between the rows t = {before[-1]:.4g} and {after[0]:.4g})"
        return f"t = {t:.4g} (not a row shown)"

    until = verdicts.certified_until
    if math.isnan(until):
        head = "bias: inconclusive from the first output time"
    elif until >= times[-1]:
        head = "bias: resolved at every output time (below SE/2 or significant)"
    else:
        head = (f"bias: resolved (below SE/2 or significant) up to {at(until)}, "
                "inconclusive after")
    horizon = verdicts.horizon
    if math.isfinite(horizon):
        n = paths if paths is not None else int(ds.attrs.get("paths", 0) or 0)
        need = independent_paths_to_certify(n, verdicts.width) if n > 0 else None
        head += (f"; the coupled pairs decorrelate from {at(horizon)}, beyond which only "
                 "independent ensembles at two steps could resolve it"
                 + (f" ({need:.2g} paths each)" if need else ""))
    return head + "."
