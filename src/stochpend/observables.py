"""The statistics every run reports, declared once.

Two tables, and everything else is derived from them: the backends' accumulate kernels (CPU,
CUDA, and through them the bias estimate's coupled pairs), the averaged dynamics
(:mod:`stochpend.reduced`), the column layout of the per-batch sums that checkpoints, sweeps
and ``reproduce`` store, the memory the resource check counts, and the Dataset's variables
with their labels.

* :data:`SUMS`: the per-path values summed over each batch at each output time. Each is an
  expression in the path's energy ``E`` (Eq. ``defenergie``), its velocity ``Omega``, its
  position ``x``, ``g`` (the function the noise multiplies: G(x) for the force coupling, x for
  the position coupling) and the values declared before it, all in float64. ``reduced`` gives
  the value in the averaged dynamics, where a path is its energy alone (``None``: undefined
  there). The per-batch sums are laid out as ``count``, the SUMS in order, ``nonfinite``.
* :data:`STATISTICS`: what a result reports, each a function of the ensemble means of the
  sums, with a delete-one-batch jackknife error and a bias estimate (``stochpend.stats``,
  ``stochpend.bias``).

A new moment is one line: ``mean("Omega6", "Omega2 * Omega4", "⟨Ω⁶⟩", "<Omega^6>")`` appended
to the table below reaches every backend, the bias estimate, the result file and ``show``.
This module imports numpy only: ``stochpend.resources`` reads it before any kernel exists.
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

__all__ = ["SUMS", "STATISTICS", "SUM_COMPONENTS", "N_SUMS", "S_COUNT", "S_NONFINITE", "column",
           "path_values_source", "reduced_values_source", "TABLE_KEY"]


@dataclass(frozen=True)
class PathSum:
    """One per-path value that the accumulate kernels sum (see the module docstring)."""

    name: str
    expression: str
    reduced: str | None = None


@dataclass(frozen=True)
class Statistic:
    """One reported statistic: ``of(m)`` maps the means ``m[..., column]`` (sums over count)
    to its value; ``label`` and ``units`` for plots, ``description`` for the file, ``short`` (ASCII)
    for warnings. ``controlled``: ``accuracy="auto"`` bounds its bias."""

    name: str
    of: Callable[[np.ndarray], np.ndarray]
    label: str
    units: str
    description: str
    short: str
    controlled: bool = True


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return num / den


_sums: list[PathSum] = []
_statistics: list[Statistic] = []


def column(name: str) -> int:
    """The column of sum ``name`` in the per-batch sums (0 is the count)."""
    for i, s in enumerate(_sums):
        if s.name == name:
            return i + 1
    raise KeyError(name)


def mean(name: str, expression: str, label: str, description: str, *, reduced: str | None = None,
         units: str = "paper units", short: str | None = None, controlled: bool = True) -> None:
    """Declare a summed value ``name`` and its ensemble mean, the statistic ``mean_<name>``."""
    _sums.append(PathSum(name, expression, reduced))
    c = len(_sums)

    def of(m: np.ndarray) -> np.ndarray:
        return m[..., c]

    _statistics.append(Statistic(f"mean_{name}", of, label, units, description, short or f"<{name}>", controlled))


# -- the table ---------------------------------------------------------------------------------
# The expressions are the kernels' arithmetic, operation for operation: E**3 is E2 * E, not
# E * E * E, so that the numbers stay what they were when the kernels spelt them out.
mean("E", "E", "⟨E⟩",
     "<E>, ensemble mean of the energy E = Omega^2/2 - omega^2 cos(theta) (defenergie)", reduced="E")
mean("E2", "E * E", "⟨E²⟩", "<E^2>", reduced="E * E")
mean("E3", "E2 * E", "⟨E³⟩", "<E^3>", reduced="E2 * E")
mean("E4", "E2 * E2", "⟨E⁴⟩", "<E^4>", reduced="E2 * E2")
_statistics.append(Statistic(
    "skewness", lambda m: _ratio(m[..., column("E3")], np.abs(m[..., column("E2")]) ** 1.5),
    "skewness S", "1", "S = <E^3>/<E^2>^(3/2), the paper's raw-moment skewness", "S"))
_statistics.append(Statistic(
    "flatness", lambda m: _ratio(m[..., column("E4")], m[..., column("E2")] ** 2),
    "flatness F", "1", "F = <E^4>/<E^2>^2, the paper's raw-moment flatness", "F"))
# In the averaged dynamics Omega**2 = 2E (exact at omega = 0, leading order for E >> omega**2).
mean("Omega2", "Omega * Omega", "⟨Ω²⟩", "<Omega^2>", reduced="2.0 * E")
mean("Omega4", "Omega2 * Omega2", "⟨Ω⁴⟩", "<Omega^4>", reduced="4.0 * E2")
mean("sin2theta", "g * g", "⟨G²⟩",
     "<G(x)^2>, G the function the noise multiplies (sin theta for the pendulum)", short="<G2>",
     controlled=False)

#: The summed values, in column order (columns 1 .. len(SUMS)).
SUMS: tuple[PathSum, ...] = tuple(_sums)
#: The reported statistics, in the order of a result's variables.
STATISTICS: tuple[Statistic, ...] = tuple(_statistics)
#: Columns of the per-batch sums ``sums[..., column]``: count, the SUMS, non-finite paths.
SUM_COMPONENTS: tuple[str, ...] = ("count", *(s.name for s in SUMS), "nonfinite")
N_SUMS = len(SUM_COMPONENTS)
S_COUNT = 0
S_NONFINITE = N_SUMS - 1


# -- the kernels' per-path function, generated from the table -----------------------------------
def path_values_source() -> str:
    """Source of ``path_values(x, Omega, omega2, n) -> (ok, E, values)``, the function every
    backend's accumulate kernel calls for a path: ``values`` the tuple of :data:`SUMS` in
    float64, ``ok`` False when one of them or G(x) is not finite (the path has escaped: it is
    counted as non-finite, never averaged in). Its globals: ``potential`` (U(x, n)) and
    ``shape`` (G(x, n), or x for the position coupling), ``isfinite``."""
    lines = ["def path_values(x, Omega, omega2, n):",
             "    E = 0.5 * Omega * Omega + omega2 * potential(x, n)",
             "    g = shape(x, n)"]
    lines += [f"    {s.name} = {s.expression}" for s in SUMS]
    names = [s.name for s in SUMS]
    lines.append("    ok = isfinite(g) and " + " and ".join(f"isfinite({v})" for v in names))
    lines.append(f"    return ok, E, ({', '.join(names)},)")
    return "\n".join(lines) + "\n"


def reduced_values_source() -> str:
    """Source of ``reduced_values(E) -> values``: the :data:`SUMS` of a path of the averaged
    dynamics (its energy E), 0.0 where a value is undefined there (its statistic is NaN)."""
    lines = ["def reduced_values(E):"]
    for s in SUMS:
        lines.append(f"    {s.name} = {s.reduced if s.reduced is not None else '0.0'}")
    lines.append(f"    return ({', '.join(s.name for s in SUMS)},)")
    return "\n".join(lines) + "\n"


#: Names what the table makes the kernels compute, for their cache keys: a table changed at
#: run time (a test adding a moment) can never load a kernel compiled for another table.
TABLE_KEY = hashlib.sha256((path_values_source() + reduced_values_source()).encode()).hexdigest()[:12]
