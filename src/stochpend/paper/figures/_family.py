"""Shared pieces of the family's gallery (``family-*``, issue 23 item 5): run keys, late-time
estimates with delete-one-batch jackknife errors, and the per-figure default sizes.

Every gallery estimate is a function of a run's statistics at a few output times (a slope of
the variance of the displacement, a mean velocity over a window, an exponential growth rate);
its error is the delete-one-batch jackknife of that function, from the per-batch sums that
:mod:`stochpend.paper.reproduce` stores with each run (:func:`stochpend.paper.figures._common.leave_one_out`),
so the correlation between the times of the same paths is accounted for.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import xarray as xr

from stochpend.paper.figures._common import _jackknife, leave_one_out


def params(**terms: float) -> tuple[tuple[str, float], ...]:
    """The family's terms as sorted (name, value) pairs (:attr:`FigureRun.params`)."""
    return tuple(sorted((k, float(v)) for k, v in terms.items()))


def index_at(ds: xr.Dataset, t: float) -> int:
    """Index of the output time nearest ``t``."""
    return int(np.argmin(np.abs(ds["time"].values - t)))


def jackknife(ds: xr.Dataset, names: tuple[str, ...],
              fn: Callable[[dict[str, np.ndarray]], float]) -> tuple[float, float]:
    """``fn`` of the statistics ``names`` (each an array over the run's times) and its
    delete-one-batch jackknife error (nan without per-batch sums)."""
    value = float(fn({n: np.asarray(ds[n].values, dtype=np.float64) for n in names}))
    loo = {n: leave_one_out(ds, n) for n in names}
    if any(v is None for v in loo.values()):
        return value, math.nan
    n_b = next(iter(loo.values())).shape[0]  # type: ignore[union-attr]
    reps = np.array([fn({n: loo[n][b] for n in names}) for b in range(n_b)])  # type: ignore[index]
    return value, _jackknife(reps)


def window_slope(ds: xr.Dataset, var: str, t_lo: float, t_hi: float | None = None, *,
                 log: bool = False) -> tuple[float, float]:
    """Least-squares slope of ``var`` (or of ``ln var``) against t over the output times in
    ``[t_lo, t_hi]`` (unit weights), with its jackknife error."""
    t = ds["time"].values
    t_hi = float(t[-1]) if t_hi is None else t_hi
    sel = (t >= t_lo * (1 - 1e-12)) & (t <= t_hi * (1 + 1e-12))
    x = t[sel]

    def fn(v: dict[str, np.ndarray]) -> float:
        y = v[var][sel]
        if log:
            with np.errstate(divide="ignore", invalid="ignore"):
                y = np.log(y)
        return float(np.polyfit(x, y, 1)[0])

    return jackknife(ds, (var,), fn)


def increment_rate(ds: xr.Dataset, var: str, t1: float, scale: float = 1.0) -> tuple[float, float, float]:
    """``scale (var(t_last) − var(t1))/(t_last − t1)`` with its jackknife error, and the output
    time used for t1 (the nearest to it)."""
    i = index_at(ds, t1)
    t = ds["time"].values
    dt = float(t[-1] - t[i])

    def fn(v: dict[str, np.ndarray]) -> float:
        return scale * float(v[var][-1] - v[var][i]) / dt

    value, err = jackknife(ds, (var,), fn)
    return value, err, float(t[i])
