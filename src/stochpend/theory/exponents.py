r"""Measured growth laws of <E(t)>: a fitted exponent with a jackknife error, and a diagnosis.

:func:`fit_exponent` fits nu in <E> ~ t**nu over a window of output times;
:func:`diagnose_growth` tells a power law from an exponential and from a finite-time blow-up.
Both read a Dataset from :func:`stochpend.simulate`, which carries, besides ``mean_E``, the
per-batch sums ``batch_sum_E`` (batch, time) and counts ``batch_n_finite`` (batch, time).

Why per-batch sums: <E> at different times comes from the same paths, so the errors of
log <E(t_i)> are strongly correlated and a least-squares slope error that treats them as
independent is wrong (usually too small at late times, where each path carries its whole
history). Deleting one batch of paths at a time and refitting (the delete-one-batch
jackknife, as in :mod:`stochpend.model.power_sums`) keeps every correlation between times.

The predictions these are compared with are in :mod:`stochpend.theory.scaling`
(derivations in ``docs/scaling.md``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import xarray as xr
from numpy.typing import NDArray

# The labels of diagnose_growth are those of ScalingPrediction.growth, so the two compare directly.
from stochpend.text._docs import documented
from stochpend.theory.scaling import GROWTHS

__all__ = ["ExponentFit", "GROWTHS", "diagnose_growth", "fit_exponent", "fit_rate", "fit_slope"]


#: Significance, in jackknife standard errors, for "the log-log slope increases".
Z_GROWTH = 4.0

#: Fewest late times diagnose_growth needs: two sub-windows of >= 3 points each.
MIN_LATE_TIMES = 6

#: Relative slack when selecting output times in [t_min, t_max], so that a window edge equal
#: to an output time up to round-off (log-spaced times) still includes it.
_EDGE_RTOL = 1e-9


def _fail(name: str, value: Any, accepted: str) -> None:
    raise ValueError(f"{name}={value!r} is not accepted: {accepted}")


@dataclass(frozen=True)
class ExponentFit:
    """The fitted exponent nu of <E> ~ t**nu over a window.

    Attributes
    ----------
    exponent : float
        Least-squares slope of log <E> against log t.
    se : float
        Delete-one-batch jackknife standard error of ``exponent``.
    t_min, t_max : float
        First and last output times used (inside the requested window).
    n_times : int
        Number of output times used.
    paths : int
        Paths simulated.
    nonfinite : int
        Paths already non-finite at ``t_max`` (left out of <E>: a nonzero count means the
        fit describes the surviving paths only).
    growth : str
        :func:`diagnose_growth` of the whole Dataset.
    """

    exponent: float
    se: float
    t_min: float
    t_max: float
    n_times: int
    paths: int
    nonfinite: int
    growth: str


def _batch_arrays(ds: xr.Dataset) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """(times, sums (batch, time), counts (batch, time)), batches with no path dropped."""
    missing = [v for v in ("batch_sum_E", "batch_n_finite") if v not in ds]
    if "time" not in ds.coords or missing:
        what = ", ".join(missing + ([] if "time" in ds.coords else ["coordinate time"]))
        raise ValueError(
            f"ds is not accepted: it lacks {what} (a Dataset from stochpend.simulate with per-batch sums is needed)"
        )
    times = np.asarray(ds["time"].values, dtype=float)
    sums = np.asarray(ds["batch_sum_E"].transpose("batch", "time").values, dtype=float)
    counts = np.asarray(ds["batch_n_finite"].transpose("batch", "time").values, dtype=float)
    keep = counts.max(axis=1) > 0  # an empty batch (paths < n_batches) carries no information
    return times, sums[keep], counts[keep]


def _means(sums: NDArray[np.float64], counts: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """<E> over all batches (time,) and with each batch left out (batch, time); NaN where empty."""
    total, n = sums.sum(axis=0), counts.sum(axis=0)
    loo_n = n[None, :] - counts
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(n > 0, total / np.where(n > 0, n, 1.0), np.nan)
        loo = np.where(loo_n > 0, (total[None, :] - sums) / np.where(loo_n > 0, loo_n, 1.0), np.nan)
    return mean, loo


def _slopes(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Least-squares slopes of y (..., k) against x (k,), along the last axis."""
    w = (x - x.mean()) / np.sum((x - x.mean()) ** 2)
    return np.asarray(y @ w)


def _jackknife_se(loo_values: NDArray[np.float64]) -> float:
    """Delete-one jackknife standard error from the leave-one-out values (n_b,)."""
    n_b = loo_values.shape[0]
    if n_b < 2:
        return math.nan
    dev = loo_values - loo_values.mean()
    return float(math.sqrt((n_b - 1) / n_b * float(np.sum(dev * dev))))


def fit_exponent(ds: xr.Dataset, t_min: float, t_max: float) -> ExponentFit:
    r"""Fit nu in <E(t)> ~ t**nu over the output times in [t_min, t_max].

    The exponent is the ordinary least-squares slope of log <E> against log t over those
    times (Eqs. `eq:scalEblanc`: nu = 1, `eq:scalEcolor`: nu = 1/2 for the paper's pendulum);
    its standard error is the delete-one-batch jackknife, which respects the correlation
    between the times (every time comes from the same paths).

    Parameters
    ----------
    ds : xarray.Dataset
        From :func:`stochpend.simulate`: coordinate ``time``, variables ``batch_sum_E`` and
        ``batch_n_finite`` (dims batch, time); ``paths`` and ``nonfinite_paths`` are read when
        present.
    t_min, t_max : float
        The window, in the simulation's time units, 0 < t_min < t_max. It must hold at least
        three output times, and <E> must be > 0 at each of them (the pendulum's energy is
        negative near the bottom of the well, so early windows can fail).

    Returns
    -------
    ExponentFit

    Raises
    ------
    ValueError
        One line naming the parameter: a bad window, fewer than 3 times in it, <E> <= 0 in
        it, or a Dataset without the per-batch sums.
    """
    return _fit(ds, t_min, t_max, log_time=True)


def fit_rate(ds: xr.Dataset, t_min: float, t_max: float) -> ExponentFit:
    r"""Fit lambda in <E(t)> ~ exp(lambda t) over the output times in [t_min, t_max].

    The least-squares slope of log <E> against t, with the delete-one-batch jackknife error,
    for the models whose energy grows exponentially (the random-frequency harmonic oscillator,
    :func:`stochpend.theory.scaling.harmonic_growth_rate`). Same arguments, refusals and
    result as :func:`fit_exponent`, ``exponent`` holding lambda (1/time).
    """
    return _fit(ds, t_min, t_max, log_time=False)


def fit_slope(ds: xr.Dataset, t_min: float, t_max: float) -> ExponentFit:
    r"""Fit A in <E(t)> ~ E_0 + A t over the output times in [t_min, t_max].

    The least-squares slope of <E> against t (energy per unit time), with the delete-one-batch
    jackknife error: a linear law with an offset, whose log-log slope reaches 1 only when
    A t >> E_0. Same arguments, refusals and result as :func:`fit_exponent`, ``exponent``
    holding A.
    """
    return _fit(ds, t_min, t_max, log_time=False, log_E=False)


def _fit(ds: xr.Dataset, t_min: float, t_max: float, *, log_time: bool,
         log_E: bool = True) -> ExponentFit:
    lo = _window_bound("t_min", t_min)
    hi = _window_bound("t_max", t_max)
    if hi <= lo:
        _fail("t_max", t_max, f"t_max must be > t_min = {t_min!r}")
    times, sums, counts = _batch_arrays(ds)
    sel = (times >= lo * (1 - _EDGE_RTOL)) & (times <= hi * (1 + _EDGE_RTOL))
    k = int(sel.sum())
    if k < 3:
        _fail(
            "t_min", t_min,
            f"the window [t_min, t_max] = [{lo:g}, {hi:g}] holds {k} output time(s), 3 are needed "
            "for a slope and its error: widen it or save more times",
        )
    t = times[sel]
    mean, loo = _means(sums[:, sel], counts[:, sel])
    _require_positive(mean, loo, t, t_min)
    x = np.log(t) if log_time else t
    f = np.log if log_E else np.asarray
    exponent = float(_slopes(x, f(mean)))
    se = _jackknife_se(_slopes(x, f(loo)))
    paths = int(ds.attrs.get("paths", int(counts[:, 0].sum())))
    if "nonfinite_paths" in ds:
        nonfinite = int(np.asarray(ds["nonfinite_paths"].values)[sel][-1])
    else:
        nonfinite = paths - int(counts[:, sel][:, -1].sum())
    return ExponentFit(
        exponent=exponent,
        se=se,
        t_min=float(t[0]),
        t_max=float(t[-1]),
        n_times=k,
        paths=paths,
        nonfinite=nonfinite,
        growth=diagnose_growth(ds),
    )


def _window_bound(name: str, value: Any) -> float:
    msg = f"{name} must be a finite time > 0 (the fit is in log t)"
    if isinstance(value, bool):
        _fail(name, value, msg)
    try:
        v = float(value)
    except (TypeError, ValueError):
        _fail(name, value, msg)
    if not math.isfinite(v) or v <= 0:
        _fail(name, value, msg)
    return v


def _require_positive(mean: NDArray[np.float64], loo: NDArray[np.float64], t: NDArray[np.float64], t_min: Any) -> None:
    """Refuse a window where log <E> (or a leave-one-batch-out log <E>) is undefined."""
    bad = ~(np.isfinite(mean) & (mean > 0))
    if bad.any():
        i = int(np.argmax(bad))
        _fail(
            "t_min", t_min,
            f"<E> = {mean[i]:.4g} at t = {t[i]:g} in the window, and log <E> needs <E> > 0 "
            "(pendulum energies are negative near the bottom of the well at early times): start later",
        )
    bad_loo = ~(np.isfinite(loo) & (loo > 0))
    if bad_loo.any():
        i = int(np.argmax(bad_loo.any(axis=0)))
        _fail(
            "t_min", t_min,
            f"<E> without one batch is <= 0 or undefined at t = {t[i]:g}, so the jackknife error "
            "of log <E> is undefined there: start the window later",
        )


@documented  # help() shows the signature's defaults
def diagnose_growth(ds: xr.Dataset, detail: bool = False) -> str:
    r"""Classify the growth of <E(t)>: power law, exponential, or finite-time blow-up.

    The rules, in order:

    1. ``"finite-time blow-up"`` if any path is non-finite at the last output time
       (``nonfinite_paths``). Whether that is the dynamics or the integrator is a separate
       question: halving the step should leave the non-finite fraction unchanged for a true
       blow-up (``docs/scaling.md``).
    2. Over the late half of the output times, split into an earlier and a later sub-window
       of equal size, fit the log-log slopes s1, s2 and note the ratio rho of the geometric
       mean times. A power law has s2 = s1; an exponential has d log<E>/dt constant, so
       s2/s1 = rho. ``"exponential"`` if s2 - s1 > ``Z_GROWTH`` jackknife standard errors and
       log(s2/s1) > log(rho)/2 (the semi-log slope is closer to constant than the log-log
       one; faster-than-exponential growth is reported as exponential too).
    3. ``"power"`` otherwise, and ``"unknown"`` when fewer than ``MIN_LATE_TIMES`` late times
       have <E> > 0, or when s1 <= 0 (no growth to classify).

    Parameters
    ----------
    ds : xarray.Dataset
        From :func:`stochpend.simulate` (see :func:`fit_exponent`).
    detail : bool
        If true, append ``": "`` and the numbers behind the decision (the label is always the
        text before the first colon).

    Returns
    -------
    str
        One of :data:`GROWTHS`, optionally followed by the detail.
    """
    times, sums, counts = _batch_arrays(ds)
    label, why = _diagnose(ds, times, sums, counts)
    return f"{label}: {why}" if detail else label


def _diagnose(
    ds: xr.Dataset, times: NDArray[np.float64], sums: NDArray[np.float64], counts: NDArray[np.float64]
) -> tuple[str, str]:
    if "nonfinite_paths" in ds:
        nonfinite = np.asarray(ds["nonfinite_paths"].values, dtype=np.int64)
        paths = int(ds.attrs.get("paths", int(counts[:, 0].sum() + nonfinite[0])))
        if nonfinite[-1] > 0:
            first = float(times[int(np.argmax(nonfinite > 0))])
            frac = nonfinite[-1] / paths if paths > 0 else math.nan
            return "finite-time blow-up", (
                f"{int(nonfinite[-1])} of {paths} paths ({100 * frac:.3g}%) non-finite at t = {times[-1]:g}, "
                f"the first by output time t = {first:g}"
            )
    late = np.arange(times.size // 2, times.size)
    mean, loo = _means(sums[:, late], counts[:, late])
    ok = np.isfinite(mean) & (mean > 0) & (times[late] > 0) & np.all(np.isfinite(loo) & (loo > 0), axis=0)
    if ok.sum() < MIN_LATE_TIMES or not ok.all():
        return "unknown", f"{int(ok.sum())} of the {late.size} late output times have <E> > 0 (need all, and >= {MIN_LATE_TIMES})"
    half = late.size // 2
    early, late_half = slice(0, half), slice(late.size - half, late.size)  # equal sizes; odd: middle unused
    x = np.log(times[late])
    s1 = float(_slopes(x[early], np.log(mean[early])))
    s2 = float(_slopes(x[late_half], np.log(mean[late_half])))
    ds_loo = _slopes(x[late_half], np.log(loo[:, late_half])) - _slopes(x[early], np.log(loo[:, early]))
    se = _jackknife_se(ds_loo)
    rho = math.exp(float(x[late_half].mean() - x[early].mean()))
    z = (s2 - s1) / se if se > 0 else math.copysign(math.inf, s2 - s1)
    numbers = f"late log-log slopes {s1:.4g} -> {s2:.4g} ({z:+.3g} SE), time ratio {rho:.3g}"
    if s1 <= 0:
        return "unknown", f"<E> is not growing over the late times ({numbers})"
    if z > Z_GROWTH and s2 > 0 and math.log(s2 / s1) > 0.5 * math.log(rho):
        return "exponential", f"{numbers}: d log<E>/dt is closer to constant than d log<E>/d log t"
    return "power", numbers
