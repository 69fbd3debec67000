"""The statistics every run reports, declared once.

Two tables, and everything else is derived from them: the backends' accumulate kernels (CPU,
CUDA, and through them the bias estimate's coupled pairs), the averaged dynamics
(:mod:`stochpend.runs.reduced`), the column layout of the per-batch sums that checkpoints, sweeps
and ``reproduce`` store, the memory the resource check counts, and the Dataset's variables
with their labels.

* :data:`SUMS`: the per-path values summed over each batch at each output time. Each is an
  expression in the path's energy ``E`` (Eq. ``defenergie``), its velocity ``Omega``, its
  position ``x``, ``g`` (the function the noise multiplies: G(x) for the force coupling, x for
  the position coupling) and the values declared before it, all in float64. ``reduced`` gives
  the value in the averaged dynamics, where a path is its energy alone (``None``: undefined
  there). The per-batch sums are laid out as ``count``, the SUMS in order, ``nonfinite``.
* :data:`STATISTICS`: what a result reports, each a function of the ensemble means of the
  sums, with a delete-one-batch jackknife error and a bias estimate (``stochpend.model.power_sums``,
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

This module imports numpy only: ``stochpend.runs.resources`` reads it before any kernel exists.
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
           "path_values_source", "reduced_values_source", "TABLE_KEY", "Observable", "TimeAverage",
           "FirstPassage", "RunningSum", "DISPLACEMENT", "EnergyObservable", "LOG_ENERGY", "register", "unregister", "get", "names",
           "resolve", "objects", "user_statistics", "user_key", "accumulators", "track_step",
           "track_initial"]


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
    #: The coupled pairs' Richardson estimate applies (False: a per-path accumulator, which the
    #: pairs do not carry, or whose step error is not O(h^2): its bias is not estimated).
    richardson: bool = True


def _ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        return num / den


def _three_halves(m2: np.ndarray) -> np.ndarray:
    """|m2|^(3/2) as |m2| sqrt(|m2|): exactly rounded operations, the same bits on every machine
    (numpy's ``** 1.5`` takes another loop on AVX-512 than on AVX2: stochpend.numerics._hostmath)."""
    a = np.abs(m2)
    return a * np.sqrt(a)


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
    "skewness", lambda m: _ratio(m[..., column("E3")], _three_halves(m[..., column("E2")])),
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


_REGISTRY: dict[str, Any] = {}


def register(observable: Any) -> Any:
    """Make ``observable`` (an :class:`Observable`, or a per-path accumulator:
    :class:`TimeAverage`, :class:`FirstPassage`, :class:`RunningSum`) available to runs by its
    name (replaces one of the same name)."""
    if not isinstance(observable, (Observable, EnergyObservable, TimeAverage, FirstPassage, RunningSum)):
        raise ValueError(f"observable={observable!r} is not accepted: a stochpend.observables.Observable, "
                         "TimeAverage, FirstPassage or RunningSum")
    _REGISTRY[observable.name] = observable
    return observable


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def get(name: str) -> Any:
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


def check_windows(names_: tuple[str, ...], times: Any) -> None:
    """A time average's window ends must be 0 or output times of the run (steps land there, so
    no step straddles an end): a one-line ValueError naming the observable otherwise."""
    allowed = {0.0, *(float(t) for t in times)}
    for name in names_:
        o = _REGISTRY.get(name)
        if isinstance(o, TimeAverage):
            for end in o.window:
                if end not in allowed:
                    raise ValueError(f"observables={names_!r} is not accepted: the window {o.window} of "
                                     f"{name!r} must start and end at 0 or an output time of the run "
                                     f"(its steps land there), and {end:g} is not one")


def objects(names_: tuple[str, ...]) -> tuple[Any, ...]:
    """The registered observables of these names (the kernels are specialised on the objects,
    so that a name registered again gets kernels of its new function)."""
    found = tuple(_REGISTRY.get(name) for name in names_)
    missing = [name for name, o in zip(names_, found, strict=True) if o is None]
    if missing:
        raise ValueError(f"observables={names_!r} is not accepted: {missing[0]!r} is not a registered observable")
    return found


def n_sums(config: Any) -> int:
    """Columns of a run's per-batch sums: the table's, one per user observable and two per
    per-path accumulator."""
    return N_SUMS + sum(_columns(_REGISTRY[name]) for name in getattr(config, "observables", ()))


def _columns(o: Any) -> int:
    return 1 if isinstance(o, Observable) else 2  # accumulators and EnergyObservable: value, count


def n_user_columns(user: tuple[Any, ...]) -> int:
    """Columns of these user observables' sums (objects): one per observable, two per
    accumulator."""
    return sum(_columns(o) for o in user)


def user_key(user: tuple[Any, ...]) -> str:
    """What names a kernel compiled for these user observables (objects of this process)."""
    return ",".join(f"{o.name}@{id(o):x}" for o in user) or "none"


def user_statistics(names_: tuple[str, ...], times: Any = None) -> tuple[Statistic, ...]:
    """The statistics of a run's user observables and accumulators, in the order of their
    columns (from N_SUMS): mean_<name> of an observable's column; an accumulator's own
    (:meth:`TimeAverage.statistics` ...). ``times``: the run's output times, which a running
    sum's rates divide by (:meth:`RunningSum.statistics`; their names need none, their values
    do)."""
    out: list[Statistic] = []
    c = N_SUMS
    for name in names_:
        obs = _REGISTRY[name]
        if isinstance(obs, Observable):
            def of(m: np.ndarray, c: int = c) -> np.ndarray:
                return m[..., c]

            out.append(Statistic(obs.statistic, of, obs.label or f"⟨{name}⟩", obs.units,
                                 obs.description or f"<{name}>, ensemble mean of a user observable", f"<{name}>"))
        elif isinstance(obs, RunningSum):
            out.extend(obs.statistics(c, times))
        else:
            out.extend(obs.statistics(c))
        c += _columns(obs)
    return tuple(out)


def user_values(observables: tuple[Any, ...], oscillator: Any = None) -> Callable:
    """``user_values(x, Omega, xi, t, tracks, i, omega2, q) -> tuple`` of the run's user columns
    (float64), for the accumulate kernels: an observable's value; an accumulator's two columns
    read from its slot ``tracks[slot, i]`` of path i; an :class:`EnergyObservable`'s value of
    e = E - E_min and 1 (0 and 0 where the value is not finite), E computed with ``oscillator``'s
    potential (its record q, omega2). ``(0.0,)`` when there are none (the kernels then read no
    value)."""
    from numba.extending import register_jitable

    namespace: dict[str, Any] = {}
    calls: list[str] = []
    slot = 0
    lines = ["def user_values(x, Omega, xi, t, tracks, i, omega2, q):"]
    if any(isinstance(o, EnergyObservable) for o in observables):
        if oscillator is None:
            raise ValueError("an EnergyObservable needs the run's oscillator")
        from stochpend.numerics.mathlib import LIBM

        namespace["potential"] = oscillator.kernel(np.float64, LIBM).potential
        namespace["floor"] = register_jitable(oscillator.energy_floor)
        lines.append("    e = 0.5 * Omega * Omega + omega2 * (potential(x, q) - floor(q))")
    for n, o in enumerate(observables):
        if isinstance(o, Observable):
            namespace[f"f{n}"] = register_jitable(o.value)
            calls.append(f"float(f{n}(x, Omega, xi, t))")
        elif isinstance(o, EnergyObservable):
            # Plain names in the returned tuple: a conditional or a starred item inside the
            # tuple display makes Python build a list (list_to_tuple), which Numba cannot type.
            namespace[f"f{n}"] = register_jitable(o.value)
            lines.append(f"    v{n} = float(f{n}(e))")
            lines.append(f"    a{n} = 0.0")
            lines.append(f"    b{n} = 0.0")
            lines.append(f"    if isfinite(v{n}):")
            lines.append(f"        a{n} = v{n}")
            lines.append(f"        b{n} = 1.0")
            calls.append(f"a{n}, b{n}")
        else:
            namespace[f"v{n}"] = o.values_function()
            lines.append(f"    a{n}, b{n} = v{n}(tracks[{slot}, i], t)")
            calls.append(f"a{n}, b{n}")
            slot += 1
    if not calls:
        calls = ["0.0"]
    namespace["isfinite"] = math.isfinite
    lines.append(f"    return ({', '.join(calls)},)")
    exec("\n".join(lines) + "\n", namespace)
    function = namespace["user_values"]
    function.__module__, function.__qualname__ = __name__, "user_values.<locals>.user_values"
    from stochpend.numerics._jitcache import name_closures

    name_closures([function], f"user_values/{builtin_key(observables) or user_key(observables)}")
    return register_jitable(function)


@dataclass(frozen=True, eq=False)
class EnergyObservable:
    """A function ``value(e)`` of a path's energy above the potential's floor, e = E - E_min =
    Omega^2/2 + omega^2 (U(x) - min U) >= 0, reported as ``mean_<name>``, the mean over the paths
    where it is finite (a path at the floor, where ln e = -inf, is left out of this statistic
    only, and ``n_<name>`` counts the paths averaged). Built in: :data:`LOG_ENERGY`, ln e, whose
    mean grows as 2 lambda t for the random-frequency oscillator (lambda its Lyapunov exponent:
    the typical growth, against the mean growth of <E>). A power e**q is one line:
    ``register(EnergyObservable("e_q", lambda e: e ** 1.5))``."""

    name: str
    value: Callable[[float], float]
    label: str | None = None
    units: str = "paper units"
    description: str = ""

    def __post_init__(self) -> None:
        _check_name(self.name, ("mean", "n"))
        _probe(self.value, "value", 1)

    def statistics(self, c: int) -> list[Statistic]:
        def n_(m: np.ndarray, c: int = c) -> np.ndarray:
            return m[..., c + 1]

        return [Statistic(f"mean_{self.name}", _ratio_of(c), self.label or f"⟨{self.name}⟩", self.units,
                          self.description or f"<{self.name}>, mean of a function of E - E_min over the paths "
                          "where it is finite", f"<{self.name}>", controlled=False),
                Statistic(f"n_{self.name}", n_, f"share of paths in ⟨{self.name}⟩", "1",
                          f"fraction of the paths where {self.name} is finite", f"n({self.name})",
                          controlled=False, richardson=False)]

    def source(self) -> str:
        return _source(self.value, self.name)


def accumulators(user: tuple[Any, ...]) -> tuple[Any, ...]:
    """The per-path accumulators among a run's user observables (objects), in slot order."""
    return tuple(o for o in user if isinstance(o, (TimeAverage, FirstPassage, RunningSum)))


def track_step(accs: tuple[Any, ...]) -> Callable | None:
    """``track(tracks, i, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1)``: every accumulator's update
    of its slot ``tracks[slot, i]`` over one step of path i from time t0 (state x0, Omega0, xi0)
    to t1, in float64 (xi1 the noise at the step's end before a jump of an event noise at t1:
    the step's own value, which the next step's xi0 is not); ``None`` without accumulators (the
    integrator then compiles no tracking at all).

    Its attribute ``members`` is the same update for coupled members (the multilevel target's
    levels): ``members(tracks, i, m, x0, ..., t1)`` updates member m's slots ``tracks[m * n +
    slot, i]``, n = ``len(accs)``; ``n_slots`` is n, ``key`` the set's name in a kernel's
    name (:func:`builtin_key`, else :func:`user_key`)."""
    if not accs:
        return None
    from numba.extending import register_jitable

    from stochpend.numerics._jitcache import name_closures

    namespace: dict[str, Any] = {f"s{slot}": a.step_function() for slot, a in enumerate(accs)}
    n = len(accs)
    for name, head, row in (("track", "", ""), ("members", "m, ", f"m * {n} + ")):
        lines = [f"def {name}(tracks, i, {head}x0, Omega0, xi0, x1, Omega1, xi1, t0, t1):"]
        lines += [f"    tracks[{row}{slot}, i] = s{slot}(tracks[{row}{slot}, i], x0, Omega0, xi0, x1, Omega1, xi1, "
                  "t0, t1)" for slot in range(n)]
        exec("\n".join(lines) + "\n", namespace)
        function = namespace[name]
        function.__module__, function.__qualname__ = __name__, f"track_step.<locals>.{name}"
        # A built-in set is named by its names alone, the same in every process (its kernel is
        # cached on disk, and Numba keys a cached kernel on its closures' names).
        name_closures([function], f"track/{builtin_key(accs) or user_key(accs)}")
    track = register_jitable(namespace["track"])
    track.members = register_jitable(namespace["members"])
    # What a kernel built on it needs besides the function: its slot count (the CPU's lanes
    # carry the slots in their scratch) and the key that names the set in a kernel's name.
    track.n_slots = n
    track.key = builtin_key(accs) or user_key(accs)
    return track


def track_initial(accs: tuple[Any, ...]) -> np.ndarray:
    """Each slot's value at t = 0, shape (len(accs), 1) (broadcast over the paths)."""
    return np.array([[a.initial] for a in accs], dtype=np.float64).reshape(len(accs), 1)


# -- per-path accumulators -----------------------------------------------------------------------
def _check_name(name: Any, prefixes: tuple[str, ...]) -> None:
    if not isinstance(name, str) or not _NAME.fullmatch(name):
        raise ValueError(f"name={name!r} is not accepted: a letter, then letters, digits or _ (at most 64)")
    taken = {s.name for s in STATISTICS} | {s.name for s in SUMS}
    if name in taken or any(f"{p}_{name}" in taken for p in prefixes):
        raise ValueError(f"name={name!r} is not accepted: it names a built-in statistic")


def _probe(function: Any, what: str, n_args: int) -> None:
    if not callable(function):
        raise ValueError(f"{what}={function!r} is not accepted: a function of {n_args} floats -> float")
    try:
        probe = float(function(*([0.5] * n_args)))
    except Exception as error:
        raise ValueError(f"{what} is not accepted: calling it with {n_args} arguments 0.5 raised "
                         f"{type(error).__name__}: {error}") from None
    if not math.isfinite(probe):
        raise ValueError(f"{what} is not accepted: it returned {probe} with {n_args} arguments 0.5")


def _ratio_of(c: int) -> Callable[[np.ndarray], np.ndarray]:
    def of(m: np.ndarray) -> np.ndarray:
        return _ratio(m[..., c], np.where(m[..., c + 1] > 0, m[..., c + 1], np.nan))

    return of


@dataclass(frozen=True, eq=False)
class TimeAverage:
    """A per-path time average over a window: (1/(t' - t0)) ∫ value(x, Omega, xi, t) dt over
    [t0, t'], t' = min(t, t1) at output time t > t0, by the trapezoidal rule over the
    integrator's own steps (second order, as the scheme is). ``window = (t0, t1)``: each end 0 or
    one of the run's output times, so that steps land on it and no step straddles it (checked
    when the run is built). Reported as ``mean_<name>``, the ensemble mean over the paths, from
    the first output time after t0 (NaN before)."""

    name: str
    value: Callable[[float, float, float, float], float]
    window: tuple[float, float]
    label: str | None = None
    units: str = "paper units"
    description: str = ""
    initial = 0.0

    def __post_init__(self) -> None:
        _check_name(self.name, ("mean",))
        _probe(self.value, "value", 4)
        try:
            t0, t1 = (float(w) for w in self.window)
        except (TypeError, ValueError):
            raise ValueError(f"window={self.window!r} is not accepted: (t0, t1), 0 <= t0 < t1") from None
        if not (math.isfinite(t0) and math.isfinite(t1) and 0.0 <= t0 < t1):
            raise ValueError(f"window={self.window!r} is not accepted: (t0, t1), 0 <= t0 < t1")
        object.__setattr__(self, "window", (t0, t1))

    def statistics(self, c: int) -> list[Statistic]:
        return [Statistic(f"mean_{self.name}", _ratio_of(c), self.label or f"⟨{self.name}⟩_T", self.units,
                          self.description or f"<{self.name}>, ensemble mean of a per-path time average "
                          f"over [{self.window[0]:g}, min(t, {self.window[1]:g})]", f"<{self.name}>_T",
                          controlled=False, richardson=False)]

    def step_function(self) -> Callable:
        from numba.extending import register_jitable

        f = register_jitable(self.value)
        w0, w1 = self.window

        def step(a, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1):
            if t0 >= w0 and t1 <= w1:
                return a + 0.5 * (t1 - t0) * (float(f(x0, Omega0, xi0, t0)) + float(f(x1, Omega1, xi1, t1)))
            return a

        return register_jitable(step)

    def values_function(self) -> Callable:
        from numba.extending import register_jitable

        w0, w1 = self.window

        def values(a, t):
            if t > w0:
                return a / (min(t, w1) - w0), 1.0
            return 0.0, 0.0

        return register_jitable(values)

    def source(self) -> str:
        return _source(self.value, self.name)


@dataclass(frozen=True, eq=False)
class FirstPassage:
    """The first time a path's ``value(x, Omega, xi, t)`` reaches ``threshold`` (at t = 0 if it
    starts there), interpolated linearly within the step that crosses. Reported as
    ``mean_<name>``, the mean first-passage time of the paths that have passed by the output
    time (conditional: the others are censored), and ``passed_<name>``, the fraction that has.
    Its step error is O(sqrt(h)) (a path can cross and come back within a step unseen), not the
    scheme's O(h^2): the coupled-pair bias estimate does not apply and is not reported.

    From each path's passage time at the end of the run the result also holds the law of the
    passage time (:mod:`stochpend.model.passage`): its quantiles at ``probabilities`` with
    distribution-free 95 % intervals (NaN where a probability exceeds the fraction passed by the
    last output time: censored) and a histogram of ``bins`` equal bins over [0, t_end] with the
    number censored, as ``fpt_<name>_...`` variables."""

    name: str
    value: Callable[[float, float, float, float], float]
    threshold: float
    label: str | None = None
    units: str = "paper units"
    description: str = ""
    #: The probabilities of the reported quantiles, each in (0, 1), increasing.
    probabilities: tuple[float, ...] = (0.1, 0.25, 0.5, 0.75, 0.9)
    #: Bins of the passage-time histogram over [0, t_end].
    bins: int = 20
    initial = -1.0

    def __post_init__(self) -> None:
        _check_name(self.name, ("mean", "passed"))
        _probe(self.value, "value", 4)
        if isinstance(self.threshold, bool) or not isinstance(self.threshold, (int, float)) \
                or not math.isfinite(self.threshold):
            raise ValueError(f"threshold={self.threshold!r} is not accepted: a finite number")
        object.__setattr__(self, "threshold", float(self.threshold))
        accepted = "a non-empty increasing sequence of at most 99 numbers in (0, 1)"
        try:
            probabilities = tuple(float(p) for p in self.probabilities)
            bad = any(isinstance(p, bool) for p in self.probabilities)
        except (TypeError, ValueError):
            raise ValueError(f"probabilities={self.probabilities!r} is not accepted: {accepted}") from None
        if (bad or not 1 <= len(probabilities) <= 99 or not all(0.0 < p < 1.0 for p in probabilities)
                or any(b <= a for a, b in zip(probabilities, probabilities[1:], strict=False))):
            raise ValueError(f"probabilities={self.probabilities!r} is not accepted: {accepted}")
        object.__setattr__(self, "probabilities", probabilities)
        if isinstance(self.bins, bool) or not isinstance(self.bins, int) or not 1 <= self.bins <= 10_000:
            raise ValueError(f"bins={self.bins!r} is not accepted: an integer in [1, 10000]")

    def statistics(self, c: int) -> list[Statistic]:
        def passed(m: np.ndarray, c: int = c) -> np.ndarray:
            return m[..., c + 1]

        return [Statistic(f"mean_{self.name}", _ratio_of(c), self.label or f"⟨τ_{self.name}⟩", "time",
                          self.description or f"mean first-passage time of {self.name} >= {self.threshold:g}, "
                          "over the paths that have passed by t (censored otherwise)", f"<tau_{self.name}>",
                          controlled=False, richardson=False),
                Statistic(f"passed_{self.name}", passed, f"P(τ_{self.name} ≤ t)", "1",
                          f"fraction of the paths whose {self.name} has reached {self.threshold:g} by t",
                          f"P(tau_{self.name}<=t)", controlled=False, richardson=False)]

    def step_function(self) -> Callable:
        from numba.extending import register_jitable

        f = register_jitable(self.value)
        level = self.threshold

        def step(a, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1):
            if a >= 0.0:
                return a
            g0 = float(f(x0, Omega0, xi0, t0))
            if g0 >= level:
                return t0
            g1 = float(f(x1, Omega1, xi1, t1))
            if g1 >= level:
                return t0 + (t1 - t0) * (level - g0) / (g1 - g0)
            return a

        return register_jitable(step)

    def values_function(self) -> Callable:
        from numba.extending import register_jitable

        def values(a, t):
            if a >= 0.0:
                return a, 1.0
            return 0.0, 0.0

        return register_jitable(values)

    def source(self) -> str:
        return _source(self.value, self.name)


@dataclass(frozen=True, eq=False)
class RunningSum:
    """A per-path sum of ``increment(x0, Omega0, xi0, x1, Omega1, xi1, t0, t1)`` over the
    integrator's steps (from the state at t0 to the state at t1, xi the noise's value; at a step
    that ends on a flip of an event noise, xi1 is the value before the flip, the step's own, and
    the next step's xi0 the value after it, so a sum of xi1 - xi0 leaves the flips out): a
    counter, a work, a displacement, an integral of the noise. Reported as
    ``mean_<name>`` and ``var_<name>``, the ensemble mean and variance of the sum at each output
    time. :data:`DISPLACEMENT` is one: the increment (t1 - t0)(Omega0 + Omega1)/2 is the step's
    own drift (x1 - x0 before x is wrapped), so its sum is the unwrapped displacement x(t) - x(0)
    of a periodic coordinate, in float64 whatever the run's precision.

    ``rates=True`` also reports ``rate_<name>`` = mean/t and ``diffusion_<name>`` = var/(2t) at
    each output time t > 0 (NaN at t = 0), with standard errors: the mean's and the variance's
    divided by the same constants (the jackknife of c f is c times f's). For the displacement,
    the mean velocity <x(t) - x(0)>/t and the effective diffusion D_eff(t) = var(x(t) - x(0))/(2t),
    which tends to lim var/2t as t grows (at finite t it still holds the start's transient: read
    it at times long after the velocity's relaxation, 1/gamma)."""

    name: str
    increment: Callable[..., float]
    label: str | None = None
    units: str = "paper units"
    description: str = ""
    rates: bool = False
    initial = 0.0

    def __post_init__(self) -> None:
        _check_name(self.name, ("mean", "var", "rate", "diffusion"))
        _probe(self.increment, "increment", 8)
        if not isinstance(self.rates, bool):
            raise ValueError(f"rates={self.rates!r} is not accepted: True or False")

    def statistics(self, c: int, times: Any = None) -> list[Statistic]:
        """``mean_<name>``, ``var_<name>`` and, with :attr:`rates`, ``rate_<name>`` and
        ``diffusion_<name>``, whose values need the run's output ``times`` (the time is the
        last axis of ``m[..., column]``; their names do not)."""
        def mean_(m: np.ndarray, c: int = c) -> np.ndarray:
            return m[..., c]

        def var_(m: np.ndarray, c: int = c) -> np.ndarray:
            return m[..., c + 1] - m[..., c] * m[..., c]

        label = self.label or self.name
        out = [Statistic(f"mean_{self.name}", mean_, f"⟨{label}⟩", self.units,
                         self.description or f"<{self.name}>, ensemble mean of a per-path running sum",
                         f"<{self.name}>", controlled=False, richardson=False),
               Statistic(f"var_{self.name}", var_, f"var {label}", self.units,
                         f"ensemble variance of {self.name}", f"var({self.name})", controlled=False,
                         richardson=False)]
        if not self.rates:
            return out
        t = None if times is None else np.asarray(times, dtype=np.float64)
        name = self.name

        def per_t(m: np.ndarray, value: np.ndarray, factor: float) -> np.ndarray:
            if t is None:
                raise ValueError(f"rate_{name} and diffusion_{name} need the run's output times")
            # The last axis: the run's output times, or their first k (a multilevel target's
            # round runs only as far as the latest time that needs it).
            tk = t[:value.shape[-1]]
            return _ratio(value, np.where(tk > 0, factor * tk, np.nan))

        def rate_(m: np.ndarray) -> np.ndarray:
            return per_t(m, mean_(m), 1.0)

        def diffusion_(m: np.ndarray) -> np.ndarray:
            return per_t(m, var_(m), 2.0)

        out += [Statistic(f"rate_{name}", rate_, f"⟨{label}⟩/t", f"{self.units} per time",
                          f"<{name}>/t, the mean rate of {name} since t = 0 (for the displacement: the "
                          "mean velocity); NaN at t = 0", f"<{name}>/t", controlled=False, richardson=False),
                Statistic(f"diffusion_{name}", diffusion_, f"var {label}/2t", f"({self.units})^2 per time",
                          f"var({name})/(2t) (for the displacement: the effective diffusion D_eff(t), "
                          "-> lim var/2t at long times); NaN at t = 0", f"var({name})/2t", controlled=False,
                          richardson=False)]
        return out

    def step_function(self) -> Callable:
        from numba.extending import register_jitable

        f = register_jitable(self.increment)

        def step(a, x0, Omega0, xi0, x1, Omega1, xi1, t0, t1):
            return a + float(f(x0, Omega0, xi0, x1, Omega1, xi1, t0, t1))

        return register_jitable(step)

    def values_function(self) -> Callable:
        from numba.extending import register_jitable

        def values(a, t):
            return a, a * a

        return register_jitable(values)

    def source(self) -> str:
        return _source(self.increment, self.name)


def _source(function: Any, name: str) -> str:
    try:
        return inspect.getsource(function).strip()
    except Exception:  # noqa: BLE001 - provenance never stops a run
        return f"{name}: source unavailable"


def _drift(x0: float, Omega0: float, xi0: float, x1: float, Omega1: float, xi1: float, t0: float,
           t1: float) -> float:
    return 0.5 * (t1 - t0) * (Omega0 + Omega1)


#: The unwrapped displacement x(t) - x(0) (see :class:`RunningSum`), with its mean velocity
#: ``rate_displacement`` = <x(t) - x(0)>/t and effective diffusion ``diffusion_displacement`` =
#: var(x(t) - x(0))/(2t). Registered.
DISPLACEMENT = RunningSum("displacement", _drift, label="x(t) − x(0)",
                          description="unwrapped displacement x(t) - x(0), the sum of each step's drift "
                          "(t1 - t0)(Omega0 + Omega1)/2", rates=True)
register(DISPLACEMENT)

#: ln(E - E_min): its mean is the typical energy's log (see :class:`EnergyObservable`). Registered.
LOG_ENERGY = EnergyObservable("log_energy", math.log, label="⟨ln(E − E_min)⟩",
                              description="<ln(E - E_min)>, over the paths above the potential's floor")
register(LOG_ENERGY)

#: The built-in observables, as this module registered them: their code is the package's, under
#: its code digest (stochpend.numerics._sources), so a kernel that tracks only these can be
#: cached on disk (:func:`builtin_key`).
_BUILTIN = dict(_REGISTRY)


def builtin_key(objects: tuple[Any, ...]) -> str | None:
    """What names a kernel compiled for the observables or accumulators ``objects`` when every
    one is built in (the very object this module registered: ``"displacement"``,
    ``"log_energy"``), their names in order; None when there are none or any is a user's (its
    functions are not the package's code: compiled in memory only, named by
    :func:`user_key`)."""
    if not objects or any(_BUILTIN.get(o.name) is not o for o in objects):
        return None
    return "+".join(o.name for o in objects)
