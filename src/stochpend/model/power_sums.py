"""On-the-fly ensemble statistics: per-batch power sums, exact merging, jackknife errors.

The ensemble is cut into ``n_batches`` batches of consecutive global path indices. For every
batch and output time the backends return the raw power sums (count, sum E**k for k = 1..4,
sum Omega**2, sum Omega**4, sum G(x)**2, number of non-finite paths) and an energy histogram.
Merging two pieces of an ensemble is placing their batches: exact, and independent of how the
work was chunked, threaded or distributed.

Every reported statistic is a smooth function of the ensemble means of these sums; its
standard error is the delete-one-batch jackknife, which for a plain mean reduces to the
batch-means error and also covers the ratios S and F.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from types import SimpleNamespace
from typing import TYPE_CHECKING

import numpy as np

from stochpend.model import observables as _table

if TYPE_CHECKING:  # pragma: no cover
    import xarray as xr

__all__ = ["EnsembleSums", "LevelSums", "N_SUMS", "STATISTICS", "passage_slots"]

#: Columns of the per-batch sums that every backend fills (``sums[batch, time, column]``):
#: count, the summed values of :data:`stochpend.observables.SUMS`, non-finite paths.
S_COUNT, S_NONFINITE, N_SUMS = _table.S_COUNT, _table.S_NONFINITE, _table.N_SUMS
S_E1 = _table.column("E")

#: The table's columns whose pairs' differences the difference kernel also sums in products
#: (``stochpend.engine.cpu.difference_kernel``): the skewness and flatness are functions of
#: these means, and the moments of their linearised per-sample difference w . d need the
#: cross products (:func:`linearised_moments`).
CROSS = tuple(_table.column(name) for name in ("E2", "E3", "E4"))


def _monomials(degree: int) -> list[tuple[int, int, int]]:
    return [(a, b, degree - a - b) for a in range(degree, -1, -1) for b in range(degree - a, -1, -1)]


#: Exponents (of CROSS's three differences) of the products summed for each degree 1..4, row
#: k holding degree k + 1: 3, 6, 10 and 15 products, in this order.
CROSS_MONOMIALS = tuple(tuple(_monomials(k + 1)) for k in range(4))
#: Columns the products take after the run's sums in the differences array (the most, degree 4).
N_CROSS = len(CROSS_MONOMIALS[-1])

#: Exponents (of a running sum's two columns' differences, the sum S and its square S^2) of the
#: products summed for each degree 1..4: 2, 3, 4 and 5 products. The variance S^2 - S S and
#: its diffusion are functions of those two means, and the moments of their linearised
#: per-sample difference need these (:func:`linearised_moments`).
SUM_MONOMIALS = tuple(tuple((a, k + 1 - a) for a in range(k + 1, -1, -1)) for k in range(4))
#: Columns each running sum's products take, after CROSS's, in the differences array.
N_SUM_PRODUCTS = len(SUM_MONOMIALS[-1])


def product_columns(observables_: tuple[str, ...]) -> int:
    """Columns after the run's sums that the difference kernel's products take
    (``cpu.difference_kernel(products=True)``): CROSS's, then :data:`N_SUM_PRODUCTS` for each
    running sum among the run's observables, in their order."""
    return N_CROSS + N_SUM_PRODUCTS * len(running_sums(observables_))


def running_sums(observables_: tuple[str, ...]) -> tuple[_table.RunningSum, ...]:
    """The running sums among a run's user observables, in the order of their products."""
    if not observables_:
        return ()
    return tuple(o for o in _table.objects(tuple(observables_)) if isinstance(o, _table.RunningSum))


def linearised_moments(products: np.ndarray, count: np.ndarray, w: np.ndarray,
                       monomials_by_degree: tuple = CROSS_MONOMIALS) -> np.ndarray:
    """Raw moments E[(w . d)^n], n = 1..4, of a linear combination of differences d: of CROSS's
    (``products`` (..., 4, N_CROSS) the summed products, row k: degree k + 1, in
    :data:`CROSS_MONOMIALS`'s order, ``w`` (..., 3) the weights), or of a running sum's two
    columns (``monomials_by_degree`` :data:`SUM_MONOMIALS`, ``products`` (..., 4,
    N_SUM_PRODUCTS), ``w`` (..., 2)); ``count`` (...) the pairs summed. Returns (4, ...)."""
    from math import factorial, prod

    out = []
    with np.errstate(invalid="ignore", divide="ignore"):
        for k, monomials in enumerate(monomials_by_degree):
            n = k + 1
            total = np.zeros(np.shape(count))
            for j, exponents in enumerate(monomials):
                term = factorial(n) / prod(factorial(e) for e in exponents)
                for i, e in enumerate(exponents):  # left to right, as written out for three columns
                    term = term * w[..., i] ** e
                total = total + term * products[..., k, j]
            out.append(total / count)
    return np.array(out)


# Each statistic: a function of the means m[..., c] = sums[..., c] / count.
STATISTICS: dict[str, Callable[[np.ndarray], np.ndarray]] = {s.name: s.of for s in _table.STATISTICS}


def passage_slots(observables_: tuple[str, ...]) -> tuple[_table.FirstPassage, ...]:
    """The first-passage observables among a run's user observables, in the order of their
    accumulator slots (and of the rows of :attr:`EnsembleSums.passage`)."""
    if not observables_:
        return ()
    return tuple(o for o in _table.accumulators(_table.objects(observables_)) if isinstance(o, _table.FirstPassage))


@dataclass
class EnsembleSums:
    """Per-batch power sums, shape (n_batches, n_times, N_SUMS), and histogram totals.

    ``hist`` has shape (n_times, n_bins + 2): underflow, the bins, overflow; with a joint
    (x, Omega) histogram, its 3 * cells integer columns follow (:meth:`joint`,
    ``stochpend.model.settings.hist_columns``), summed like the rest. ``filled`` marks the batches
    already computed (all must be filled before statistics are read).
    """

    sums: np.ndarray
    hist: np.ndarray
    filled: np.ndarray
    #: The run's user observables (stochpend.observables): their sums follow the table's.
    observables: tuple[str, ...] = ()
    #: The final passage time of every path for each first-passage observable, (n_passages,
    #: paths) float64 (:func:`stochpend.model.passage.final_values`: -1 not passed, NaN non-finite
    #: or not yet run); None without first passages.
    passage: np.ndarray | None = None

    @classmethod
    def empty(cls, n_batches: int, n_times: int, n_bins: int,
              observables_: tuple[str, ...] = (), paths: int = 0, joint_cells: int = 0) -> EnsembleSums:
        """Zeroed sums, written once here: ``np.zeros`` maps pages that become resident only
        when first written, so the per-batch sums would grow the process's memory batch by
        batch over a long run (a slow rise that looks like a leak, and a shortfall that shows
        late). Written now, the memory the resource check counted is held from the start.
        ``paths``: the ensemble's, for the per-path passage times of its first passages;
        ``joint_cells``: the joint histogram's (``stochpend.model.settings.joint_cells``), whose counts
        follow the energy histogram's columns (``stochpend.model.settings.hist_columns``)."""
        sums = np.empty((n_batches, n_times, _table.n_sums(SimpleNamespace(observables=observables_))))
        sums.fill(0.0)
        filled = np.empty(n_batches, dtype=bool)
        filled.fill(False)
        n_passages = len(passage_slots(tuple(observables_)))
        passage = None
        if n_passages:
            if paths < 1:  # an empty array would report a law of no path
                raise ValueError(f"paths={paths!r} is not accepted: the ensemble's paths, >= 1, for its first passages")
            passage = np.empty((n_passages, paths))
            passage.fill(np.nan)
        return cls(sums=sums, hist=np.zeros((n_times, n_bins + 2 + 3 * joint_cells), dtype=np.int64), filled=filled,
                   observables=tuple(observables_), passage=passage)

    def add_passage(self, first_path: int, values: np.ndarray) -> None:
        """Insert the final passage times of paths ``first_path ...`` (shape (n_passages, n))."""
        if self.passage is not None:
            self.passage[:, first_path:first_path + values.shape[1]] = values

    def add_batches(self, first_batch: int, sums: np.ndarray, hist: np.ndarray) -> None:
        """Insert the sums of batches ``first_batch ...`` (shape (n, n_times, N_SUMS))."""
        stop = first_batch + sums.shape[0]
        if np.any(self.filled[first_batch:stop]):
            raise ValueError(f"batches {first_batch}..{stop - 1} were already accumulated")
        self.sums[first_batch:stop] = sums
        self.hist += hist
        self.filled[first_batch:stop] = True

    def merge(self, other: EnsembleSums) -> EnsembleSums:
        """Combine two disjoint sets of batches of the same ensemble (exact)."""
        if np.any(self.filled & other.filled):
            raise ValueError("cannot merge: the two accumulators share batches")
        passage = None
        if self.passage is not None and other.passage is not None:  # each path's, from whichever ran it
            passage = np.where(np.isnan(self.passage), other.passage, self.passage)
        out = EnsembleSums(self.sums.copy(), self.hist + other.hist, self.filled | other.filled, self.observables,
                           passage)
        out.sums[other.filled] = other.sums[other.filled]
        return out

    # -- reading --------------------------------------------------------------------------
    @property
    def complete(self) -> bool:
        return bool(np.all(self.filled))

    def statistics(self, times: np.ndarray | None = None) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Every statistic with its jackknife standard error, each of shape (n_times,); ``times``
        (the output times) for the statistics that divide by t (a running sum's rates)."""
        sums = self.sums[self.filled]
        n_b = sums.shape[0]
        total = sums.sum(axis=0)
        count = total[..., S_COUNT]
        m_all = total / np.where(count > 0, count, np.nan)[..., None]
        loo = total[None] - sums  # leave-one-batch-out sums
        loo_count = loo[..., S_COUNT]
        m_loo = loo / np.where(loo_count > 0, loo_count, np.nan)[..., None]
        out = {}
        for statistic in self.declared(times):
            name, f = statistic.name, statistic.of
            value = f(m_all)
            if n_b >= 2:
                jk = f(m_loo)
                with np.errstate(invalid="ignore", divide="ignore"):
                    # A statistic undefined for the whole ensemble (e.g. S when every E = 0)
                    # has an undefined error too: NaN propagates, nothing is silently dropped.
                    dev = jk - jk.mean(axis=0)
                    se = np.sqrt((n_b - 1) / n_b * np.sum(dev * dev, axis=0))
            else:
                se = np.full_like(value, np.nan)
            out[name] = (value, se)
        return out

    def declared(self, times: np.ndarray | None = None) -> tuple[_table.Statistic, ...]:
        """The statistics this ensemble reports: the table's, then its user observables'."""
        return _table.STATISTICS + _table.user_statistics(self.observables, times)

    def nonfinite(self) -> np.ndarray:
        """Number of paths already non-finite at each time, shape (n_times,)."""
        return self.sums[self.filled][..., S_NONFINITE].sum(axis=0).astype(np.int64)

    def counts(self) -> np.ndarray:
        """Number of finite paths averaged at each time, shape (n_times,)."""
        return self.sums[self.filled][..., S_COUNT].sum(axis=0).astype(np.int64)

    def joint(self, n_e_cols: int, shape: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
        """The joint histogram's counts and the standard error of each cell's probability,
        each (n_times, nx + 2, nOmega + 2) (``shape``: (nx, nOmega)) with the outside rows and
        columns; ``n_e_cols``: the energy histogram's columns before it.

        The probability of a cell is p = C / N (C its count, N the finite paths); its error is
        the batch-means (linearised delete-one-batch jackknife) error of that ratio,
        var p = B/(B - 1) sum_b (c_b - p n_b)**2 / N**2 over the B batches, from the summed
        c_b, c_b**2 and c_b n_b the kernels keep per cell (exact integers)."""
        cells = (shape[0] + 2) * (shape[1] + 2)
        block = self.hist[:, n_e_cols:n_e_cols + 3 * cells].astype(np.float64)
        c, c2, cn = block[:, :cells], block[:, cells:2 * cells], block[:, 2 * cells:]
        n_b = self.sums[self.filled][..., S_COUNT]  # (B, n_times)
        b = n_b.shape[0]
        n = n_b.sum(axis=0)[:, None]
        n2 = (n_b * n_b).sum(axis=0)[:, None]
        with np.errstate(invalid="ignore", divide="ignore"):
            p = c / n
            var = (c2 - 2.0 * p * cn + p * p * n2) / (n * n) * (b / (b - 1) if b >= 2 else np.nan)
            se = np.sqrt(np.maximum(var, 0.0))
        full = (self.hist.shape[0], shape[0] + 2, shape[1] + 2)
        return self.hist[:, n_e_cols:n_e_cols + cells].reshape(full), se.reshape(full)

    def to_dataset(self, times: np.ndarray, edges: np.ndarray, attrs: dict,
                   joint: tuple[np.ndarray, np.ndarray] | None = None) -> xr.Dataset:
        """The result as an ``xarray.Dataset`` (names fixed: other tools read them).
        ``joint``: the joint histogram's edges (``stochpend.model.settings.joint_grid``), when the run
        has one."""
        data_vars: dict[str, tuple] = {}
        n_e = edges.shape[-1] + 1  # the energy histogram's columns, outside ones included
        declared = {s.name: s for s in self.declared(times)}
        for name, (value, se) in self.statistics(times).items():
            label, units = declared[name].label, declared[name].units
            data_vars[name] = ("time", value, {"long_name": label, "units": units,
                                               "description": declared[name].description})
            data_vars[f"{name}_stderr"] = (
                "time",
                se,
                {"long_name": f"std. error of {label}", "units": units,
                 "description": f"standard error of {name} (delete-one-batch jackknife)"},
            )
        data_vars["E_hist"] = (
            ("time", "E_bin"),
            self.hist[:, 1:n_e - 1],
            {"long_name": "number of finite paths with E in each bin"},
        )
        data_vars["E_bin_edges"] = (("time", "E_bin_edge"), edges, {"long_name": "histogram bin edges"})
        data_vars["E_hist_underflow"] = ("time", self.hist[:, 0])
        data_vars["E_hist_overflow"] = ("time", self.hist[:, n_e - 1])
        if joint is not None:
            data_vars.update(_joint_variables(self, n_e, *joint))
        data_vars["n_finite_paths"] = ("time", self.counts())
        # Per-batch sums, so that any function of <E(t)> over several times (an exponent fit)
        # gets a delete-one-batch jackknife error that respects the correlation between times.
        data_vars["batch_sum_E"] = (
            ("batch", "time"),
            self.sums[..., S_E1],
            {"long_name": "sum of E over the finite paths of each batch"},
        )
        data_vars["batch_n_finite"] = (
            ("batch", "time"),
            self.sums[..., S_COUNT].astype(np.int64),
            {"long_name": "finite paths of each batch"},
        )
        data_vars["nonfinite_paths"] = (
            "time",
            self.nonfinite(),
            {"long_name": "paths that went non-finite by this time: excluded from every statistic"},
        )
        time = ("time", np.asarray(times), {"long_name": "time t", "units": "paper units"})
        coords: dict[str, tuple] = {"time": time}
        if self.passage is not None:  # the law of each first passage, from every path's own time
            from stochpend.model import passage as _passage

            t_end = float(np.asarray(times)[-1])
            nonfinite = int(self.nonfinite()[-1])
            for row, o in zip(self.passage, passage_slots(self.observables), strict=True):
                if int(np.isnan(row).sum()) != nonfinite:  # every path's time, or a path was lost
                    raise RuntimeError(f"internal error: the passage times of {o.name} miss paths")
                more, more_coords = _passage.variables(o, row, t_end, nonfinite)
                data_vars.update(more)
                coords.update(more_coords)
        import xarray as xr  # here: `show` reads the statistics' names from this module, without xarray

        return xr.Dataset(data_vars, coords=coords, attrs=attrs)


@dataclass
class LevelSums:
    """The per-batch power sums of coupled members (``runner.run_batches`` with ``levels`` >
    1), shape (n_batches, n_times, levels, n_sums): member 0 the coarsest (step h), member m
    the step h / 2**m, each batch's sums over the same sets of members. ``differences``: the
    raw power sums of two members' differences over the whole run, (n_times, 4, n_sums), or
    (n_times, 4, n_sums + N_CROSS) with the products of CROSS's differences after the run's
    columns
    (``stochpend.engine.cpu.difference_kernel``), or None when not asked for."""

    sums: np.ndarray
    filled: np.ndarray
    differences: np.ndarray | None = None

    @classmethod
    def empty(cls, n_batches: int, n_times: int, levels: int, n_sums: int) -> LevelSums:
        return cls(np.zeros((n_batches, n_times, levels, n_sums)), np.zeros(n_batches, dtype=bool))

    def add_passage(self, first_path: int, values: np.ndarray) -> None:
        raise ValueError("coupled levels carry no first passages")

    def add_batches(self, first_batch: int, sums: np.ndarray, differences: np.ndarray | None) -> None:
        """Insert the sums of batches ``first_batch ...``; ``differences`` the engine's running
        totals so far (added in path order chunk after chunk, as one array: replaced, not added)."""
        stop = first_batch + sums.shape[0]
        if np.any(self.filled[first_batch:stop]):
            raise ValueError(f"batches {first_batch}..{stop - 1} were already accumulated")
        self.sums[first_batch:stop] = sums
        self.filled[first_batch:stop] = True
        self.differences = differences


def _joint_variables(sums: EnsembleSums, n_e: int, x_edges: np.ndarray,
                     Omega_edges: np.ndarray) -> dict[str, tuple]:
    """The joint (x, Omega) histogram's variables: counts, outside counts, density and its
    standard error, edges."""
    shape = (x_edges.shape[-1] - 1, Omega_edges.shape[-1] - 1)
    counts, se = sums.joint(n_e, shape)
    inside = counts[:, 1:-1, 1:-1]
    n = sums.counts().astype(np.float64)[:, None, None]
    area = (np.diff(x_edges, axis=-1)[:, :, None] * np.diff(Omega_edges, axis=-1)[:, None, :])
    with np.errstate(invalid="ignore", divide="ignore"):
        density = inside / n / area
        density_se = se[:, 1:-1, 1:-1] / area
    dims = ("time", "x_bin", "Omega_bin")
    units = "1/(paper units)^2"
    return {
        "joint_hist": (dims, inside, {
            "long_name": "number of finite paths with (x, Omega) in each bin",
            "description": "x: a periodic oscillator's angle reduced to [-pi, pi); bins "
                           "[lo, hi) along x_bin_edges and Omega_bin_edges"}),
        "joint_hist_outside": ("time", counts.sum(axis=(1, 2)) - inside.sum(axis=(1, 2)), {
            "long_name": "number of finite paths with x or Omega outside the joint histogram's range"}),
        "joint_density": (dims, density, {
            "long_name": "probability density of (x, Omega)", "units": units,
            "description": "joint_hist / (n_finite_paths * bin area)"}),
        "joint_density_stderr": (dims, density_se, {
            "long_name": "std. error of the probability density of (x, Omega)", "units": units,
            "description": "batch-means (linearised delete-one-batch jackknife) error"}),
        "x_bin_edges": (("time", "x_bin_edge"), x_edges, {"long_name": "joint histogram's x bin edges"}),
        "Omega_bin_edges": (("time", "Omega_bin_edge"), Omega_edges,
                            {"long_name": "joint histogram's Omega bin edges"}),
    }
