"""Shared pieces of the figure modules: run specifications, time grids, late-time fits, table rows.

A figure module (``fig1`` ... ``fig4``) declares the simulations named in the paper's caption
as :class:`FigureRun` objects, draws the figure from their datasets and builds a table of
late-time values against the predictions as :class:`Row` objects. Nothing here simulates.

Late-time values and their extrapolation
----------------------------------------
The asymptotic laws are approached slowly (corrections of relative size ``(t/t_c)^{-1/2}`` for
coloured noise, ``1/t`` for white noise), so a value at the last time is not the limit. The
tables give both:

* the value at the last output time with its jackknife standard error, and
* a weighted least-squares fit of ``value(t) = a + b t^{-p}`` over the last decade of output
  times (weights 1/stderr^2), reporting ``a``. The values at different times come from the
  same paths and are strongly correlated, so the error of ``a`` is NOT the textbook
  least-squares error: it is the delete-one-batch jackknife of the whole fit (the fit is
  repeated on each leave-one-batch-out ensemble, from the per-batch sums stored with each run).
  The fit with the other exponent (``p = 1`` instead of ``1/2`` or vice versa) is reported
  too, as a measure of the model dependence.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np
import xarray as xr

from stochpend.model import observables
from stochpend.text._notation import ve

#: Names of the components of the per-batch sums stored with each run (``batch_sums``), in the
#: order of every backend's accumulator (declared in stochpend.observables).
SUM_COMPONENTS = observables.SUM_COMPONENTS

#: Output times per decade of every run (log-spaced).
PER_DECADE = 12
#: First output time of every run.
T_MIN = 1e-2
#: Factor of the fit window: the last decade [t_last/10, t_last].
FIT_WINDOW = 10.0


# ---------------------------------------------------------------------------------------------
# The runs a figure needs
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class FigureRun:
    """One simulation of a figure: its physics, its size and its seed.

    ``key`` names the physical run (noise, D, tau, omega); two figures that need the same
    simulation (same parameters, times, paths and seed) share one cached file.
    """

    key: str
    label: str
    noise: str
    D: float
    tau: float | None
    omega: float
    t_max: float
    seed: int
    paths: int
    t_min: float = T_MIN
    per_decade: int = PER_DECADE
    # Beyond the paper's pendulum (the exponent table): the model and the noise's W.
    potential: str = "pendulum"
    power_n: int = 2
    coupling: str = "force"
    omega_noise: float | None = None
    # Step controls when the defaults are not fine enough for the model (None: the defaults).
    h_max: float | None = None
    step_c: float | None = None
    # The family's terms (stochpend.model.dynamics: gamma, torque, additive_D, ...), sorted (name,
    # value) pairs; the initial state; registered observables (e.g. "displacement"). Each enters
    # the keyword arguments only when set, so a paper run's cache key is what it was.
    params: tuple[tuple[str, float], ...] = ()
    theta0: float | str = "uniform"
    Omega0: float = 0.0
    observables: tuple[str, ...] = ()

    def times(self) -> np.ndarray:
        """Log-spaced output times from ``t_min`` to ``t_max`` (``per_decade`` a decade)."""
        decades = math.log10(self.t_max / self.t_min)
        n = max(2, int(round(self.per_decade * decades)) + 1)
        t = np.geomspace(self.t_min, self.t_max, n)
        t[-1] = self.t_max
        return t

    def simulate_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`stochpend.simulate` (and ``SimulationConfig.build``)."""
        return {
            "noise": self.noise,
            "D": float(self.D),
            "tau": None if self.tau is None else float(self.tau),
            "omega": float(self.omega),
            "paths": int(self.paths),
            "t_max": float(self.t_max),
            "times": [float(x) for x in self.times()],
            "seed": int(self.seed),
            "theta0": self.theta0 if isinstance(self.theta0, str) else float(self.theta0),
            "Omega0": float(self.Omega0),
            "potential": self.potential,
            "power_n": int(self.power_n),
            "coupling": self.coupling,
            "omega_noise": None if self.omega_noise is None else float(self.omega_noise),
            **({} if self.h_max is None else {"h_max": float(self.h_max)}),
            **({} if self.step_c is None else {"step_c": float(self.step_c)}),
            **({"dyn_params": {k: float(v) for k, v in self.params}} if self.params else {}),
            **({"observables": tuple(self.observables)} if self.observables else {}),
        }

    def param(self, name: str, default: float = 0.0) -> float:
        """The value of one of the family's terms (``params``), or ``default``."""
        return float(dict(self.params).get(name, default))

    def cache_key(self, version: str, backend: str = "cpu", precision: str = "float64") -> str:
        """SHA-256 of the fully resolved configuration, the package version, the code, and the
        backend and precision that ran it (a GPU's float64 differs from the CPU's in the last
        bits, float32 by more: a run is reused only where it would be made again).

        The resolved configuration includes every default (step controls, histogram, batches),
        so a run stored before a default changed is never reused for the new settings.
        """
        from stochpend.model.settings import SimulationConfig
        from stochpend.numerics import _sources

        config = SimulationConfig.build(**self.simulate_kwargs())
        resolved = {**config.to_attrs(), "times": list(config.times), "hist_E_max": list(config.hist_E_max)}
        # The code that determines the numbers is part of the key: a run made by an older
        # integrator (same version string, e.g. during development) is never reused.
        content: dict[str, Any] = {"run": resolved, "stochpend": version, "code": _sources.digest(),
                                   "backend": backend, "precision": precision}
        if self.observables:  # a user observable's code decides its numbers (absent: the key as before)
            content["observables_source"] = [observables.get(n).source() for n in self.observables]
        payload = json.dumps(content, sort_keys=True, default=str)
        return hashlib.sha256(payload.encode()).hexdigest()

    @property
    def t_c(self) -> float:
        """Crossover time 1/(D tau^2) (Eq. `tpcross`); inf for white noise."""
        if self.noise != "ou" or self.tau is None or self.D == 0:
            return math.inf
        return 1.0 / (self.D * self.tau**2)

    def describe(self) -> str:
        """One line: the physics of the run."""
        return describe_attrs({"noise": self.noise, "D": self.D, "tau": self.tau, "omega": self.omega,
                               "omega_noise": self.omega_noise, "potential": self.potential,
                               "power_n": self.power_n, "coupling": self.coupling})


def run_key(noise: str, D: float, tau: float | None, omega: float) -> str:
    """File-name stem of a physical run, e.g. ``ou_D1_tau0.1_omega1``."""
    if noise == "white":
        return f"white_D{D:g}_omega{omega:g}"
    return f"ou_D{D:g}_tau{tau:g}_omega{omega:g}"


#: How a run's noise is named in captions and the report (another, a plugin's, by its name).
_NOISE_NAMES = {"ou": "OU", "white": "white", "dichotomous": "dichotomous", "harmonic": "harmonic"}


def describe_attrs(attrs: dict[str, Any]) -> str:
    """'white noise, D = 1, omega = 1' or 'OU noise, D = 1, tau = 0.1, omega = 1' for the
    paper's pendulum; another noise by its own name (the report labelled dichotomous and
    harmonic-noise runs "OU noise"), and an oscillator or coupling other than the pendulum's
    named first ('quartic oscillator x^4/4, position coupling, harmonic noise, ...')."""
    D = float(attrs["D"])
    omega = float(attrs["omega"])
    noise = str(attrs["noise"])
    model = _describe_model(attrs)
    if noise == "white":
        text = f"white noise, D = {D:g}, ω = {omega:g}"
    else:
        text = f"{_NOISE_NAMES.get(noise, noise)} noise, D = {D:g}, τ = {float(attrs['tau']):g}"
        omega_noise = attrs.get("omega_noise")
        if noise == "harmonic" and omega_noise not in (None, "none"):
            text += f", W = {float(omega_noise):g}"
        text += f", ω = {omega:g}"
    return f"{model}, {text}" if model else text


def _describe_model(attrs: dict[str, Any]) -> str:
    """The oscillator and coupling, when they are not the paper's pendulum driven through its
    force ('' then: the paper's captions stay as they were)."""
    potential = str(attrs.get("potential", "pendulum"))
    coupling = str(attrs.get("coupling", "force"))
    if potential == "power":
        n = int(attrs.get("power_n", 2))
        name = "quartic oscillator (x⁴/4)" if n == 2 else f"power oscillator (x^{2 * n}/{2 * n})"
    elif potential == "harmonic":
        name = "harmonic oscillator"
    elif potential == "pendulum":
        name = "" if coupling == "force" else "pendulum"
    else:
        name = potential
    if coupling != "force":
        name += f", {coupling} coupling"
    return name


def fmt_num(x: float) -> str:
    """Compact number for captions: 10000 -> '10⁴', 0.01 -> '0.01', 300 -> '300'."""
    if x == 0 or not math.isfinite(x):
        return f"{x:g}"
    e = math.log10(abs(x))
    if abs(e - round(e)) < 1e-9 and abs(e) >= 3:
        sup = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
        return "10" + str(int(round(e))).translate(sup)
    return f"{x:.4g}"


# ---------------------------------------------------------------------------------------------
# Statistics of a run, scaled, with leave-one-batch-out replicas
# ---------------------------------------------------------------------------------------------


def attr_float(ds: xr.Dataset, name: str) -> float:
    v: Any = ds.attrs.get(name)
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan


def norm_series(ds: xr.Dataset, kind: str) -> np.ndarray:
    """The normalisation of a scaled observable at the run's times.

    ``kind``: "one" (1), "Dt" (D t), "(Dt)^2", "Dt/tau2" (D t/tau^2), "sqrt(Dt/tau2)".
    """
    t = ds["time"].values
    D = attr_float(ds, "D")
    tau = attr_float(ds, "tau")
    if kind == "one":
        return np.ones_like(t)
    if kind == "Dt":
        return D * t
    if kind == "(Dt)^2":
        return (D * t) ** 2
    if kind == "Dt/tau2":
        return D * t / tau**2
    if kind == "sqrt(Dt/tau2)":
        return np.sqrt(D * t / tau**2)
    raise ValueError(f"kind={kind!r} is not accepted: one of one, Dt, (Dt)^2, Dt/tau2, sqrt(Dt/tau2)")


def scaled(ds: xr.Dataset, var: str, kind: str = "one") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(t, value/norm, stderr/norm)`` of a statistic, where t > 0."""
    t = ds["time"].values
    norm = norm_series(ds, kind)
    with np.errstate(divide="ignore", invalid="ignore"):
        v = ds[var].values / norm
        se = ds[f"{var}_stderr"].values / norm
    keep = t > 0
    return t[keep], v[keep], se[keep]


def leave_one_out(ds: xr.Dataset, var: str) -> np.ndarray | None:
    """Leave-one-batch-out values of a statistic, shape (n_batches, n_times), or None.

    Computed from the per-batch sums ``batch_sums`` that :mod:`stochpend.paper.reproduce` stores with
    each run, with the same statistic functions as the simulator (:data:`stochpend.model.power_sums.STATISTICS`).
    """
    if "batch_sums" not in ds:
        return None
    from stochpend.model.power_sums import STATISTICS

    of = STATISTICS[var] if var in STATISTICS else _user_statistic(ds, var)
    if of is None:
        return None

    sums = np.asarray(ds["batch_sums"].values, dtype=np.float64)
    if sums.shape[0] < 2:
        return None
    total = sums.sum(axis=0)
    loo = total[None] - sums
    count = loo[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        means = loo / np.where(count > 0, count, np.nan)[..., None]
        return np.asarray(of(means))


def _user_statistic(ds: xr.Dataset, var: str) -> Any:
    """The function of the means that gives a user observable's statistic ``var`` (e.g.
    ``mean_displacement``) of a run that asked for it, or None."""
    names = tuple(n.strip() for n in str(ds.attrs.get("observables", "")).split(",") if n.strip())
    if not names or any(observables.get(n) is None for n in names):
        return None
    for s in observables.user_statistics(names, np.asarray(ds.time.values, dtype=np.float64)):
        if s.name == var:
            return s.of
    return None


@dataclass
class Fit:
    """Result of a late-time fit ``value(t) = a + b t^{-p}`` over ``[t_lo, t_hi]``."""

    value: float
    stderr: float
    power: float
    t_lo: float
    t_hi: float
    n_points: int
    error_method: str
    alt_value: float = math.nan
    alt_stderr: float = math.nan
    alt_power: float = math.nan

    @property
    def model(self) -> str:
        return model_text(self.power)


def model_text(power: float) -> str:
    return "a + b/t" if power == 1 else f"a + b·t^-{power:g}"


def _wls_intercept(x: np.ndarray, y: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted least squares of y = a + b x (y may be (n_rep, n)): returns (a, b)."""
    sw = w.sum()
    sx = (w * x).sum()
    sxx = (w * x * x).sum()
    sy = (y * w).sum(axis=-1)
    sxy = (y * w * x).sum(axis=-1)
    det = sw * sxx - sx * sx
    a = (sxx * sy - sx * sxy) / det
    b = (sw * sxy - sx * sy) / det
    return a, b


def _jackknife(values: np.ndarray) -> float:
    values = values[np.isfinite(values)]
    n = values.size
    if n < 2:
        return math.nan
    return float(math.sqrt((n - 1) / n * np.sum((values - values.mean()) ** 2)))


def extrapolate(
    ds: xr.Dataset, var: str, kind: str, *, power: float, alt_power: float | None = None,
    window: float = FIT_WINDOW,
) -> Fit | None:
    """Fit ``a + b t^{-power}`` to ``var/norm`` over the last ``window`` factor of times.

    The error of ``a`` is the delete-one-batch jackknife of the whole fit when the run holds
    its per-batch sums; otherwise the least-squares error (which ignores the correlation
    between times and underestimates the error; marked in ``error_method``). Returns None when
    fewer than 3 usable points lie in the window.
    """
    t, v, se = scaled(ds, var, kind)
    t_hi = float(t[-1])
    sel = (t >= t_hi / window * (1 - 1e-12)) & np.isfinite(v) & np.isfinite(se) & (se > 0)
    if sel.sum() < 3:
        return None
    loo = leave_one_out(ds, var)
    if loo is not None:
        norm = norm_series(ds, kind)[ds["time"].values > 0]
        loo = loo[:, ds["time"].values > 0] / norm[None, :]
        loo = loo[:, sel]
        loo = loo[np.all(np.isfinite(loo), axis=1)]
    w = 1.0 / se[sel] ** 2

    def one(p: float) -> tuple[float, float, str]:
        x = t[sel] ** (-p)
        a, _ = _wls_intercept(x, v[sel], w)
        if loo is not None and loo.shape[0] >= 2:
            a_rep, _ = _wls_intercept(x, loo, w)
            return float(a), _jackknife(np.asarray(a_rep)), "delete-one-batch jackknife of the fit"
        # Least-squares error (assumes independent points): a lower bound.
        X = np.stack([np.ones_like(x), x], axis=1)
        cov = np.linalg.inv(X.T @ (X * w[:, None]))
        return float(a), float(math.sqrt(cov[0, 0])), "least-squares error (ignores time correlations)"

    a, sa, method = one(power)
    fit = Fit(a, sa, power, float(t[sel][0]), t_hi, int(sel.sum()), method)
    if alt_power is not None:
        fit.alt_value, fit.alt_stderr, _ = one(alt_power)
        fit.alt_power = alt_power
    return fit


def log_slope(ds: xr.Dataset, var: str = "mean_E", *, window: float = FIT_WINDOW) -> tuple[float, float, float]:
    """Slope of ln(var) vs ln(t) over the last ``window`` factor of times, with jackknife error.

    Returns ``(slope, stderr, t_lo)``.
    """
    t, v, se = scaled(ds, var, "one")
    sel = (t >= t[-1] / window * (1 - 1e-12)) & (v > 0)
    x = np.log(t[sel])
    w = np.ones_like(x)
    _, b = _wls_intercept(x, np.log(v[sel]), w)
    loo = leave_one_out(ds, var)
    err = math.nan
    if loo is not None:
        rep = loo[:, ds["time"].values > 0][:, sel]
        rep = rep[np.all(rep > 0, axis=1)]
        if rep.shape[0] >= 2:
            _, b_rep = _wls_intercept(x, np.log(rep), w)
            err = _jackknife(np.asarray(b_rep))
    return float(b), err, float(t[sel][0])


def slope_of_curve(t: np.ndarray, y: np.ndarray, t_lo: float) -> float:
    """Least-squares slope of ln y vs ln t over ``t >= t_lo`` (for theory curves)."""
    sel = (t >= t_lo * (1 - 1e-12)) & (y > 0)
    x = np.log(t[sel])
    _, b = _wls_intercept(x, np.log(y[sel]), np.ones_like(x))
    return float(b)


# ---------------------------------------------------------------------------------------------
# Table rows
# ---------------------------------------------------------------------------------------------

#: Column titles of every figure table (same order as :meth:`Row.cells`).
COLUMNS = (
    "Run",
    "Quantity",
    "t",
    "Value at t",
    "t → ∞ (fit)",
    "t → ∞ (other model)",
    "Theory",
    "Prediction",
    "Dev. at t (σ)",
    "Dev. t → ∞ (σ)",
)

DASH = "—"


@dataclass
class Row:
    """One comparison: a measured quantity of one run against one prediction.

    ``prediction`` is compared with the value at ``t`` and, when ``fit`` is set, with the
    extrapolated value; deviations are in units of the respective standard errors.
    """

    run: str
    quantity: str
    t: float
    value: float
    stderr: float
    theory: str
    prediction: float
    fit: Fit | None = None
    fit_note: str = ""
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def dev_at_t(self) -> float:
        return deviation(self.value, self.stderr, self.prediction)

    @property
    def dev_extrapolated(self) -> float:
        if self.fit is None:
            return math.nan
        return deviation(self.fit.value, self.fit.stderr, self.prediction)

    def cells(self) -> list[str]:
        """The row as text, one string per column of :data:`COLUMNS` (never empty)."""
        if self.fit is not None:
            fit = f"{fmt_se(self.fit.value, self.fit.stderr)} ({self.fit.model}, t ≥ {self.fit.t_lo:.3g})"
            alt = (f"{fmt_se(self.fit.alt_value, self.fit.alt_stderr)} ({model_text(self.fit.alt_power)})"
                   if math.isfinite(self.fit.alt_value) else DASH)
        else:
            fit = self.fit_note or DASH
            alt = DASH
        return [
            self.run,
            self.quantity,
            f"{self.t:.4g}",
            fmt_se(self.value, self.stderr),
            fit,
            alt,
            self.theory,
            f"{self.prediction:.4g}",
            fmt_dev(self.dev_at_t),
            fmt_dev(self.dev_extrapolated) if self.fit is not None else DASH,
        ]

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        d["dev_at_t"] = self.dev_at_t
        d["dev_extrapolated"] = self.dev_extrapolated
        return d


def deviation(value: float, stderr: float, prediction: float) -> float:
    if not (math.isfinite(value) and math.isfinite(stderr)) or stderr <= 0:
        return math.nan
    return (value - prediction) / stderr


def fmt_dev(d: float) -> str:
    if not math.isfinite(d):
        return "n/a"
    return f"{d:+.1f}"


def fmt_se(value: float, se: float) -> str:
    """Value with its standard error in the one notation of every table (:func:`stochpend.
    _notation.ve`), e.g. 0.3482(22)."""
    return ve(value, se)


def at_last(ds: xr.Dataset, var: str, kind: str) -> tuple[float, float, float]:
    """``(t_last, value/norm, stderr/norm)`` at the last output time."""
    t, v, se = scaled(ds, var, kind)
    return float(t[-1]), float(v[-1]), float(se[-1])


def run_label(ds: xr.Dataset) -> str:
    return describe_attrs(ds.attrs)
