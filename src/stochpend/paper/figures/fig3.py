"""Fig. 3 (`fig:color`): OU noise, D = 1, tau = 1, omega = 1.0 and 0.0.

(a) <E> vs t with, inset, <E>/(D t/tau^2)^{1/2}; (b) S and F vs t. Dotted: second-order
averaging, 0.338 (D t/tau^2)^{1/2}, S = 2.028, F = 5 (Eqs. `eq:scalEcolor`-`eq:flatEcolor`);
dash-dotted: first-order averaging, 0.564 (D t/tau^2)^{1/2}, S = 1.596, F = 3 (Eq. `diff1` and the
half-Gaussian law `PDFav1`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr

from stochpend.paper.figures._common import FigureRun, Row, at_last, attr_float, fmt_num, run_key
from stochpend.paper.figures.fig2 import fit_if_asymptotic, slowest_time

NAME = "fig3"
TITLE = "Fig. 3 — OU noise, D = 1, τ = 1: mean energy, skewness and flatness"

#: Runs of the caption. Why t_max = 10^4: t_c = 1/(D tau^2) = 1 and tau^2 omega^4/D = 1, so the
#: last decade [10^3, 10^4] is 10^3 t_c in, where the (t/t_c)^{-1/2} corrections are a few
#: per cent -- comparable to the statistical error of S and F with 10^4 paths. Cost ~2.7e5 steps
#: a path. The omega = 1 run is also the (D, tau) = (1, 1) run of Fig. 2 and the omega = 0 run
#: the tau = 1 run of Fig. 4 (same seeds and times: simulated once).
CONFIG: dict[str, Any] = {
    "noise": "ou",
    "D": 1.0,
    "tau": 1.0,
    "runs": [{"omega": 1.0, "seed": 301}, {"omega": 0.0, "seed": 302}],
    "t_max": 1e4,
    "quick_t_max": 100.0,
}

COLORS = {1.0: "C0", 0.0: "C3"}


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    T = t_max if t_max is not None else (CONFIG["quick_t_max"] if quick else CONFIG["t_max"])
    D, tau = CONFIG["D"], CONFIG["tau"]
    return [
        FigureRun(key=run_key("ou", D, tau, r["omega"]), label=f"ω = {r['omega']:g}", noise="ou", D=D,
                tau=tau, omega=r["omega"], t_max=T, seed=r["seed"], paths=paths)
        for r in CONFIG["runs"]
    ]


def caption(figure_runs: list[FigureRun]) -> str:
    s = figure_runs[0]
    seeds = ", ".join(str(x.seed) for x in figure_runs)
    return (
        f"Stochastic pendulum with Ornstein–Uhlenbeck noise (Eqs. dyncolOmega–OU), D = {s.D:g}, "
        f"τ = {s.tau:g}, ω = 1.0 and 0.0, {s.paths} realizations each (seeds {seeds}), stationary "
        f"ξ(0), θ(0) uniform, Ω(0) = 0; times log-spaced from {s.t_min:g} to {fmt_num(s.t_max)}. "
        f"(a) ⟨E⟩ vs t and, inset, ⟨E⟩/(Dt/τ²)^{{1/2}}; (b) skewness S and flatness F of E vs t. "
        f"Dotted: second-order averaging, 0.338 (Dt/τ²)^{{1/2}}, S = 2.028, F = 5 "
        f"(eq:scalEcolor–eq:flatEcolor, skewness typo corrected); dash-dotted: first-order "
        f"averaging, 0.564 (Dt/τ²)^{{1/2}} (diff1), S = 1.596, F = 3 (half-Gaussian PDFav1). "
        f"Shaded: ±2 standard errors. Time range: t_c = 1/(Dτ²) = {s.t_c:g}, so the last decade "
        f"ends at t/t_c = {s.t_max / s.t_c:.3g}; the corrections decay like (t/t_c)^{{-1/2}}."
    )


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    from stochpend import theory as th

    m = [th.ou1_moment_E(k, 1.0, D=1.0, tau=1.0) for k in (2, 3, 4)]
    return {
        "ou2_E": th.OU2_MEAN_PREFACTOR,
        "ou1_E": th.OU1_MEAN_PREFACTOR,
        "ou2_E2": th.OU2_MEAN_E2_PREFACTOR,
        "ou1_E2": th.OU1_MEAN_E2_PREFACTOR,
        "ou2_S": th.ou2_skewness(),
        "ou2_F": th.ou2_flatness(),
        # First-order averaging (half-Gaussian law of E, PDFav1): raw-moment S and F are
        # time-independent; computed from its moments.
        "ou1_S": float(m[1] / m[0] ** 1.5),
        "ou1_F": float(m[2] / m[0] ** 2),
        "white_S": th.white_skewness(),
        "white_F": th.white_flatness(),
    }


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    from stochpend.paper import plotting

    fig, (ax_a, ax_b) = plotting.new_figure((11.0, 4.9), ncols=2)
    inset = ax_a.inset_axes((0.16, 0.57, 0.4, 0.37))
    inset.set_xscale("log")
    first = next(iter(datasets.values()))
    D, tau = attr_float(first, "D"), attr_float(first, "tau")
    t_hi = max(float(ds.time[-1]) for ds in datasets.values())
    for ds in datasets.values():
        omega = float(ds.attrs["omega"])
        color = COLORS.get(omega)
        label = f"ω = {omega:g}"
        plotting.plot_mean_E(ds, ax=ax_a, label=label, color=color)
        plotting.plot_ratio(ds, "ou_E", ax=inset, t_min=0.1, color=color, linewidth=1.0)
        plotting.plot_skewness_flatness(ds, ax=ax_b, label=label, t_min=0.1, color=color)
    tt = np.linspace(0.0, t_hi, 400)
    plotting.plot_theory(ax_a, tt, theory["ou2_E"] * np.sqrt(D * tt / tau**2),
                         label=r"$0.338\,(\mathcal{D}t/\tau^2)^{1/2}$ (2nd order)")
    plotting.plot_theory(ax_a, tt, theory["ou1_E"] * np.sqrt(D * tt / tau**2),
                         label=r"$0.564\,(\mathcal{D}t/\tau^2)^{1/2}$ (1st order)", **plotting.ALT_THEORY_STYLE)
    ax_a.set_xlim(0, t_hi)
    ax_a.set_ylim(0, 1.05 * theory["ou1_E"] * np.sqrt(D * t_hi / tau**2))
    ax_a.set_xlabel("$t$")
    ax_a.set_ylabel(r"$\langle E\rangle$")
    ax_a.legend(loc="lower right", fontsize=8)
    ax_a.set_title("(a)", loc="left")
    plotting.plot_level(inset, theory["ou2_E"])
    plotting.plot_level(inset, theory["ou1_E"], **plotting.ALT_THEORY_STYLE)
    inset.set_ylim(0.0, 0.7)
    inset.set_xlabel("$t$", fontsize=8, labelpad=1)
    inset.set_ylabel(r"$\langle E\rangle/(\mathcal{D}t/\tau^2)^{1/2}$", fontsize=8)
    inset.tick_params(labelsize=7)
    plotting.plot_level(ax_b, theory["ou2_S"], label="2.028, 5 (2nd order)")
    plotting.plot_level(ax_b, theory["ou2_F"])
    plotting.plot_level(ax_b, theory["ou1_S"], label="1.596, 3 (1st order)", **plotting.ALT_THEORY_STYLE)
    plotting.plot_level(ax_b, theory["ou1_F"], **plotting.ALT_THEORY_STYLE)
    ax_b.set_ylim(0, 13.0)
    ax_b.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=8, ncol=3)
    ax_b.set_title("(b)", loc="left")
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    """Late-time scaled <E>, <E^2>, S and F against second-order, first-order and white values."""
    th = theory_values or theory(datasets)
    items = [
        ("⟨E⟩/(Dt/τ²)^½", "mean_E", "sqrt(Dt/tau2)", [
            ("second-order averaging, eq:scalEcolor", th["ou2_E"]),
            ("first-order averaging, diff1", th["ou1_E"])]),
        ("⟨E²⟩/(Dt/τ²)", "mean_E2", "Dt/tau2", [
            ("second-order averaging, eq:scalE2color", th["ou2_E2"]),
            ("first-order averaging, quad1", th["ou1_E2"])]),
        ("S", "skewness", "one", [
            ("second-order averaging, eq:skewEcolor", th["ou2_S"]),
            ("first-order averaging, PDFav1", th["ou1_S"]),
            ("white noise, eq:skewEblanc", th["white_S"])]),
        ("F", "flatness", "one", [
            ("second-order averaging, eq:flatEcolor", th["ou2_F"]),
            ("first-order averaging, PDFav1", th["ou1_F"]),
            ("white noise, eq:flatEblanc", th["white_F"])]),
    ]
    rows = []
    for ds in datasets.values():
        D, tau, omega = attr_float(ds, "D"), attr_float(ds, "tau"), attr_float(ds, "omega")
        t_star = slowest_time(D, tau, omega)
        label = f"ω = {omega:g} (t/t_c = {fmt_num(float(ds.time[-1]) * D * tau**2)})"
        for quantity, var, kind, preds in items:
            t, v, se = at_last(ds, var, kind)
            fit, note = fit_if_asymptotic(ds, var, kind, t_star)
            for name, pred in preds:
                rows.append(Row(label, quantity, t, v, se, name, pred, fit, note))
    return rows
