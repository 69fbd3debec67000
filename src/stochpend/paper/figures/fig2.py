"""Fig. 2 (`fig:collapse`): OU noise, omega = 1, (D, tau) in {1, 10, 100} x {0.1, 1, 10}.

<E^2>/(D t/tau^2) vs t for all nine pairs; dotted: 1/4 (second-order averaging,
Eq. `eq:scalE2color`); dash-dotted: 1/2 (first-order averaging, Eq. `quad1`, known to be wrong).
"""

from __future__ import annotations

import math
from typing import Any

import xarray as xr

from stochpend.paper.figures._common import (
    FigureRun,
    Row,
    at_last,
    attr_float,
    extrapolate,
    fmt_num,
    run_key,
)

NAME = "fig2"
TITLE = "Fig. 2 — OU noise, ω = 1: collapse of ⟨E²⟩/(Dt/τ²) for nine (D, τ)"

#: Runs of the caption. Default final times: 10^4 for D = 1 and 10^3 for D = 10, 100. The
#: slowest time scale of a run is t* = max(t_c, tau^2 omega^4/D), with t_c = 1/(D tau^2) the
#: crossover (Eq. `tpcross`) and tau^2 omega^4/D the time at which <E> ~ (D t)^{1/2}/tau passes
#: omega^2 (rotation instead of libration). For D = 1 the worst cases, tau = 0.1 (t_c = 100) and
#: tau = 10 (tau^2/D = 100), need 10^4 to put the last decade at >= 10 t*; for D >= 10 every
#: t* <= 10 and 10^3 suffices (10^4 would cost 5x more for nothing: energies grow with D).
CONFIG: dict[str, Any] = {
    "noise": "ou",
    "omega": 1.0,
    "runs": [
        {"D": D, "tau": tau, "seed": 200 + 3 * i + j + 1, "t_max": 1e4 if D == 1 else 1e3}
        for i, D in enumerate((1.0, 10.0, 100.0))
        for j, tau in enumerate((0.1, 1.0, 10.0))
    ],
    "quick_t_max": 100.0,
}
# The (D, tau) = (1, 1) run is the omega = 1 run of Fig. 3: same seed and times, one cached file.
CONFIG["runs"][1]["seed"] = 301

#: Second-order corrections decay like (t/t_c)^{-1/2} (and omega^2/<E> ~ t^{-1/2}).
FIT_POWER = 0.5
ALT_POWER = 1.0
TAU_COLORS = {0.1: "C0", 1.0: "C2", 10.0: "C3"}
D_STYLES = {1.0: "-", 10.0: "--", 100.0: (0, (5, 1, 1, 1))}


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    out = []
    omega = CONFIG["omega"]
    for r in CONFIG["runs"]:
        T = t_max if t_max is not None else (CONFIG["quick_t_max"] if quick else r["t_max"])
        out.append(FigureRun(
            key=run_key("ou", r["D"], r["tau"], omega), label=f"D = {r['D']:g}, τ = {r['tau']:g}",
            noise="ou", D=r["D"], tau=r["tau"], omega=omega, t_max=T, seed=r["seed"], paths=paths,
        ))
    return out


def slowest_time(D: float, tau: float, omega: float) -> float:
    """t* = max(t_c, tau^2 omega^4/D): after a few t* the second-order law can hold."""
    return max(1.0 / (D * tau**2), tau**2 * omega**4 / D)


def caption(figure_runs: list[FigureRun]) -> str:
    s = figure_runs[0]
    t_maxes = sorted({x.t_max for x in figure_runs})
    if len(t_maxes) == 1:
        trange = f"up to t = {fmt_num(t_maxes[0])}"
    else:
        trange = ("up to t = " + ", ".join(
            f"{fmt_num(T)} for D = " + "/".join(sorted({f"{x.D:g}" for x in figure_runs if x.t_max == T}, key=float))
            for T in t_maxes))
    seeds = ", ".join(str(x.seed) for x in figure_runs)
    return (
        f"Stochastic pendulum with Ornstein–Uhlenbeck noise (Eqs. dyncolOmega–OU), ω = {s.omega:g}, "
        f"(D, τ) ∈ {{1, 10, 100}} × {{0.1, 1, 10}}, {s.paths} realizations each (seeds {seeds}, in "
        f"the order of the legend), stationary ξ(0), θ(0) uniform, Ω(0) = 0; times log-spaced from "
        f"{s.t_min:g}, {trange}. We plot ⟨E²⟩/(Dt/τ²) vs t. Dotted: 0.25 (second-order averaging, "
        f"eq:scalE2color); dash-dotted: 0.5 (first-order averaging, quad1). Shaded: ±2 standard "
        f"errors. Time range: each run is followed to at least 10 times its slowest scale "
        f"t* = max(t_c, τ²ω⁴/D), t_c = 1/(Dτ²), except where --t-max or --quick shortens it; "
        f"convergence is slowest for (D, τ) = (1, 0.1) (t_c = 100), as the paper notes for small τ."
    )


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    from stochpend import theory as th

    return {"ou2_E2": th.OU2_MEAN_E2_PREFACTOR, "ou1_E2": th.OU1_MEAN_E2_PREFACTOR}


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    from stochpend.paper import plotting

    fig, ax = plotting.new_figure((9.0, 5.0))
    t_hi = max(float(ds.time[-1]) for ds in datasets.values())
    for ds in datasets.values():
        D, tau = attr_float(ds, "D"), attr_float(ds, "tau")
        plotting.plot_ratio(ds, "ou_E2", ax=ax, label=f"D = {D:g}, τ = {tau:g}", t_min=0.1,
                            color=TAU_COLORS.get(tau), linestyle=D_STYLES.get(D, "-"), linewidth=1.3)
    plotting.plot_level(ax, theory["ou2_E2"], label="0.25, second-order averaging")
    plotting.plot_level(ax, theory["ou1_E2"], label="0.5, first-order averaging",
                        **plotting.ALT_THEORY_STYLE)
    ax.set_xlim(0.1, t_hi)
    ax.set_ylim(0.0, 0.65)
    ax.set_xlabel("$t$")
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    """Late-time <E^2>/(D t/tau^2) of each run against 1/4 (second order) and 1/2 (first order)."""
    th = theory_values or theory(datasets)
    rows = []
    for ds in datasets.values():
        D, tau, omega = attr_float(ds, "D"), attr_float(ds, "tau"), attr_float(ds, "omega")
        t, v, se = at_last(ds, "mean_E2", "Dt/tau2")
        t_star = slowest_time(D, tau, omega)
        label = f"D = {D:g}, τ = {tau:g} (t/t* = {fmt_num(t / t_star)})"
        fit, note = fit_if_asymptotic(ds, "mean_E2", "Dt/tau2", t_star)
        for name, pred in (("second-order averaging, eq:scalE2color", th["ou2_E2"]),
                           ("first-order averaging, quad1", th["ou1_E2"])):
            rows.append(Row(label, "⟨E²⟩/(Dt/τ²)", t, v, se, name, pred, fit, note))
    return rows


def fit_if_asymptotic(ds: xr.Dataset, var: str, kind: str, t_star: float) -> tuple[Any, str]:
    """The late-time fit when the last decade starts after t*; else None and the reason."""
    t_last = float(ds.time[-1])
    if t_last / 10.0 < t_star or not math.isfinite(t_star):
        return None, f"not extrapolated: the last decade starts at t/t* = {t_last / 10.0 / t_star:.2g} < 1"
    fit = extrapolate(ds, var, kind, power=FIT_POWER, alt_power=ALT_POWER)
    if fit is None:
        return None, "not extrapolated: too few times in the last decade"
    return fit, ""

