"""Gallery (c): the tilted washboard, mean velocity against the torque F, and its hysteresis.

    dx/dt = Omega,  dOmega/dt = -gamma Omega - omega^2 sin x + F + xi_a,  <xi_a xi_a'> = D_a delta

(D = 0). The mean velocity <Omega> is measured as [<x(t)> - <x(t1)>]/(t - t1) over the second
half of each run (unwrapped displacement, ``observables=("displacement",)``). At low noise the
pendulum is bistable between the retrapping torque F_r = (4/pi) gamma omega and the locking
torque omega^2 (:func:`stochpend.theory.family.retrapping_torque`, :func:`locking_torque`): an
ensemble started at rest in a well stays locked, one started at Omega = F/gamma keeps running
at the velocity of the noiseless running orbit, which tends to F/gamma
(:func:`running_velocity`) for F >> omega^2. At higher noise the two ensembles meet.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import xarray as xr

from stochpend.paper.figures._common import FigureRun, Row, fmt_num
from stochpend.paper.figures._family import increment_rate, params

NAME = "family-washboard"
TITLE = "Family (c) — tilted washboard: mean velocity against torque, hysteresis at low noise"

#: gamma = 0.1 omega: F_r = 0.127 well below omega^2 = 1, a wide bistable window. t_max = 150
#: is 15 damping times 1/gamma; the mean velocity is taken over [75, 150], where an ensemble
#: started at rest that runs has reached its velocity to ~v e^{-7.5} (at t_max = 100, over
#: [50, 100], it still lagged by 0.03 at F = 1.4, 10 s.e.). A running path
#: takes steps c/|Omega| = 0.1 gamma/F, so the cost grows with F (~140 steps a path a time unit
#: at F = 1.4). ``paths`` at the default reproduction (10^4 asked).
CONFIG: dict[str, Any] = {
    "gamma": 0.1,
    "omega": 1.0,
    "F": [0.05, 0.2, 0.35, 0.5, 0.65, 0.8, 1.1, 1.4],
    "quick_F": [0.05, 0.5, 1.4],  # --quick: below F_r, bistable, above omega^2
    # (T, which ensembles); the low temperature shows the hysteresis, the higher one the escape
    # of the locked ensemble towards the running one.
    "temperatures": [(0.05, ("locked", "running")), (0.5, ("locked", "running"))],
    "seed0": 2500,
    "paths": 2000,
    "t_max": 150.0,
    "quick_t_max": 30.0,
}
#: A locked ensemble is compared with 0 only where the tilted well's barrier is high,
#: Delta U(F)/T >= LOCKED_BARRIER (:func:`tilted_barrier`): above ~8 thermal escape within
#: t_max is rare; below, the low-noise pendulum escapes and runs (F > F_r), which is the
#: finite-temperature end of the hysteresis, not a locked state.
LOCKED_BARRIER = 10.0
DEFAULT_PATHS = 10_000
WINDOW_START = 0.5  # the mean velocity is taken over [0.5 t_max, t_max]


def runs(paths: int, t_max: float | None, quick: bool) -> list[FigureRun]:
    T_end = t_max if t_max is not None else (CONFIG["quick_t_max"] if quick else CONFIG["t_max"])
    n = max(2, round(CONFIG["paths"] * paths / DEFAULT_PATHS))
    g, w = CONFIG["gamma"], CONFIG["omega"]
    out = []
    for iT, (T, ensembles) in enumerate(CONFIG["temperatures"]):
        for F in CONFIG["quick_F" if quick else "F"]:
            for ens in ensembles:
                # A run's seed is its place in the full grid (the same run with --quick or not).
                seed = CONFIG["seed0"] + 1 + (iT * len(CONFIG["F"]) + CONFIG["F"].index(F)) * 2 \
                    + ("locked", "running").index(ens)
                if ens == "locked":  # at rest at the tilted well's bottom (its top for F >= omega^2)
                    theta0, Omega0 = math.asin(min(F / (w * w), 1.0)), 0.0
                else:
                    theta0, Omega0 = 0.0, F / g
                out.append(FigureRun(
                    key=f"family_washboard_T{T:g}_F{F:g}_{ens}_gamma{g:g}", label=f"T = {T:g}, F = {F:g}, {ens}",
                    noise="white", D=0.0, tau=None, omega=w, t_max=float(T_end), seed=seed, paths=n,
                    params=params(gamma=g, torque=F, additive_D=2.0 * g * T), theta0=theta0, Omega0=Omega0,
                    observables=("displacement",)))
    return out


def _info(ds: xr.Dataset) -> tuple[float, float, float, str]:
    g = float(ds.attrs["gamma"])
    T = float(ds.attrs["additive_D"]) / (2.0 * g)
    F = float(ds.attrs["torque"])
    ens = "running" if float(ds.attrs["Omega0"]) != 0.0 else "locked"
    return T, F, g, ens


def caption(figure_runs: list[FigureRun]) -> str:
    s = figure_runs[0]
    g = s.param("gamma")
    Fs = ", ".join(f"{F:g}" for F in sorted({x.param("torque") for x in figure_runs}))
    Ts = ", ".join(f"{T:g}" for T, _ in CONFIG["temperatures"])
    seeds = f"{min(x.seed for x in figure_runs)}–{max(x.seed for x in figure_runs)}"
    T_lo, T_hi = CONFIG["temperatures"][0][0], CONFIG["temperatures"][-1][0]
    return (
        f"Tilted washboard: damped pendulum with constant torque F and additive white noise (D = 0), "
        f"γ = {g:g}, ω = {s.omega:g}, F = {Fs}, T = D_a/(2γ) = {Ts}; {len(figure_runs)} runs of {s.paths} "
        f"realizations to t = {fmt_num(s.t_max)} (seeds {seeds}), two initial ensembles each: 'locked', "
        f"at rest at the tilted well's bottom x = arcsin(F/ω²) (its inflection for F ≥ ω²), and "
        f"'running', x = 0, Ω = F/γ. ⟨Ω⟩ is [⟨x(t)−x(0)⟩ at t_max − at t₁]/(t_max − t₁), t₁ the "
        f"output time nearest t_max/2 (observable 'displacement'), ±2 s.e. (jackknife over batches). "
        f"Lines: the noiseless running velocity F/γ (stochpend.theory.family.running_velocity, its "
        f"F ≫ ω² limit), the noiseless running orbit's period-averaged velocity (integrated here, "
        f"scipy solve_ivp, for F above the retrapping torque), the locking torque ω² (locking_torque) "
        f"and the retrapping torque (4/π)γω (retrapping_torque, small γ/ω). At T = {T_lo:g} the two "
        f"ensembles stay apart between the two torques (hysteresis) as long as the tilted well's "
        f"barrier ΔU(F) holds the locked one; at T = {T_hi:g} the locked ensemble escapes and the "
        f"running one is partly retrapped (at small F), so the two approach the stationary velocity "
        f"from both sides and meet within t_max where the tilted barrier is low (F ≥ 0.8 here). Table: at "
        f"T = {T_lo:g}, each locked ensemble with a high tilted barrier, ΔU(F)/T ≥ {LOCKED_BARRIER:g}, "
        f"against 0 (at F = 0.65, 0.8 the barrier is 8 and 3.4 T: the locked ensemble escapes and runs, "
        f"the hysteresis window's thermal end), and each ensemble running above the retrapping torque "
        f"against the noiseless orbit (just above it, at F = 0.2, the running orbit passes close to "
        f"the separatrix and the noise retraps part of the ensemble, so its ⟨Ω⟩ falls below the "
        f"orbit's); at T = {T_hi:g}, F > ω² against the noiseless orbit and F/γ."
    )


def tilted_barrier(F: float, omega: float) -> float:
    """Barrier of the tilted washboard U(x) = -omega^2 cos x - F x, from its minimum
    x_m = arcsin(F/omega^2) to the next maximum pi - x_m: 2 omega^2 [sqrt(1 - f^2) - f arccos f],
    f = F/omega^2 (0 for f >= 1; 2 omega^2 at F = 0, :func:`stochpend.theory.family.pendulum_barrier`)."""
    w2 = omega * omega
    f = abs(F) / w2
    if f >= 1.0:
        return 0.0
    return 2.0 * w2 * (math.sqrt(1.0 - f * f) - f * math.acos(f))


def running_orbit_velocity(F: float, gamma: float, omega: float) -> float:
    """Period-averaged velocity of the noiseless running orbit started at (0, F/gamma); 0 when
    it is retrapped (F below the retrapping torque). Integrated over 30 damping times, then the
    velocity from the times of the last whole-turn crossings."""
    from scipy.integrate import solve_ivp

    w2 = omega * omega
    t_end = 30.0 / gamma

    def rhs(t: float, y: np.ndarray) -> list[float]:
        return [y[1], -gamma * y[1] - w2 * math.sin(y[0]) + F]

    def turn(t: float, y: np.ndarray) -> float:  # zero at x = 2 pi n
        return math.sin(0.5 * y[0])

    sol = solve_ivp(rhs, (0.0, t_end), [0.0, F / gamma], method="DOP853", rtol=1e-9, atol=1e-9,
                    events=turn)
    crossings = sol.t_events[0]
    late = crossings[crossings >= t_end / 2.0]
    if late.size < 3 or sol.y[1, -1] <= 0.0:  # trapped (or oscillating in a well)
        return 0.0
    return float(2.0 * math.pi * (late.size - 1) / (late[-1] - late[0]))


def theory(datasets: dict[str, xr.Dataset]) -> dict[str, Any]:
    from stochpend.theory import family as fam

    ds0 = next(iter(datasets.values()))
    g, w = float(ds0.attrs["gamma"]), float(ds0.attrs["omega"])
    Fs = sorted({_info(ds)[1] for ds in datasets.values()})
    return {
        "gamma": g, "omega": w,
        "locking": fam.locking_torque(omega=w),
        "retrapping": fam.retrapping_torque(gamma=g, omega=w),
        "F/gamma": {F: fam.running_velocity(F=F, gamma=g) for F in Fs},
        "orbit": {F: running_orbit_velocity(F, g, w) for F in Fs},
    }


def mean_velocity(ds: xr.Dataset) -> tuple[float, float, float]:
    t_last = float(ds["time"].values[-1])
    return increment_rate(ds, "mean_displacement", WINDOW_START * t_last)


def draw(datasets: dict[str, xr.Dataset], theory: dict[str, Any]) -> Any:
    from stochpend.paper import plotting

    fig, ax = plotting.new_figure((7.5, 5.0))
    points: dict[tuple[float, str], list[tuple[float, float, float]]] = {}
    for ds in datasets.values():
        T, F, _, ens = _info(ds)
        v, e, _ = mean_velocity(ds)
        points.setdefault((T, ens), []).append((F, v, e))
    temps = sorted({T for T, _ in points})
    for i, T in enumerate(temps):
        for ens, marker, fill in (("locked", "o", "full"), ("running", "s", "none")):
            if (T, ens) not in points:
                continue
            Fa, va, ea = (np.asarray(a) for a in zip(*sorted(points[T, ens]), strict=True))
            ax.errorbar(Fa, va, yerr=2 * ea, fmt=marker + "-", fillstyle=fill, color=f"C{i}", capsize=2,
                        linewidth=0.8, label=f"T = {T:g}, {ens} start")
    F_all = np.asarray(sorted(theory["orbit"]))
    FF = np.linspace(0.0, F_all.max() * 1.05, 100)
    plotting.plot_theory(ax, FF, FF / theory["gamma"], label="F/γ (running_velocity)")
    run_F = [F for F in F_all if theory["orbit"][F] > 0]
    ax.plot(run_F, [theory["orbit"][F] for F in run_F], "k+", markersize=9, label="noiseless running orbit")
    ax.axvline(theory["locking"], color="0.4", linestyle="--", linewidth=0.9, label="locking torque ω²")
    ax.axvline(theory["retrapping"], color="0.4", linestyle="-.", linewidth=0.9, label="retrapping torque (4/π)γω")
    ax.set_xlabel("torque $F$")
    ax.set_ylabel(r"mean velocity $\langle\Omega\rangle$")
    ax.set_xlim(0.0, F_all.max() * 1.05)
    ax.set_ylim(bottom=-0.3)
    ax.legend(loc="upper left", fontsize=8)
    ax.set_title(f"γ = {theory['gamma']:g}, ω = {theory['omega']:g}", loc="left")
    return fig


def table(datasets: dict[str, xr.Dataset], theory_values: dict[str, Any] | None = None) -> list[Row]:
    th = theory_values or theory(datasets)
    temps = sorted({_info(ds)[0] for ds in datasets.values()})
    rows: list[Row] = []
    for ds in datasets.values():
        T, F, g, ens = _info(ds)
        v, e, t1 = mean_velocity(ds)
        t = float(ds["time"].values[-1])
        label = f"T = {T:g}, F = {F:g}, {ens} start"
        q = f"⟨Ω⟩ over [{t1:.3g}, {t:.3g}]"
        note = "mean of x increments over the window"
        orbit = th["orbit"][F]
        if T == temps[0]:
            if ens == "locked" and F < th["locking"]:
                if tilted_barrier(F, th["omega"]) / T >= LOCKED_BARRIER:
                    rows.append(Row(label, q, t, v, e, f"locked (F < ω², ΔU(F)/T ≥ {LOCKED_BARRIER:g}): 0", 0.0,
                                    None, note))
            elif orbit > 0 and (ens == "running" or F > th["locking"]):
                rows.append(Row(label, q, t, v, e, "noiseless running orbit (period average)", orbit, None, note))
            elif orbit == 0:
                rows.append(Row(label, q, t, v, e, "retrapped (F < retrapping torque): 0", 0.0, None, note))
        elif F > th["locking"]:
            rows.append(Row(label, q, t, v, e, "noiseless running orbit (period average)", orbit, None, note))
            rows.append(Row(label, q, t, v, e, "F/γ (running_velocity)", th["F/gamma"][F], None, note))
    return rows
