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

**Observables users write** (:class:`Observable`, :func:`register`): a function
``value(x, Omega, xi, t)`` of one path's state -- its coordinate, velocity, the noise's value
and the time -- whose ensemble mean a run reports as ``mean_<name>`` with its standard error
and bias estimate, when the run asks for it (``simulate(..., observables=("name",))``). Its
sum takes a column after the table's (``count, SUMS..., nonfinite, user...``), so the table's
columns never move. A path whose value is not finite is excluded from then on, like an
escaped path, and counted in ``nonfinite_paths``. Like a user's model, it is compiled by Numba
(nopython: ``math`` functions, arithmetic) into the run's kernels, CPU and CUDA, in memory::

    import math
    from stochpend.observables import Observable, register
    register(Observable("cos_x", lambda x, Omega, xi, t: math.cos(x), label="⟨cos x⟩"))
    ds = stochpend.simulate(noise="ou", observables=("cos_x",))   # ds.mean_cos_x

This module imports numpy only: ``stochpend.resources`` reads it before any kernel exists.
"""

from __future__ import annotations

import hashlib
import inspect
import math
import re
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

__all__ = ["SUMS", "STATISTICS", "SUM_COMPONENTS", "N_SUMS", "S_COUNT", "S_NONFINITE", "column",
           "path_values_source", "reduced_values_source", "TABLE_KEY", "Observable", "register",
           "unregister", "get", "names", "resolve", "objects", "user_statistics", "user_key"]


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
    counted as non-finite, never averaged in). ``n`` is the oscillator's parameter record q
    (``Oscillator.record``). Its globals: ``potential`` (U(x, q)) and ``shape`` (G(x, q), or x
    for the position coupling), ``isfinite``."""
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


# -- observables users write ---------------------------------------------------------------------
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]{0,63}")


@dataclass(frozen=True, eq=False)
class Observable:
    """A per-path value a user declares (see the module docstring): ``value(x, Omega, xi, t)``
    -> float, in the paper's units; reported as ``mean_<name>`` (``label`` for plots, by default
    ``⟨name⟩``; ``units`` and ``description`` for the file)."""

    name: str
    value: Callable[[float, float, float, float], float]
    label: str | None = None
    units: str = "paper units"
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not _NAME.fullmatch(self.name):
            raise ValueError(f"name={self.name!r} is not accepted: a letter, then letters, digits or _ "
                             "(at most 64): the result's variable is mean_<name>")
        taken = {s.name for s in STATISTICS} | {s.name for s in SUMS}
        if self.name in taken or f"mean_{self.name}" in taken:
            raise ValueError(f"name={self.name!r} is not accepted: mean_{self.name} is a built-in statistic")
        if not callable(self.value):
            raise ValueError(f"value={self.value!r} is not accepted: a function (x, Omega, xi, t) -> float")
        try:
            probe = float(self.value(0.5, 0.5, 0.5, 0.5))
        except Exception as error:
            raise ValueError(f"value is not accepted: calling it with (x, Omega, xi, t) = (0.5, 0.5, 0.5, 0.5) "
                             f"raised {type(error).__name__}: {error}") from None
        if not math.isfinite(probe):
            raise ValueError(f"value is not accepted: it returned {probe} at (x, Omega, xi, t) = (0.5, 0.5, 0.5, 0.5)")

    @property
    def statistic(self) -> str:
        return f"mean_{self.name}"

    def source(self) -> str:
        """The function's source, for provenance (empty where Python cannot find it)."""
        try:
            return inspect.getsource(self.value).strip()
        except Exception:  # noqa: BLE001 - provenance never stops a run
            return f"{self.name}: source unavailable"


_REGISTRY: dict[str, Observable] = {}


def register(observable: Observable) -> Observable:
    """Make ``observable`` available to runs by its name (replaces one of the same name)."""
    if not isinstance(observable, Observable):
        raise ValueError(f"observable={observable!r} is not accepted: a stochpend.observables.Observable")
    _REGISTRY[observable.name] = observable
    return observable


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def get(name: str) -> Observable | None:
    return _REGISTRY.get(name)


def resolve(value: Any) -> tuple[str, ...]:
    """Validate a run's ``observables`` (names of registered observables) and return them as a
    tuple; a one-line ValueError naming the parameter otherwise."""
    if value is None:
        return ()
    if isinstance(value, str):
        value = (value,)
    try:
        items = tuple(value)
    except TypeError:
        raise ValueError(f"observables={value!r} is not accepted: names of registered observables "
                         "(stochpend.observables.register)") from None
    for name in items:
        if not isinstance(name, str) or name not in _REGISTRY:
            known = ", ".join(_REGISTRY) or "none registered"
            raise ValueError(f"observables={items!r} is not accepted: {name!r} is not a registered observable "
                             f"({known}; stochpend.observables.register)")
    if len(set(items)) != len(items):
        raise ValueError(f"observables={items!r} is not accepted: a name appears twice")
    return items


def objects(names_: tuple[str, ...]) -> tuple[Observable, ...]:
    """The registered observables of these names (the kernels are specialised on the objects,
    so that a name registered again gets kernels of its new function)."""
    found = tuple(_REGISTRY.get(name) for name in names_)
    missing = [name for name, o in zip(names_, found, strict=True) if o is None]
    if missing:
        raise ValueError(f"observables={names_!r} is not accepted: {missing[0]!r} is not a registered observable")
    return found  # type: ignore[return-value]  # no None left


def n_sums(config: Any) -> int:
    """Columns of a run's per-batch sums: the table's and one per user observable."""
    return N_SUMS + len(getattr(config, "observables", ()))


def user_key(user: tuple[Observable, ...]) -> str:
    """What names a kernel compiled for these user observables (objects of this process)."""
    return ",".join(f"{o.name}@{id(o):x}" for o in user) or "none"


def user_statistics(names_: tuple[str, ...]) -> tuple[Statistic, ...]:
    """The statistics of a run's user observables: mean_<name> of column N_SUMS + i."""
    out = []
    for i, name in enumerate(names_):
        obs = _REGISTRY[name]

        def of(m: np.ndarray, c: int = N_SUMS + i) -> np.ndarray:
            return m[..., c]

        out.append(Statistic(obs.statistic, of, obs.label or f"⟨{name}⟩", obs.units,
                             obs.description or f"<{name}>, ensemble mean of a user observable", f"<{name}>"))
    return tuple(out)


def user_values(observables: tuple[Observable, ...]) -> Callable:
    """``user_values(x, Omega, xi, t) -> tuple`` of the observables' values (float64), for the
    accumulate kernels; ``(0.0,)`` when there are none (the kernels then read no value)."""
    from numba.extending import register_jitable

    functions = {f"f{i}": register_jitable(o.value) for i, o in enumerate(observables)}
    calls = [f"float(f{i}(x, Omega, xi, t))" for i in range(len(observables))] or ["0.0"]
    namespace: dict[str, Any] = dict(functions)
    exec(f"def user_values(x, Omega, xi, t):\n    return ({', '.join(calls)},)\n", namespace)
    function = namespace["user_values"]
    function.__module__, function.__qualname__ = __name__, "user_values.<locals>.user_values"
    from stochpend._jitcache import name_closures

    name_closures([function], f"user_values/{user_key(observables)}")
    return register_jitable(function)
