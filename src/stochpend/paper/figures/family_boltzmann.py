"""Gallery (a): the damped noisy pendulum relaxes to the Boltzmann law.

    dx/dt = Omega,  dOmega/dt = -gamma Omega - omega^2 sin x + xi_a,  <xi_a xi_a'> = D_a delta

with no multiplicative noise (D = 0): the stationary law is exp(-E/T)/Z, T = D_a/(2 gamma), so
<Omega^2> -> T (equipartition) and <E> -> T/2 - omega^2 I_1/I_0(omega^2/T)
(:func:`stochpend.theory.family.boltzmann_mean_Omega2`, :func:`boltzmann_pendulum_mean_E`).
Three temperatures; theta(0) uniform, Omega(0) = 0 (not the Boltzmann law: the curves show the
relaxation, over a few 1/gamma).
"""

from __future__ import annotations

from typing import Any

import xarray as xr

from stochpend.paper.figures._common import FigureRun, Row, at_last, fmt_num
from stochpend.paper.figures._family import params

NAME = "family-boltzmann"
TITLE = "Family (a) — damped noisy pendulum: relaxation to the Boltzmann law"

#: gamma = 1: <Omega^2> relaxes at rate 2 gamma, the angle at rate ~gamma/2 (underdamped well);
#: t_max = 30 is 15 of the slowest relaxation times, so the last output is stationary to far
#: below the statistical error. ``paths`` is the size at the default reproduction (10^4 paths
#: per run asked, times 4: each run costs ~600 steps a path, seconds).
CONFIG: dict[str, Any] = {
    "gamma": 1.0,
    "omega": 1.0,
    "runs": [{"T": 0.5, "seed": 2301}, {"T": 1.0, "seed": 2302}, {"T": 2.0, "seed": 2303}],
    "paths": 40_000,
    "t_max": 30.0,
    "quick_t_max": 10.0,
}
DEFAULT_PATHS = 10_000
COLORS = ("C0", "C1", "C3")


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    T_end = t_max if t_max is not None else (CONFIG["quick_t_max"] if quick else CONFIG["t_max"])
    n = max(2, round(CONFIG["paths"] * paths / DEFAULT_PATHS))
    g, w = CONFIG["gamma"], CONFIG["omega"]
    return [FigureRun(key=f"family_boltzmann_T{r['T']:g}_gamma{g:g}", label=f"T = {r['T']:g}", noise="white",
                    D=0.0, tau=None, omega=w, t_max=float(T_end), seed=r["seed"], paths=n,
                    params=params(gamma=g, additive_D=2.0 * g * r["T"]))
            for r in CONFIG["runs"]]


def _T(ds: xr.Dataset) -> tuple[float, float, float]:
    D_a, gamma = float(ds.attrs["additive_D"]), float(ds.attrs["gamma"])
    return D_a, gamma, D_a / (2.0 * gamma)


def caption(figure_runs: list[FigureRun]) -> str:
    s = figure_runs[0]
    temps = ", ".join(f"{x.param('additive_D') / (2 * x.param('gamma')):g}" for x in figure_runs)
    seeds = ", ".join(str(x.seed) for x in figure_runs)
    return (
        f"Damped pendulum with additive white noise only (D = 0): dΩ/dt = −γΩ − ω² sin x + ξ_a, "
        f"⟨ξ_a ξ_a′⟩ = D_a δ, γ = {s.param('gamma'):g}, ω = {s.omega:g}, D_a = 2γT for T = {temps}; "
        f"{s.paths} realizations each (seeds {seeds}); θ(0) uniform on [−π, π), Ω(0) = 0; output times "
        f"log-spaced from {s.t_min:g} to {fmt_num(s.t_max)}. (a) ⟨Ω²⟩ vs t, dotted: T (equipartition); "
        f"(b) ⟨E⟩ vs t, dotted: the Boltzmann mean T/2 − ω² I₁(ω²/T)/I₀(ω²/T) "
        f"(stochpend.theory.family.boltzmann_mean_Omega2, boltzmann_pendulum_mean_E; docs/theory.md, "
        f"'The damped, driven family'). Shaded: ±2 standard errors (jackknife over batches). The table "
        f"compares the last output time, {fmt_num(s.t_max)} = {s.t_max * s.param('gamma'):g}/γ, with the "
        f"stationary values (the scheme's own stationary ⟨Ω²⟩ differs from T by a relative h²ω²/4 ≲ 6·10⁻⁴, "
        f"docs/numerics.md)."
    )


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    from stochpend.theory import family as fam

    out: dict[str, Any] = {}
    for key, ds in datasets.items():
        D_a, gamma, T = _T(ds)
        omega = float(ds.attrs["omega"])
        out[key] = {"T": T,
                    "Omega2": fam.boltzmann_mean_Omega2(D_a=D_a, gamma=gamma),
                    "E": fam.boltzmann_pendulum_mean_E(D_a=D_a, gamma=gamma, omega=omega)}
    return out


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    from stochpend.paper import plotting

    fig, (ax_a, ax_b) = plotting.new_figure((11.0, 4.6), ncols=2)
    for (key, ds), color in zip(datasets.items(), COLORS, strict=False):
        label = f"T = {theory[key]['T']:g}"
        for ax, var, ref in ((ax_a, "mean_Omega2", "Omega2"), (ax_b, "mean_E", "E")):
            ax.set_xscale("log")
            plotting.plot_statistic(ds, var, ax=ax, label=label, color=color, t_min=0.01)
            plotting.plot_level(ax, theory[key][ref], color=color)
    ax_a.set_ylabel(r"$\langle\Omega^2\rangle$")
    ax_b.set_ylabel(r"$\langle E\rangle$")
    ax_a.set_title("(a) equipartition ⟨Ω²⟩ → T", loc="left")
    ax_b.set_title("(b) ⟨E⟩ → T/2 − ω² I₁/I₀(ω²/T)", loc="left")
    ax_a.legend(loc="upper left", fontsize=9)
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    th = theory_values or theory(datasets)
    rows: list[Row] = []
    for key, ds in datasets.items():
        label = f"T = {th[key]['T']:g}, γ = {float(ds.attrs['gamma']):g}"
        for quantity, var, name, ref in (
            ("⟨Ω²⟩", "mean_Omega2", "Boltzmann: T (boltzmann_mean_Omega2)", "Omega2"),
            ("⟨E⟩", "mean_E", "Boltzmann: T/2 − ω² I₁/I₀(ω²/T) (boltzmann_pendulum_mean_E)", "E"),
        ):
            t, v, se = at_last(ds, var, "one")
            rows.append(Row(label, quantity, t, v, se, name, float(th[key][ref]), None, "stationary: value at t"))
    return rows

