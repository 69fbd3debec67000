"""Fig. 1 (`fig:blanc`): the pendulum with Gaussian white noise, D = 1, omega = 1.0 and 0.0.

(a) <E> vs t with, inset, <E>/(D t); (b) skewness S and flatness F of E vs t. Dotted: the
white-noise laws <E> = D t/4, S = 5/sqrt(3), F = 35/3 (Eqs. `eq:scalEblanc`-`eq:flatEblanc`),
which do not depend on omega.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import xarray as xr

from stochpend.paper.figures._common import FigureRun, Row, at_last, extrapolate, fmt_num, run_key

NAME = "fig1"
TITLE = "Fig. 1 — white noise: mean energy, skewness and flatness"

#: The runs of the caption. ``t_max`` is the default final time, ``quick_t_max`` the one of
#: ``--quick``. Why t_max = 1000: <E> = D t/4 reaches 250 >> omega^2 = 1, so the omega = 1
#: pendulum rotates over the last two decades and the omega-independent laws apply there; the
#: corrections decay like 1/t. Cost ~1.2e5 steps a path (c = 0.1) (the step shrinks like 1/Omega).
CONFIG: dict[str, Any] = {
    "noise": "white",
    "D": 1.0,
    "runs": [{"omega": 1.0, "seed": 101}, {"omega": 0.0, "seed": 102}],
    "t_max": 1000.0,
    "quick_t_max": 100.0,
}

#: Late-time corrections of the white-noise laws decay like 1/t (e.g. <E> = D t/4 + const).
FIT_POWER = 1.0
ALT_POWER = 0.5
COLORS = {1.0: "C0", 0.0: "C3"}


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    """The simulations of the caption (``t_max`` overrides the default final time)."""
    T = t_max if t_max is not None else (CONFIG["quick_t_max"] if quick else CONFIG["t_max"])
    D = CONFIG["D"]
    out = []
    for r in CONFIG["runs"]:
        out.append(FigureRun(
            key=run_key("white", D, None, r["omega"]), label=f"ω = {r['omega']:g}", noise="white",
            D=D, tau=None, omega=r["omega"], t_max=T, seed=r["seed"], paths=paths,
        ))
    return out


def caption(figure_runs: list[FigureRun]) -> str:
    s = figure_runs[0]
    seeds = ", ".join(str(x.seed) for x in figure_runs)
    return (
        f"Stochastic pendulum with Gaussian white noise (Eqs. dynOmega, dyntheta, defbruitblanc), "
        f"D = {s.D:g}, ω = 1.0 and 0.0, {s.paths} realizations each (seeds {seeds}); θ(0) uniform on "
        f"[−π, π), Ω(0) = 0; output times log-spaced from {s.t_min:g} to {fmt_num(s.t_max)} "
        f"({s.per_decade} a decade). (a) ⟨E⟩ vs t and, inset, ⟨E⟩/(Dt); (b) skewness S and "
        f"flatness F of E (raw-moment ratios) vs t. Dotted: D t/4, 5/√3 ≈ 2.887 and 35/3 ≈ 11.67 "
        f"(Eqs. eq:scalEblanc–eq:flatEblanc). Shaded: ±2 standard errors (jackknife over batches). "
        f"Time range: at t = {fmt_num(s.t_max)} the mean energy D t/4 ≈ {s.D * s.t_max / 4:.3g} is far above "
        f"ω² = 1, so the ω = 1 pendulum rotates and the ω-independent laws apply over the last decades "
        f"(corrections decay like 1/t)."
    )


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    """The white-noise predictions (from :mod:`stochpend.theory`)."""
    from stochpend import theory as th

    return {
        "mean_prefactor": th.WHITE_MEAN_PREFACTOR,
        "mean_E2_prefactor": th.WHITE_MEAN_E2_PREFACTOR,
        "skewness": th.white_skewness(),
        "flatness": th.white_flatness(),
    }


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    """Panels (a) and (b) of Fig. 1 as a matplotlib Figure."""
    from stochpend.paper import plotting

    fig, (ax_a, ax_b) = plotting.new_figure((11.0, 4.9), ncols=2)
    inset = ax_a.inset_axes((0.16, 0.57, 0.4, 0.37))
    inset.set_xscale("log")
    t_hi = max(float(ds.time[-1]) for ds in datasets.values())
    D = float(next(iter(datasets.values())).attrs["D"])
    for ds in datasets.values():
        omega = float(ds.attrs["omega"])
        color = COLORS.get(omega)
        label = f"ω = {omega:g}"
        plotting.plot_mean_E(ds, ax=ax_a, label=label, color=color)
        plotting.plot_ratio(ds, "white", ax=inset, t_min=0.1, color=color, linewidth=1.0)
        plotting.plot_skewness_flatness(ds, ax=ax_b, label=label, t_min=0.1, color=color)
    tt = np.linspace(0.0, t_hi, 200)
    plotting.plot_theory(ax_a, tt, theory["mean_prefactor"] * D * tt, label=r"$\mathcal{D}t/4$")
    plotting.plot_level(inset, theory["mean_prefactor"])
    ax_a.set_xlim(0, t_hi)
    ax_a.set_ylim(bottom=0)
    ax_a.set_xlabel("$t$")
    ax_a.legend(loc="lower right", fontsize=9)
    ax_a.set_title("(a)", loc="left")
    inset.set_ylim(0.1, 0.4)
    inset.set_xlabel("$t$", fontsize=8, labelpad=1)
    inset.set_ylabel(r"$\langle E\rangle/(\mathcal{D}t)$", fontsize=8)
    inset.tick_params(labelsize=7)
    plotting.plot_level(ax_b, theory["skewness"], label=r"$5/\sqrt{3}$")
    plotting.plot_level(ax_b, theory["flatness"], label=r"$35/3$")
    ax_b.set_ylim(0, 1.35 * theory["flatness"])
    ax_b.legend(loc="upper center", bbox_to_anchor=(0.5, -0.14), fontsize=8, ncol=3)
    ax_b.set_title("(b)", loc="left")
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    """Late-time <E>/(Dt), <E^2>/(Dt)^2, S and F of each run against the white-noise laws."""
    th = theory_values or theory(datasets)
    rows: list[Row] = []
    items = [
        ("⟨E⟩/(Dt)", "mean_E", "Dt", "white noise, eq:scalEblanc (1/4)", th["mean_prefactor"]),
        ("⟨E²⟩/(Dt)²", "mean_E2", "(Dt)^2", "white noise, eq:pdfEblanc (3/16)", th["mean_E2_prefactor"]),
        ("S", "skewness", "one", "white noise, eq:skewEblanc (5/√3)", th["skewness"]),
        ("F", "flatness", "one", "white noise, eq:flatEblanc (35/3)", th["flatness"]),
    ]
    for ds in datasets.values():
        label = f"ω = {float(ds.attrs['omega']):g}"
        for quantity, var, kind, name, pred in items:
            t, v, se = at_last(ds, var, kind)
            fit = extrapolate(ds, var, kind, power=FIT_POWER, alt_power=ALT_POWER)
            rows.append(Row(label, quantity, t, v, se, name, pred, fit))
    return rows
