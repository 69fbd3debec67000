"""The scaling-exponent table: long-time growth of <E> beyond the paper's two cases.

For each (oscillator, coupling, noise) of the table, one run; the measured law is a fit over
the last decade of the run (:mod:`stochpend.exponents`: slope of log <E> against log t, or
against t for an exponential, with delete-one-batch jackknife errors), compared with the
prediction of :func:`stochpend.theory.scaling.predicted_exponent` (derivations in
``docs/scaling.md``). The quartic oscillator with the noise on the force blows up in finite
time: its row reports the fraction of paths that escaped (frozen and counted, never averaged).

Figure: (a) the local exponent d log<E>/d log t of every power-law run against t, with the
predicted levels; (b) the escaped fraction of the blow-up runs and log<E> of the exponential run.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr

from stochpend.paper.figures._common import FigureRun, Row, fmt_num

#: The reproduction's default paths per run: each case's ``paths`` is its size at that default
#: (``reproduce(paths=...)`` scales them all, e.g. --quick's 500 gives 5 %).
DEFAULT_PATHS = 10_000

NAME = "exponents"
TITLE = "Scaling exponents — pendulum, quartic and harmonic oscillators, four noises"

#: Every run has D = 1, omega = 1 and, for the colored noises, tau = 1 (harmonic noise: W = 2,
#: critical damping). The fit window is [t_max/10, t_max]; ``paths``: the size at the default
#: reproduction (cost). Why these times: the colored-noise pendulum runs are 10^3 crossover times in
#: (t_c = 1/(D tau^2) = 1), where the paper's corrections are a few per cent of the exponent;
#: the quartic position-coupling runs reach orbit frequencies ~ E^(1/4) >> 1/tau.
CASES: list[dict[str, Any]] = [
    dict(key="pendulum_white", label="pendulum, white", noise="white", tau=None, t_max=1e3,
         paths=10_000, seed=801),
    dict(key="pendulum_ou", label="pendulum, OU", noise="ou", tau=1.0, t_max=1e4, paths=10_000,
         seed=802),
    dict(key="pendulum_dichotomous", label="pendulum, dichotomous", noise="dichotomous", tau=1.0,
         t_max=1e4, paths=10_000, seed=803),
    dict(key="pendulum_harmonic_noise", label="pendulum, harmonic noise", noise="harmonic",
         tau=1.0, t_max=1e4, paths=4000, seed=804),
    dict(key="quartic_position_white", label="quartic x⁴/4, noise on x, white", noise="white",
         tau=None, t_max=3e3, paths=2000, seed=805, potential="power",
         coupling="position"),
    dict(key="quartic_position_ou", label="quartic x⁴/4, noise on x, OU", noise="ou", tau=1.0,
         t_max=1e4, paths=4000, seed=806, potential="power", coupling="position"),
    dict(key="quartic_position_harmonic_noise", label="quartic x⁴/4, noise on x, harmonic noise",
         noise="harmonic", tau=1.0, t_max=1e4, paths=2000, seed=810,
         potential="power", coupling="position"),
    dict(key="quartic_force_white", label="quartic x⁴/4, noise on force, white", noise="white",
         tau=None, t_max=10.0, paths=2000, seed=807, potential="power",
         coupling="force"),
    dict(key="quartic_force_ou", label="quartic x⁴/4, noise on force, OU", noise="ou", tau=1.0,
         t_max=30.0, paths=2000, seed=808, potential="power", coupling="force"),
    # The sample mean of an exponentially growing, ever more skewed E under-represents the rare
    # large paths once log E spreads by more than ~log(paths): a short window and many paths.
    dict(key="harmonic_white", label="harmonic x²/2, white", noise="white", tau=None, t_max=10.0,
         paths=100_000, seed=809, potential="harmonic", coupling="force"),
]
QUICK_T_MAX = 30.0  # --quick: a smoke test of the pipeline


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    figure_runs = []
    for case in CASES:
        T = case["t_max"]
        if t_max is not None:
            T = t_max
        elif quick:
            T = min(T, QUICK_T_MAX)
        figure_runs.append(FigureRun(
            key=f"exponent_{case['key']}", label=case["label"], noise=case["noise"], D=1.0,
            tau=case["tau"], omega=1.0, t_max=T, seed=case["seed"],
            paths=max(16, round(case["paths"] * paths / DEFAULT_PATHS)),
            t_min=min(1e-2, T / 1e3), per_decade=8, potential=case.get("potential", "pendulum"),
            coupling=case.get("coupling", "force"),
        ))
    return figure_runs


def caption(figure_runs: list[FigureRun]) -> str:
    lines = ", ".join(f"{s.label} ({s.paths} paths, t ≤ {fmt_num(s.t_max)}, seed {s.seed})" for s in figure_runs)
    return (
        "Long-time growth of ⟨E⟩ for D = 1, ω = 1, τ = 1 (harmonic noise: W = 2/τ), θ(0) or x(0) "
        "uniform on [−π, π), Ω(0) = 0, stationary noise. Power laws: least-squares slope of "
        "log⟨E⟩ against log t over the last decade [t_max/10, t_max], jackknife error over 100 "
        "batches; exponential: slope of log⟨E⟩ against t over the same window; blow-up: fraction "
        "of paths escaped by t_max (frozen when the step control asks for a step below 1e-9 "
        f"h_max, or non-finite). Predictions: docs/scaling.md. Runs: {lines}."
    )


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    from stochpend.theory.scaling import harmonic_growth_rate, predicted_exponent

    out: dict[str, Any] = {}
    for key, ds in datasets.items():
        a = ds.attrs
        pred = predicted_exponent(a["potential"], a["noise"], a["coupling"], int(a["power_n"]))
        rate = math.nan
        if pred.growth == "exponential":
            tau: Any = a.get("tau")
            rate = harmonic_growth_rate(a["noise"], D=float(a["D"]), omega=float(a["omega"]),
                                        tau=None if tau == "none" else float(tau))
        out[key] = {"prediction": pred, "rate": rate}
    return out


def harmonic_white_mean_E(t: np.ndarray, D: float, omega: float, x2_0: float) -> np.ndarray:
    """Exact <E(t)> of the harmonic oscillator with white noise (either coupling), from the
    closed second-moment system m = (<x^2>, <x Omega>, <Omega^2>) (Ito):
    dm/dt = M m, M = [[0, 2, 0], [-omega^2, 0, 1], [D, -2 omega^2, 0]], m(0) = (x2_0, 0, 0)
    (x(0) uniform, Omega(0) = 0); E = Omega^2/2 + omega^2 x^2/2. Its growth rate tends to the
    real root of lambda^3 + 4 omega^2 lambda = 2 D (``harmonic_growth_rate``)."""
    import scipy.linalg

    w2 = omega * omega
    M = np.array([[0.0, 2.0, 0.0], [-w2, 0.0, 1.0], [D, -2.0 * w2, 0.0]])
    m0 = np.array([x2_0, 0.0, 0.0])
    out = []
    for ti in np.atleast_1d(t):
        m = scipy.linalg.expm(M * ti) @ m0
        out.append(0.5 * m[2] + 0.5 * w2 * m[0])
    return np.array(out)


def _window(ds: xr.Dataset) -> tuple[float, float]:
    T = float(ds.time[-1])
    return T / 10.0, T


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    from stochpend.paper import plotting

    fig, (ax_a, ax_b) = plotting.new_figure((11.0, 4.9), ncols=2)
    colors = iter(f"C{i}" for i in range(10))
    for key, ds in datasets.items():
        pred = theory[key]["prediction"]
        color = next(colors)
        t = ds.time.values
        E = ds.mean_E.values
        logE = np.log(np.where(E > 0, E, np.nan))  # early pendulum energies can be <= 0
        if pred.growth == "power":
            slope = np.diff(logE) / np.diff(np.log(t))
            tm = np.sqrt(t[1:] * t[:-1])
            keep = tm > 1.0
            ax_a.plot(tm[keep], slope[keep], color=color, lw=1.0, label=ds.attrs.get("reproduce_label", key))
            ax_a.axhline(pred.exponent, color=color, ls=":", lw=1.0)
        elif pred.growth == "finite-time blow-up":
            frac = ds.nonfinite_paths.values / float(ds.attrs["paths"])
            ax_b.plot(t, frac, color=color, label=f"{ds.attrs.get('reproduce_label', key)}: escaped fraction")
        else:
            ax_b.plot(t, logE / 10.0, color=color,
                      label=f"{ds.attrs.get('reproduce_label', key)}: log⟨E⟩/10")
            rate = theory[key]["rate"]
            lo, hi = _window(ds)
            tt = np.linspace(lo, hi, 50)
            i = np.searchsorted(t, lo)
            ax_b.plot(tt, (logE[i] + rate * (tt - t[i])) / 10.0, color="k", ls=":", lw=1.0,
                      label=f"rate {rate:.4f} (exact)")
    ax_a.set_xscale("log")
    ax_a.set_xlabel("$t$")
    ax_a.set_ylabel(r"local exponent $d\log\langle E\rangle/d\log t$")
    ax_a.set_ylim(0.0, 2.6)
    ax_a.legend(fontsize=7, loc="upper left")
    ax_a.set_title("(a) power laws; dotted: predictions", loc="left")
    ax_b.set_xscale("log")
    ax_b.set_xlabel("$t$")
    ax_b.legend(fontsize=7, loc="upper left")
    ax_b.set_title("(b) blow-up and exponential growth", loc="left")
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    from stochpend.theory.exponents import fit_exponent, fit_rate, fit_slope
    from stochpend.theory.scaling import quartic_position_heating_rate

    th = theory_values or theory(datasets)
    rows = []
    for key, ds in datasets.items():
        pred = th[key]["prediction"]
        label = str(ds.attrs.get("reproduce_label", key))
        lo, hi = _window(ds)
        paths = int(ds.attrs["paths"])
        if pred.growth in ("power", "exponential"):
            try:
                fit = (fit_exponent if pred.growth == "power" else fit_rate)(ds, lo, hi)
            except ValueError as error:  # e.g. <E> <= 0 in a window too early (tiny test runs)
                rows.append(Row(label, "no fit", hi, math.nan, math.nan, f"{pred.source}",
                                math.nan if pred.exponent is None else float(pred.exponent), None,
                                str(error)))
                continue
        if pred.growth == "power":
            rows.append(Row(label, f"ν, ⟨E⟩ ~ t^ν over [{fmt_num(fit.t_min)}, {fmt_num(fit.t_max)}]",
                            fit.t_max, fit.exponent, fit.se, f"{pred.source}: {pred.regime}",
                            float(pred.exponent), None, f"{paths} paths, {fit.nonfinite} non-finite"))
            a = ds.attrs
            if (a["potential"], a["coupling"], int(a["power_n"])) == ("power", "position", 2) \
                    and a["noise"] in ("ou", "dichotomous"):
                # The averaged law is linear with an offset, <E(0)> + A t: its log-log slope
                # tends to 1 slowly, so the rate A itself is the sharper test.
                lin = fit_slope(ds, lo, hi)
                rate = quartic_position_heating_rate(a["noise"], D=float(a["D"]),
                                                     tau=float(a["tau"]), omega=float(a["omega"]))
                rows.append(Row(label, f"A = d⟨E⟩/dt over [{fmt_num(lin.t_min)}, {fmt_num(lin.t_max)}]",
                                lin.t_max, lin.exponent, lin.se,
                                f"{pred.source}: A = (3/8)(D/τ²) Var(x²/2)/(Eω²), sec. 8", rate,
                                None, f"{paths} paths"))
        elif pred.growth == "exponential":
            # The prediction over the same window: the slope of the exact log <E(t)> (initial
            # transient included); its t -> infinity limit is th[key]["rate"].
            t = ds.time.values
            sel = (t >= fit.t_min) & (t <= fit.t_max)
            exact = harmonic_white_mean_E(t[sel], float(ds.attrs["D"]), float(ds.attrs["omega"]),
                                          math.pi**2 / 3.0)
            window_rate = float(np.polyfit(t[sel], np.log(exact), 1)[0])
            rows.append(Row(label, f"λ, ⟨E⟩ ~ e^(λt) over [{fmt_num(fit.t_min)}, {fmt_num(fit.t_max)}]",
                            fit.t_max, fit.exponent, fit.se,
                            f"{pred.source}: exact second moments, slope over the window "
                            f"(→ {th[key]['rate']:.4f} as t → ∞)",
                            window_rate, None, f"{paths} paths"))
        else:
            n_bad = int(ds.nonfinite_paths.values[-1])
            p = n_bad / paths
            rows.append(Row(label, "escaped fraction (finite-time blow-up)", float(ds.time[-1]), p,
                            math.sqrt(max(p * (1 - p), 1.0 / paths) / paths),
                            f"{pred.source}: {pred.growth}; the fraction grows to 1", math.nan, None,
                            f"{n_bad} of {paths} paths escaped"))
    return rows
