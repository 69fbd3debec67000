"""The law of a first-passage time from each path's own passage time (issue 23).

A :class:`stochpend.observables.FirstPassage` carries, for every path, the time its value first
reached the threshold (-1 while it has not). At the end of a run the runner keeps these final
per-path values (:func:`final_values`: NaN for a path that went non-finite, which every
statistic excludes), whatever the backend, the chunking, the threads or an interruption: a seed
fixes every number here. From them, :func:`summary` and :func:`variables` give

* the quantiles at the observable's ``probabilities``: the order statistic tau_(r),
  r = ceil(n p), of the n finite paths, the paths not passed by the last output time t_end
  counted as later than every passed one (right-censored). A quantile with r greater than the
  number passed k, i.e. p > k/n, lies beyond t_end: it is NaN (censored), never extrapolated;
* a distribution-free confidence interval of each quantile from the binomial law of the
  number of paths below it: [tau_(l), tau_(u)] with l the Binomial(n, p) (1 - c)/2 quantile and
  u the (1 + c)/2 quantile + 1, which covers the true quantile with probability >= c for any
  continuous law (its lower end 0 when l = 0, its upper end NaN when u > k: censored);
* a histogram of the passage times over [0, t_end] in equal bins, and the number censored.

The step error of a passage time is O(sqrt(h)), not the scheme's O(h^2): a path can cross
and come back within one step unseen, so the detected passage comes late. The coupled-pair
(Richardson) estimate assumes an error in h^2 and does not apply; none is reported. What does
apply, for a value that moves locally as a Brownian motion of variance sigma^2 per unit time,
is Siegmund's boundary correction: the passage detected at the steps of size h has, to o(sqrt(h)),
the law of the continuous passage to the shifted threshold a + beta sigma sqrt(h), beta =
-zeta(1/2)/sqrt(2 pi) = 0.5826 (Siegmund 1979; Broadie, Glasserman & Kou 1997). It is not
applied here (sigma depends on the observable and the state): halve the step to see the shift,
or compare with a law at the shifted threshold, as tests/statistical/test_first_passage.py does.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["CONFIDENCE", "SIEGMUND_BETA", "final_values", "summary", "variables"]

#: Coverage of the quantiles' intervals.
CONFIDENCE = 0.95
#: -zeta(1/2)/sqrt(2 pi): the overshoot of a discretely watched Brownian motion, in sigma sqrt(h).
SIEGMUND_BETA = 0.5825971579390106

STEP_ERROR = ("O(sqrt(h)): a path can cross and come back within a step unseen, so passages are "
              "detected late; the coupled-pair (Richardson) bias estimate does not apply and none is "
              "reported. For a value moving as a Brownian motion of variance sigma^2 per unit time, "
              "the detected passage has the law of the continuous one to the threshold shifted by "
              "0.5826 sigma sqrt(h) (Siegmund's correction, not applied)")


def final_values(tracks: np.ndarray, status: np.ndarray) -> np.ndarray:
    """A chunk's final passage times from its slots ``tracks`` (n_slots, n) and ``status`` (n,):
    the time where passed, -1.0 where not, NaN where the path went non-finite."""
    out = np.array(tracks, dtype=np.float64, copy=True)
    out[:, np.asarray(status) != 0] = np.nan
    return out


def _binom_ppf(q: float, n: int, p: float) -> int:
    """The smallest m in [0, n] with P(Binomial(n, p) <= m) >= q (bisection on scipy's bdtr)."""
    from scipy.special import bdtr

    lo, hi = 0, n
    while lo < hi:
        mid = (lo + hi) // 2
        if bdtr(mid, n, p) >= q:
            hi = mid
        else:
            lo = mid + 1
    return lo


def summary(values: np.ndarray, probabilities: tuple[float, ...], bins: int, t_end: float,
            confidence: float = CONFIDENCE) -> dict[str, Any]:
    """The law of the passage times ``values`` (one per path: the time, -1 not passed, NaN
    excluded) censored at ``t_end``: ``n`` finite paths, ``passed`` k, ``quantile``,
    ``lower``, ``upper`` (arrays over ``probabilities``), ``hist`` (``bins`` counts over
    [0, t_end]), ``edges`` and ``censored`` (n - k). See the module docstring."""
    v = np.asarray(values, dtype=np.float64)
    finite = v[np.isfinite(v)]
    times = np.sort(finite[finite >= 0.0])
    n, k = int(finite.size), int(times.size)
    m = len(probabilities)
    quantile, lower, upper = np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)

    def order(r: int) -> float:  # tau_(r), 1-based; NaN beyond the passed ones (censored)
        return float(times[r - 1]) if 1 <= r <= k else math.nan

    for i, p in enumerate(probabilities):
        if n == 0:
            break
        # ceil(n p), robust to n p landing a rounding error above an integer (1000 * 0.1)
        r = max(1, math.ceil(round(n * p, 9)))
        quantile[i] = order(r)
        lo = _binom_ppf((1.0 - confidence) / 2.0, n, p)
        hi = _binom_ppf((1.0 + confidence) / 2.0, n, p) + 1
        lower[i] = 0.0 if lo == 0 else order(lo)  # a passage time is >= 0
        upper[i] = order(hi)
    edges = np.linspace(0.0, float(t_end), bins + 1)
    if t_end > 0:
        hist, _ = np.histogram(np.minimum(times, edges[-1]), bins=edges)
    else:  # a run whose only output time is 0: every passage is at 0, in the first (empty) bin
        hist = np.zeros(bins, dtype=np.int64)
        hist[0] = k
    return {"n": n, "passed": k, "censored": n - k, "quantile": quantile, "lower": lower, "upper": upper,
            "hist": hist.astype(np.int64), "edges": edges}


def variables(observable: Any, values: np.ndarray, t_end: float, nonfinite: int
              ) -> tuple[dict[str, tuple], dict[str, tuple]]:
    """The Dataset's ``fpt_<name>_...`` variables and coordinates of a
    :class:`~stochpend.observables.FirstPassage` from its final per-path ``values``; ``nonfinite``
    paths are excluded."""
    name = observable.name
    s = summary(values, observable.probabilities, observable.bins, t_end)
    pre = f"fpt_{name}"
    prob, bin_, edge = f"{pre}_probability", f"{pre}_bin", f"{pre}_bin_edge"
    what = f"first-passage time of {name} >= {observable.threshold:g}"
    censoring = (f"right-censored at t_end = {t_end:g}: {s['censored']} of the {s['n']} finite paths had not "
                 f"passed by then (fraction passed {s['passed'] / s['n'] if s['n'] else math.nan:.6g}); "
                 f"{nonfinite} non-finite paths excluded")
    common = {"units": "time", "step_error": STEP_ERROR, "censoring": censoring}
    level = f"{CONFIDENCE:.0%}"
    coords = {prob: (prob, np.asarray(observable.probabilities, dtype=np.float64),
                     {"long_name": f"probability p of the quantiles of {name}'s passage time"})}
    data = {
        f"{pre}_quantile": (prob, s["quantile"], {
            "long_name": f"quantile of τ_{name}", **common,
            "description": f"p-quantile of the {what}: the order statistic tau_(ceil(n p)) of the n finite "
                           "paths; NaN where p exceeds the fraction passed by t_end (censored: beyond t_end, "
                           "not estimated)"}),
        f"{pre}_quantile_lower": (prob, s["lower"], {
            "long_name": f"{level} lower bound of the quantile of τ_{name}", **common, "confidence": CONFIDENCE,
            "description": "distribution-free lower confidence bound: tau_(l), l the Binomial(n, p) "
                           f"{(1 - CONFIDENCE) / 2:g} quantile (0 when l = 0)"}),
        f"{pre}_quantile_upper": (prob, s["upper"], {
            "long_name": f"{level} upper bound of the quantile of τ_{name}", **common, "confidence": CONFIDENCE,
            "description": "distribution-free upper confidence bound: tau_(u), u the Binomial(n, p) "
                           f"{(1 + CONFIDENCE) / 2:g} quantile + 1; NaN where u exceeds the paths passed "
                           "(the bound lies beyond t_end: censored)"}),
        f"{pre}_hist": (bin_, s["hist"], {
            "long_name": f"paths whose τ_{name} lies in each bin", "units": "1", "step_error": STEP_ERROR,
            "censoring": censoring,
            "description": f"histogram of the {what} over [0, t_end] in equal bins (each [lo, hi), the last "
                           f"[lo, t_end]); the censored paths are in {pre}_censored, in no bin"}),
        f"{pre}_bin_edges": (edge, s["edges"], {"long_name": f"edges of the bins of {pre}_hist", "units": "time"}),
        f"{pre}_censored": ((), np.int64(s["censored"]), {
            "long_name": f"paths whose {name} had not reached {observable.threshold:g} by t_end",
            "units": "1", "censoring": censoring}),
        f"{pre}_passed": ((), np.int64(s["passed"]), {
            "long_name": f"paths whose {name} reached {observable.threshold:g} by t_end", "units": "1"}),
        f"{pre}_paths": ((), np.int64(s["n"]), {
            "long_name": f"finite paths in the law of τ_{name} (non-finite ones excluded)", "units": "1"}),
    }
    return data, coords
