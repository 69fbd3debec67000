"""Gallery (d): the damped random-frequency oscillator, mean-square and typical growth.

    x'' + gamma x' + (omega^2 + xi(t)) x = 0,  <xi xi'> = D delta

(``potential="harmonic"``, ``coupling="position"``; for the harmonic oscillator the force
coupling is the same model). <E> grows (or decays) at the exact rate of the second moments,
:func:`stochpend.theory.family.random_frequency_moment_growth_rate`, which changes sign at
D_c = 2 gamma omega^2 (:func:`random_frequency_threshold`). A typical path grows at twice the
top Lyapunov exponent, <ln E>/t -> 2 lambda (:func:`random_frequency_lyapunov`, Riccati
quadrature), which changes sign at a larger D (:func:`random_frequency_typical_threshold`):
between the two thresholds <E> grows while almost every path decays.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr

from stochpend.model import observables
from stochpend.paper.figures._common import FigureRun, Row, fmt_num
from stochpend.paper.figures._family import window_slope


def _ln_energy(x: float, Omega: float, xi: float, t: float) -> float:
    return math.log(0.5 * Omega * Omega + 0.5 * x * x)


#: ln E of one path for omega = 1 (E = Omega^2/2 + x^2/2); registered on import so that a stored
#: run's statistics are read back with it.
LN_ENERGY = observables.register(observables.Observable(
    "lnE_harmonic_omega1", _ln_energy, label="⟨ln E⟩",
    description="<ln E>, E = Omega^2/2 + x^2/2 (the harmonic oscillator's energy at omega = 1)"))

NAME = "family-random-frequency"
TITLE = "Family (d) — damped random-frequency oscillator: mean-square and typical growth rates"

#: gamma = 0.5, omega = 1: D_c = 1, typical threshold ~2.1. The rates are slopes against t over
#: [t_max/2, t_max]; t_max = 20 is short on purpose: the sample mean of an exponentially growing,
#: ever more skewed E under-represents the rare large paths once ln E spreads by more than
#: ~ln(paths) (the exponents table's harmonic runs, same reason). A fixed step h = 0.01 (the
#: linear oscillator has no large-energy stiffness; the adaptive control would shrink the step
#: with the amplitude for nothing). ``paths`` at the default reproduction (10^4 asked).
CONFIG: dict[str, Any] = {
    "gamma": 0.5,
    "omega": 1.0,
    "D": [0.25, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0],
    # The window of the mean-square rate, per D (fractions of t_max): late where the moments'
    # transient is slow (small D: the other eigenvalues are only ~0.2 below the largest), early
    # where the spread of ln E grows fast (large D: at D = 3 over [10, 20] the measured slope was
    # 0.40(4) against 0.67, the rare large paths missing from 2·10⁴).
    "moment_window": {0.25: (0.5, 1.0), 0.5: (0.5, 1.0), 1.0: (0.5, 1.0), 1.5: (0.2, 0.4),
                      2.0: (0.15, 0.3), 3.0: (0.1, 0.2), 4.0: (0.075, 0.15)},
    "seed0": 2600,
    "paths": 20_000,
    "t_max": 20.0,
    "quick_t_max": 10.0,
    "h": 0.01,
    "x0": 1.0,
}
DEFAULT_PATHS = 10_000
WINDOW_START = 0.5


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    T_end = t_max if t_max is not None else (CONFIG["quick_t_max"] if quick else CONFIG["t_max"])
    n = max(2, round(CONFIG["paths"] * paths / DEFAULT_PATHS))
    g, w = CONFIG["gamma"], CONFIG["omega"]
    return [FigureRun(key=f"family_random_frequency_D{D:g}_gamma{g:g}", label=f"D = {D:g}", noise="white",
                    D=float(D), tau=None, omega=w, t_max=float(T_end), seed=CONFIG["seed0"] + i + 1, paths=n,
                    potential="harmonic", coupling="position", h_max=CONFIG["h"], step_c=0.0,
                    params=(("gamma", g),), theta0=CONFIG["x0"], Omega0=0.0,
                    observables=(LN_ENERGY.name,))
            for i, D in enumerate(CONFIG["D"])]


def caption(figure_runs: list[FigureRun]) -> str:
    s = figure_runs[0]
    g = s.param("gamma")
    Ds = ", ".join(f"{x.D:g}" for x in figure_runs)
    seeds = f"{min(x.seed for x in figure_runs)}–{max(x.seed for x in figure_runs)}"
    t1 = WINDOW_START * s.t_max
    return (
        f"Damped random-frequency oscillator x'' + γx' + (ω² + ξ)x = 0 (potential 'harmonic', noise on x), "
        f"Gaussian white ξ, ⟨ξξ′⟩ = Dδ, γ = {g:g}, ω = {s.omega:g}, D = {Ds}; {s.paths} realizations each "
        f"(seeds {seeds}), x(0) = {s.theta0}, Ω(0) = 0, fixed step h = {s.h_max:g}, to t = {fmt_num(s.t_max)}. "
        f"(a) ln⟨E⟩ (solid) and ⟨ln E⟩ (dashed) vs t; (b) their growth rates, least-squares slopes against t "
        f"(⟨ln E⟩ over [{t1:g}, {fmt_num(s.t_max)}]; ln⟨E⟩ over a window per D, late for small D, where the "
        f"moments' transient is slow, early for large D, table) (±2 s.e., jackknife over batches), vs D. Lines: the exact "
        f"mean-square rate (largest eigenvalue of the closed second-moment equations, stochpend.theory."
        f"family.random_frequency_moment_growth_rate), zero at D_c = 2γω² (random_frequency_threshold); "
        f"twice the top Lyapunov exponent 2λ (Riccati quadrature, random_frequency_lyapunov), zero at the "
        f"typical threshold (random_frequency_typical_threshold). ⟨ln E⟩ is the registered observable "
        f"'{LN_ENERGY.name}', ln(Ω²/2 + x²/2). The windows of ln⟨E⟩ are short at large D because the "
        f"sample mean of a log-normally spreading E misses the rare large paths once the spread of ln E "
        f"exceeds ~ln(paths): there the measured slope falls below the exact rate, and its jackknife error "
        f"understates the uncertainty. The table gives each ln⟨E⟩ slope against the t → ∞ rate and "
        f"against the exact second moments' slope over the same window (which includes the transient)."
    )


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    from stochpend.theory import family as fam

    ds0 = next(iter(datasets.values()))
    g, w = float(ds0.attrs["gamma"]), float(ds0.attrs["omega"])
    Ds = sorted(float(ds.attrs["D"]) for ds in datasets.values())
    return {
        "gamma": g, "omega": w,
        "D_c": fam.random_frequency_threshold(gamma=g, omega=w),
        "D_typ": fam.random_frequency_typical_threshold(gamma=g, omega=w),
        "moment": {D: fam.random_frequency_moment_growth_rate(D=D, gamma=g, omega=w) for D in Ds},
        "typical": {D: 2.0 * fam.random_frequency_lyapunov(D=D, gamma=g, omega=w) for D in Ds},
        "moment_window": {float(ds.attrs["D"]): exact_moment_slope(ds) for ds in datasets.values()},
    }


def moment_window(ds: xr.Dataset) -> tuple[float, float]:
    """The window [t_lo, t_hi] of the mean-square rate of this run (``CONFIG["moment_window"]``)."""
    t_last = float(ds["time"].values[-1])
    a, b = CONFIG["moment_window"].get(float(ds.attrs["D"]), (WINDOW_START, 1.0))
    return a * t_last, b * t_last


def exact_moment_slope(ds: xr.Dataset) -> float:
    """Slope of ln<E> over the run's moment window from the exact second moments of the run's
    initial state (expm of :func:`stochpend.theory.family.random_frequency_moment_matrix`): the
    mean-square rate with the window's own transient."""
    from scipy.linalg import expm

    from stochpend.theory import family as fam

    D, g, w = float(ds.attrs["D"]), float(ds.attrs["gamma"]), float(ds.attrs["omega"])
    M = fam.random_frequency_moment_matrix(D=D, gamma=g, omega=w)
    x0, v0 = float(ds.attrs["theta0"]), float(ds.attrs["Omega0"])
    m0 = np.array([x0 * x0, x0 * v0, v0 * v0])
    t = ds["time"].values
    lo, hi = moment_window(ds)
    sel = (t >= lo * (1 - 1e-12)) & (t <= hi * (1 + 1e-12))
    E = np.array([0.5 * (m[2] + w * w * m[0]) for m in (expm(M * tt) @ m0 for tt in t[sel])])
    return float(np.polyfit(t[sel], np.log(E), 1)[0])


def rates(ds: xr.Dataset) -> dict[str, tuple[float, float]]:
    t_lo = WINDOW_START * float(ds["time"].values[-1])
    lo, hi = moment_window(ds)
    return {"moment": window_slope(ds, "mean_E", lo, hi, log=True),
            "typical": window_slope(ds, LN_ENERGY.statistic, t_lo)}


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    from stochpend.paper import plotting
    from stochpend.theory import family as fam

    fig, (ax_a, ax_b) = plotting.new_figure((11.0, 4.6), ncols=2)
    Ds, m, me, ty, tye = [], [], [], [], []
    for i, ds in enumerate(datasets.values()):
        D = float(ds.attrs["D"])
        t = ds["time"].values
        keep = t >= 0.1
        with np.errstate(divide="ignore", invalid="ignore"):
            ax_a.plot(t[keep], np.log(ds["mean_E"].values[keep]), color=f"C{i}", label=f"D = {D:g}")
        ax_a.plot(t[keep], ds[LN_ENERGY.statistic].values[keep], color=f"C{i}", linestyle="--")
        r = rates(ds)
        Ds.append(D)
        m.append(r["moment"][0])
        me.append(r["moment"][1])
        ty.append(r["typical"][0])
        tye.append(r["typical"][1])
    ax_a.set_xlabel("$t$")
    ax_a.set_ylabel(r"$\ln\langle E\rangle$ (solid), $\langle\ln E\rangle$ (dashed)")
    ax_a.legend(loc="upper left", fontsize=8, ncol=2)
    ax_a.set_title("(a)", loc="left")
    g, w = theory["gamma"], theory["omega"]
    DD = np.linspace(0.05, max(Ds) * 1.05, 150)
    ax_b.errorbar(Ds, m, yerr=2 * np.asarray(me), fmt="o", color="C0", capsize=3, label="d ln⟨E⟩/dt")
    ax_b.errorbar(Ds, ty, yerr=2 * np.asarray(tye), fmt="s", color="C3", capsize=3, fillstyle="none",
                  label="d⟨ln E⟩/dt")
    plotting.plot_theory(ax_b, DD, np.array([fam.random_frequency_moment_growth_rate(D=D, gamma=g, omega=w)
                                             for D in DD]),
                         label="mean-square rate (exact)", color="C0")
    plotting.plot_theory(ax_b, DD, np.array([2 * fam.random_frequency_lyapunov(D=D, gamma=g, omega=w) for D in DD]),
                         label="2λ (Riccati)", color="C3")
    ax_b.axhline(0.0, color="0.6", linewidth=0.6)
    ax_b.axvline(theory["D_c"], color="C0", linestyle="--", linewidth=0.8, label=f"D_c = 2γω² = {theory['D_c']:g}")
    ax_b.axvline(theory["D_typ"], color="C3", linestyle="-.", linewidth=0.8,
                 label=f"typical threshold = {theory['D_typ']:.3g}")
    ax_b.set_xlabel("$D$")
    ax_b.set_ylabel("growth rate")
    ax_b.legend(loc="upper left", fontsize=8)
    ax_b.set_title(f"(b) γ = {g:g}, ω = {w:g}", loc="left")
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    th = theory_values or theory(datasets)
    rows: list[Row] = []
    for ds in datasets.values():
        D = float(ds.attrs["D"])
        t = float(ds["time"].values[-1])
        t_lo = WINDOW_START * t
        r = rates(ds)
        label = f"D = {D:g}, γ = {th['gamma']:g}"
        note = f"slope over [{t_lo:g}, {t:g}]"
        lo, hi = moment_window(ds)
        q = f"d ln⟨E⟩/dt over [{lo:.3g}, {hi:.3g}]"
        m_note = f"slope over [{lo:.3g}, {hi:.3g}]"
        rows.append(Row(label, q, hi, r["moment"][0], r["moment"][1],
                        "mean-square rate, t → ∞ (random_frequency_moment_growth_rate)", th["moment"][D], None,
                        m_note))
        rows.append(Row(label, q, hi, r["moment"][0], r["moment"][1],
                        "exact second moments from x(0), slope over the same window (expm of "
                        "random_frequency_moment_matrix)", th["moment_window"][D], None, m_note))
        rows.append(Row(label, f"d⟨ln E⟩/dt over [{t_lo:.3g}, {t:.3g}]", t, r["typical"][0], r["typical"][1],
                        "2λ, Riccati (random_frequency_lyapunov)", th["typical"][D], None, note))
    return rows
