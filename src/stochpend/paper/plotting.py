"""Plots of simulation results (matplotlib, imported lazily; never simulates).

Every function takes a result ``Dataset`` from :func:`stochpend.simulate` (or a file opened with
:func:`stochpend.io.open_results`), draws on ``ax`` (a new Agg figure when ``ax`` is None) and
returns the ``Axes``. Simulated curves carry a shaded band of ``band`` standard errors
(default 2, the jackknife errors stored with the run); theory is drawn dotted.

The figures are built on :class:`matplotlib.figure.Figure` with the Agg canvas, never through
``pyplot``: no global backend or state is touched, and nothing needs a display.
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = [
    "new_figure",
    "plot_band",
    "plot_statistic",
    "plot_mean_E",
    "plot_ratio",
    "plot_skewness_flatness",
    "plot_theory",
    "plot_level",
    "plot_run",
    "predicted_mean_E",
]

#: Scaled observables: label and normalisation kind (see :func:`stochpend.paper.figures._common.norm_series`).
RATIOS = {
    "white": ("mean_E", "Dt", r"$\langle E\rangle/(\mathcal{D}t)$"),
    "ou_E": ("mean_E", "sqrt(Dt/tau2)", r"$\langle E\rangle/(\mathcal{D}t/\tau^2)^{1/2}$"),
    "ou_E2": ("mean_E2", "Dt/tau2", r"$\langle E^2\rangle/(\mathcal{D}t/\tau^2)$"),
}

THEORY_STYLE: dict[str, Any] = {"color": "0.15", "linestyle": ":", "linewidth": 1.3}
ALT_THEORY_STYLE: dict[str, Any] = {"color": "0.55", "linestyle": "-.", "linewidth": 1.0}


def new_figure(figsize: tuple[float, float] = (5.5, 4.2), *, ncols: int = 1, nrows: int = 1) -> tuple[Any, Any]:
    """A figure on the Agg canvas (no pyplot) and its axes (an array when ``ncols`` or ``nrows`` > 1)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols)
    return fig, axes


def _axes(ax: Any) -> Any:
    if ax is None:
        _, ax = new_figure()
    return ax


def plot_band(ax: Any, t: np.ndarray, value: np.ndarray, stderr: np.ndarray, *, band: float = 2.0,
              label: str | None = None, color: Any = None, **line_kw: Any) -> Any:
    """A curve with a shaded ``value ± band*stderr`` band; returns the line."""
    ok = np.isfinite(value)
    (line,) = ax.plot(t[ok], value[ok], label=label, color=color, **line_kw)
    if band > 0:
        se = np.where(np.isfinite(stderr), stderr, 0.0)
        lo = value - band * se
        hi = value + band * se
        if ax.get_yscale() == "log":
            floor = np.nanmin(value[ok & (value > 0)]) * 1e-3 if np.any(ok & (value > 0)) else 1e-300
            lo = np.maximum(lo, floor)
        ax.fill_between(t[ok], lo[ok], hi[ok], color=line.get_color(), alpha=0.22, linewidth=0)
    return line


def plot_statistic(ds: Any, var: str, *, ax: Any = None, kind: str = "one", band: float = 2.0,
                   label: str | None = None, t_min: float | None = None, **line_kw: Any) -> Any:
    """Any statistic of ``ds`` (e.g. ``"skewness"``) divided by a normalisation ``kind``.

    ``kind``: "one", "Dt", "Dt/tau2" or "sqrt(Dt/tau2)".
    """
    from stochpend.paper.figures._common import scaled

    ax = _axes(ax)
    t, v, se = scaled(ds, var, kind)
    if t_min is not None:
        keep = t >= t_min
        t, v, se = t[keep], v[keep], se[keep]
    plot_band(ax, t, v, se, band=band, label=label, **line_kw)
    ax.set_xlabel("$t$")
    return ax


def plot_mean_E(ds: Any, *, ax: Any = None, band: float = 2.0, label: str | None = None,
                loglog: bool = False, **line_kw: Any) -> Any:
    """``<E>`` vs ``t`` with its ±band standard-error band (log-log when ``loglog``)."""
    ax = _axes(ax)
    if loglog:
        ax.set_xscale("log")
        ax.set_yscale("log")
    plot_statistic(ds, "mean_E", ax=ax, band=band, label=label, **line_kw)
    ax.set_ylabel(r"$\langle E\rangle$")
    return ax


def plot_ratio(ds: Any, which: str, *, ax: Any = None, band: float = 2.0, label: str | None = None,
               t_min: float | None = None, **line_kw: Any) -> Any:
    """A scaled ratio vs ``t`` (log time axis).

    ``which``: "white" (<E>/(Dt)), "ou_E" (<E>/(Dt/tau^2)^{1/2}) or "ou_E2" (<E^2>/(Dt/tau^2)).
    """
    if which not in RATIOS:
        raise ValueError(f"which={which!r} is not accepted: one of {', '.join(RATIOS)}")
    var, kind, ylabel = RATIOS[which]
    ax = _axes(ax)
    ax.set_xscale("log")
    plot_statistic(ds, var, ax=ax, kind=kind, band=band, label=label, t_min=t_min, **line_kw)
    ax.set_ylabel(ylabel)
    return ax


def plot_skewness_flatness(ds: Any, *, ax: Any = None, band: float = 2.0, label: str | None = None,
                           t_min: float | None = None, color: Any = None) -> Any:
    """Skewness S (solid) and flatness F (dashed) of E vs ``t`` (raw-moment ratios, log time)."""
    ax = _axes(ax)
    ax.set_xscale("log")
    suffix = f", {label}" if label else ""
    plot_statistic(ds, "skewness", ax=ax, band=band, label=f"S{suffix}", t_min=t_min, color=color)
    plot_statistic(ds, "flatness", ax=ax, band=band, label=f"F{suffix}", t_min=t_min, color=color,
                   linestyle="--")
    ax.set_ylabel("skewness $S$, flatness $F$")
    return ax


def plot_theory(ax: Any, t: np.ndarray, y: np.ndarray, *, label: str | None = None, **style: Any) -> Any:
    """A theory curve, dotted by default."""
    kw = {**THEORY_STYLE, **style}
    ax.plot(t, y, label=label, **kw)
    return ax


def plot_level(ax: Any, value: float, *, label: str | None = None, **style: Any) -> Any:
    """A horizontal theory level (dotted by default)."""
    kw = {**THEORY_STYLE, **style}
    ax.axhline(value, label=label, **kw)
    return ax


def predicted_mean_E(ds: Any, t: np.ndarray) -> list[tuple[str, np.ndarray, dict[str, Any]]]:
    """The predicted laws of ``<E>(t)`` for the model of ``ds``: ``[(label, values, style)]``.

    The pendulum: D t/4 with white noise (Eq. `eq:scalEblanc`); with OU noise the white-like law
    D t/4 for t << t_c and the second-order averaging law 0.338 (D t/tau^2)^{1/2} for t >> t_c
    (Eq. `eq:scalEcolor`). Every other model: the predicted power law t**nu of
    :func:`stochpend.theory.scaling.predicted_exponent`, drawn through the last point (its
    prefactor is not predicted); nothing where the growth is not a power law.
    """
    from stochpend.theory import laws
    from stochpend.theory.scaling import predicted_exponent

    a = ds.attrs
    noise = str(a.get("noise", ""))
    potential = str(a.get("potential", ""))
    D = float(a.get("D", np.nan))
    t = np.asarray(t, dtype=float)
    if potential == "pendulum" and noise in ("white", "ou") and D > 0:
        out = [(r"$\mathcal{D}t/4$ (white noise, Eq. (9))", np.asarray(laws.white_mean_E(t, D=D)),
                THEORY_STYLE)]
        if noise == "ou":
            tau = float(a["tau"])
            out = [(r"$\mathcal{D}t/4$ ($t \ll t_c$, Eq. (9))", out[0][1], THEORY_STYLE),
                   (r"$0.338\,(\mathcal{D}t/\tau^2)^{1/2}$ ($t \gg t_c$, Eq. (54))",
                    np.asarray(laws.ou2_mean_E(t, D=D, tau=tau)), ALT_THEORY_STYLE)]
        return out
    try:
        pred = predicted_exponent(potential, noise, str(a.get("coupling", "force")),
                                  int(a.get("power_n", 2)))
    except (ValueError, TypeError):
        return []
    E = np.asarray(ds["mean_E"].values, dtype=float)
    ok = np.isfinite(E) & (E > 0) & (t > 0)
    if pred.exponent is None or not np.any(ok):
        return []
    i = np.flatnonzero(ok)[-1]
    nu = float(pred.exponent)
    return [(rf"$\propto t^{{{nu:.3g}}}$ (predicted; prefactor through the last point)",
             E[i] * (t / t[i]) ** nu, THEORY_STYLE)]


def plot_run(ds: Any, *, band: float = 2.0) -> Any:
    """One run at a glance: ``<E>`` vs t, log-log, with its ``band``-standard-error band and the
    predicted law(s) of :func:`predicted_mean_E`, titled with the model. Returns the Figure."""
    from stochpend.paper.figures._common import describe_attrs

    fig, ax = new_figure((6.0, 4.4))
    t = np.asarray(ds.time.values, dtype=float)
    keep = t > 0
    sub = ds.isel(time=np.flatnonzero(keep))
    plot_mean_E(sub, ax=ax, band=band, loglog=True, label=f"simulation (±{band:g} SE)")
    for label, y, style in predicted_mean_E(sub, t[keep]):
        plot_theory(ax, t[keep], y, label=label, **style)
    ax.set_title(describe_attrs(ds.attrs) + f", {int(ds.attrs.get('paths', 0))} paths", fontsize=9)
    ax.legend(fontsize=8)
    return fig


def plot_target(ds: Any) -> Any:
    """A total-error target's result (``simulate(target_error=...)``, stochpend.runs.multilevel): each
    target statistic against t with its total error (statistical + bias bound, at the stated
    confidence) as error bars; certified times filled, the others open. Returns the Figure."""
    from stochpend.paper.figures._common import describe_attrs

    names = [n for n in str(ds.attrs.get("target_statistics", "")).split(",") if n in ds]
    fig, axes = new_figure((6.0, 2.6 * max(len(names), 1)), nrows=max(len(names), 1))
    axes = np.atleast_1d(axes)
    t = np.asarray(ds.time.values, dtype=float)
    for ax, name in zip(axes, names, strict=False):
        y = np.asarray(ds[name].values, dtype=float)
        err = np.asarray(ds[f"{name}_total_error"].values, dtype=float)
        ok = np.asarray(ds[f"{name}_certified"].values, dtype=bool)
        for mask, face, label in ((ok, None, "certified"), (~ok, "none", "not certified")):
            if np.any(mask):
                ax.errorbar(t[mask], y[mask], yerr=err[mask], fmt="o", mfc=face, capsize=3, label=label)
        if np.all(t > 0):
            ax.set_xscale("log")
        if np.all(y - err > 0):
            ax.set_yscale("log")
        ax.set_ylabel(name)
        ax.legend(fontsize=8)
    axes[-1].set_xlabel("t")
    eps = float(ds.attrs.get("target_error", float("nan")))
    conf = float(ds.attrs.get("target_confidence", float("nan")))
    axes[0].set_title(describe_attrs(ds.attrs) + f"; target {eps:g} at {100 * conf:g} %", fontsize=9)
    return fig
