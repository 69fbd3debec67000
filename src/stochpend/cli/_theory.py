"""The ``theory``, ``bfpe`` and ``reduced`` commands (registered in :mod:`stochpend.cli`)::

    from stochpend.cli._theory import bfpe_command, reduced_command, theory_command
    app.command("theory")(theory_command)
    app.command("bfpe")(bfpe_command)
    app.command("reduced")(reduced_command)

Thin layers over :func:`stochpend.theory.predictions`, :func:`stochpend.theory.solve_bfpe` and
:func:`stochpend.runs.reduced.simulate_reduced`: they validate nothing themselves (the API raises
one-line ``ValueError``s, turned into one red line and exit code 2 by ``handles_errors``).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from stochpend.cli._common import (
    MAX_POWER_N,
    _fmt,
    console,
    handles_errors,
    note,
    parse_times,
    results,
    rows_hint,
    summary_table,
)
from stochpend.cli._types import file_name, integer
from stochpend.text._terminal import markup
from stochpend.text.equations import eq

__all__ = ["bfpe_command", "bfpe_table", "reduced_command", "reduced_table", "theory_command", "theory_table"]


def _num(v: Any) -> str:  # a float, or a 0-d array from the laws
    if math.isinf(v):
        return "inf"
    if math.isnan(v):
        return "nan"
    return f"{v:.6g}"


def theory_table(rows: list[Any], *, title: str) -> Table:
    """A rich table of :class:`stochpend.theory.Prediction` rows, one section per regime."""
    from stochpend.text.equations import with_numbers

    # Text columns fold rather than end in '…' at 80 columns; the equation is the paper's number.
    table = Table(title=title, show_lines=False)
    for col, kw in (("regime", {"ratio": 3}), ("quantity", {"no_wrap": True}),
                    ("value", {"justify": "right", "no_wrap": True}), ("equation", {"ratio": 2}),
                    ("valid for", {"ratio": 3}), ("note", {"ratio": 4})):
        table.add_column(col, overflow="fold", **kw)
    previous = None
    for r in rows:
        if previous is not None and r.regime != previous:
            table.add_section()
        # Every text column in Eq. numbers: a regime's name cites the law's label too ("(eq:pdfEcolor)").
        table.add_row(with_numbers(r.regime) if r.regime != previous else "", r.quantity, _num(r.value),
                      with_numbers(r.equation), with_numbers(r.validity), with_numbers(r.note))
        previous = r.regime
    return table


@handles_errors
def theory_command(
    noise: Annotated[str, typer.Option(help=f"Noise: 'ou' (Ornstein-Uhlenbeck, {eq('eqOU')}) or 'white' (Gaussian white noise, {eq('defbruitblanc')}).")] = "ou",
    D: Annotated[float, typer.Option("--D", help="Noise amplitude D >= 0.")] = 1.0,
    tau: Annotated[float, typer.Option("--tau", help="OU correlation time tau > 0 (ignored for white noise).")] = 1.0,
    omega: Annotated[float, typer.Option("--omega", help="Pendulum frequency omega >= 0 (the asymptotic laws do not depend on it).")] = 1.0,
    time: Annotated[float, typer.Option("--time", help="Time at which the predictions are evaluated, >= 0.")] = 1000.0,
    t: Annotated[float | None, typer.Option("--t", "--t-max", hidden=True, help="Former name of --time; --t-max, simulate's name of the last time, means it too.")] = None,
    bfpe: Annotated[bool, typer.Option("--bfpe", help=f"Also solve the averaged Best Fokker-Planck Equation (omega = 0, {eq('avbfpe')}) up to that time.")] = False,
    family: Annotated[bool, typer.Option("--family", help="Instead, the laws of the damped, driven family (docs/theory.md): Boltzmann, Kramers, washboard, random-frequency oscillator; --D is then the multiplicative noise on x, --time is not used.")] = False,
    gamma: Annotated[float, typer.Option("--gamma", help="With --family: damping gamma > 0.")] = 0.5,
    D_a: Annotated[float, typer.Option("--D-a", help="With --family: additive noise intensity D_a > 0, <xi_a xi_a'> = D_a delta (T = D_a/(2 gamma)).")] = 0.2,
    F: Annotated[float, typer.Option("--F", help="With --family: constant torque F (washboard rows).")] = 0.0,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Print the paper's predictions at a time: every regime, its equation and where it is valid
    (with --family: the damped, driven family's stationary laws and rates)."""
    from stochpend.theory import predictions

    if t is not None:  # --t, the former name, and --t-max (simulate's word) still work
        time = t
    if family:
        from stochpend.theory.family import family_predictions

        if bfpe:
            raise ValueError("bfpe=True is not accepted with --family: the B.F.P.E. is the paper's (omega = 0, "
                             "no damping); drop --bfpe or --family")
        ou = noise.lower() == "ou"
        rows = family_predictions(noise=noise, D_a=D_a, gamma=gamma, omega=omega, D=D, tau=tau if ou else None, F=F)
        params = (f"gamma={gamma:g}, D_a={D_a:g}, D={D:g}" + (f", tau={tau:g}" if ou else "")
                  + f", omega={omega:g}" + ("" if ou else f", F={F:g}"))
        results.print(theory_table(rows, title=f"Damped, driven family, {noise.lower()} noise: {params}"))
        return

    rows = predictions(noise=noise, D=D, tau=tau if noise.lower() != "white" else None, omega=omega, t=time,
                       bfpe=bfpe)
    params = f"D={D:g}" + (f", tau={tau:g}" if noise.lower() == "ou" else "") + f", omega={omega:g}"
    results.print(theory_table(rows, title=f"Predictions at t = {time:g}: {noise.lower()} noise, {params}"))


def bfpe_table(ds: Any, max_rows: int = 12, width: int | None = None) -> Table:
    """Short table of a :func:`stochpend.theory.solve_bfpe` result, fitted to ``width`` columns
    (a terminal's; None: no limit): columns that do not fit are left out, the least needed
    first, and the caption says which (numbers are never cut or folded)."""
    D = float(ds.attrs["D"])
    tau = float(ds.attrs["tau"])
    n = ds.sizes["time"]
    shown = min(max_rows, n)
    idx = sorted({round(k * (n - 1) / max(shown - 1, 1)) for k in range(shown)})
    columns: dict[str, list[str]] = {name: [] for name in (
        "t", "t/t_c", "<E>", "<E>/(Dt/tau^2)^1/2", "<E2>/(Dt/tau^2)", "phi", "S", "F", "identity res.")}
    for i in idx:
        r = ds.isel(time=i)
        t = float(r.time)
        x = D * t / tau**2
        cells = (f"{t:.4g}", f"{D * tau**2 * t:.4g}", _num(float(r.mean_E)), _num(float(r.mean_E) / math.sqrt(x)),
                 _num(float(r.mean_E2) / x), _num(float(r.phi)), _num(float(r.skewness)), _num(float(r.flatness)),
                 f"{float(r.identity_residual):.1e}")
        for name, cell in zip(columns, cells, strict=True):
            columns[name].append(cell)

    def needed(names: list[str]) -> int:
        return 1 + sum(3 + max(len(name), *(len(c) for c in columns[name])) for name in names)

    names = list(columns)
    dropped: list[str] = []
    for name in ("identity res.", "t/t_c", "<E2>/(Dt/tau^2)", "phi"):
        if width is None or needed(names) <= width:
            break
        names.remove(name)
        dropped.append(name)
    table = Table(title=f"Averaged B.F.P.E. ({eq('avbfpe')}, omega = 0): D={D:g}, tau={tau:g}, "
                        f"t_c={1 / (D * tau**2):.4g}")
    for name in names:
        table.add_column(name, justify="right", no_wrap=True)
    for row in zip(*(columns[name] for name in names), strict=True):
        table.add_row(*row)
    from stochpend.theory import laws

    table.caption = (
        f"t >> t_c limits (second-order averaging): <E>/(Dt/tau^2)^1/2 {laws.OU2_MEAN_PREFACTOR:.6f}, "
        f"<E2>/(Dt/tau^2) {laws.OU2_MEAN_E2_PREFACTOR:g}, phi {laws.PHI_INF:.6f}, S {laws.OU2_SKEWNESS:.6f}, "
        f"F {laws.OU2_FLATNESS:g}."
        + (f" Not shown at this width: {', '.join(dropped)} (--format csv has all)." if dropped else "")
    )
    return table


@handles_errors
def bfpe_command(
    D: Annotated[float, typer.Option("--D", help="OU noise amplitude D > 0.")] = 1.0,
    tau: Annotated[float, typer.Option("--tau", help="OU correlation time tau > 0.")] = 0.1,
    t_max: Annotated[float, typer.Option("--t-max", help="Last time, > 0.")] = 1e5,
    n_times: Annotated[int, typer.Option("--n-times", parser=integer, help="Number of log-spaced output times from t_max/1000 to t_max.")] = 40,
    n_cells: Annotated[int, typer.Option("--n-cells", parser=integer, help="Finite-volume cells on the half line Omega >= 0.")] = 1000,
    steps_per_decade: Annotated[int, typer.Option("--steps-per-decade", parser=integer, help="Time steps per decade of t.")] = 100,
    max_cell_steps: Annotated[float | None, typer.Option("--max-cell-steps", help="Refuse solves needing more than this many cell-steps, n_cells x time steps (1e11: about 1.4 h; inf: no limit).", show_default="1e11")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", parser=file_name, help="Write the solution as NetCDF (atomically).", show_default="none: no file")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing --out file.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No table.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Solve the averaged Best Fokker-Planck Equation (omega = 0, eq. {avbfpe}) from Omega = 0."""
    from stochpend.files import io
    from stochpend.theory import solve_bfpe

    if out is not None:
        io.check_output_path(out, overwrite=overwrite)
    # As simulate does: a long solve says what it will cost before it starts.
    ds = solve_bfpe(D=D, tau=tau, t_max=t_max, n_times=n_times, n_cells=n_cells,
                    steps_per_decade=steps_per_decade, max_cell_steps=max_cell_steps,
                    log=lambda line: console.print(markup(line), highlight=False, soft_wrap=True))
    ds.attrs["command_line"] = " ".join(["stochpend", *sys.argv[1:]])
    if out is not None:
        io.to_netcdf(ds, out, overwrite=overwrite)
    if not quiet:
        results.print(bfpe_table(ds, width=results.width))
        if out is not None:
            console.print(f"wrote {markup(out)}", highlight=False, soft_wrap=True)


bfpe_command.__doc__ = (bfpe_command.__doc__ or "").replace("eq. {avbfpe}", eq("avbfpe"))


def reduced_table(ds: Any) -> Table:
    """The final-time moments of a reduced run next to the closed forms."""
    from stochpend.theory import laws

    order = ds.attrs["order"]
    D, tau = float(ds.attrs["D"]), float(ds.attrs["tau"])
    r = ds.isel(time=-1)
    t = float(r.time)
    x = D * t / tau**2
    if order == "first":
        m = [laws.ou1_moment_E(k, 1.0, D=1.0, tau=1.0) for k in (1, 2, 3, 4)]
        ref = (m[0], m[1], m[2] / m[1] ** 1.5, m[3] / m[1] ** 2, "PDFav1 (from E0 = 0)")
    elif order in ("second", "asymptotic"):
        ref = (laws.OU2_MEAN_PREFACTOR, laws.OU2_MEAN_E2_PREFACTOR, laws.OU2_SKEWNESS, laws.OU2_FLATNESS,
               "eq:pdfEcolor (from E0 = 0" + ("" if order == "asymptotic" else "; t >> t_c") + ")")
    else:
        ref = (math.nan, math.nan, math.nan, math.nan, "E = E0")
    table = Table(title=f"Reduced dynamics, {order} order, at t = {t:.4g}")
    for col in ("quantity", "simulated", "closed form"):
        table.add_column(col, justify="right", no_wrap=True)
    sq = math.sqrt(x) if x > 0 else math.nan
    table.add_row("<E>/(Dt/tau^2)^1/2", _fmt(float(r.mean_E) / sq, float(r.mean_E_stderr) / sq), _num(ref[0]))
    table.add_row("<E2>/(Dt/tau^2)", _fmt(float(r.mean_E2) / x, float(r.mean_E2_stderr) / x), _num(ref[1]))
    table.add_row("S", _fmt(float(r.skewness), float(r.skewness_stderr)), _num(ref[2]))
    table.add_row("F", _fmt(float(r.flatness), float(r.flatness_stderr)), _num(ref[3]))
    from stochpend.text.equations import with_numbers

    table.caption = with_numbers(f"model: {ds.attrs['equations']}; closed form: {ref[4]}")  # Eq. numbers, not labels
    return table


@handles_errors
def reduced_command(
    order: Annotated[str, typer.Option(help=f"Order of the averaging: zeroth (the energy is conserved, {eq('average0')}), first ({eq('average1')}), second (with its Ornstein-Uhlenbeck variable, {eq('average2', 'ZOU')}) or asymptotic (t >> t_c, {eq('average2eta')}).")] = "asymptotic",
    D: Annotated[float, typer.Option("--D", help="OU noise amplitude D > 0.")] = 1.0,
    tau: Annotated[float, typer.Option("--tau", help="OU correlation time tau > 0.")] = 1.0,
    omega: Annotated[float, typer.Option("--omega", help="Pendulum frequency omega >= 0 (enters the second order only).")] = 1.0,
    paths: Annotated[int, typer.Option(parser=integer, help="Number of realizations (1e6 is accepted).")] = 10_000,
    t_max: Annotated[float, typer.Option("--t-max", help="Final time.")] = 1000.0,
    n_times: Annotated[int | None, typer.Option("--n-times", parser=integer, help="Number of log-spaced output times from t_max/1000 to t_max (not with --times).", show_default="40")] = None,
    times: Annotated[str | None, typer.Option(help="Explicit output times, comma-separated, e.g. 10,100,1000.", show_default="none: see --n-times")] = None,
    seed: Annotated[int, typer.Option(parser=integer, help="Seed in [0, 2^64) (the reduced dynamics have their own Philox stream).")] = 0,
    E0: Annotated[float, typer.Option("--E0", help="Initial energy E0 >= 0.")] = 0.0,
    h_max: Annotated[float | None, typer.Option("--h-max", help="Second-order time step, > 0.", show_default="0.05 tau")] = None,
    threads: Annotated[int | None, typer.Option(parser=integer, help="CPU threads (results do not depend on it).", show_default="every CPU")] = None,
    max_path_steps: Annotated[float | None, typer.Option("--max-path-steps", help="Refuse runs needing more than this many path-steps (paths x t_max / h_max for the second order, paths x output times otherwise; inf: no limit).", show_default="1e13")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", parser=file_name, help="Write the results as NetCDF (atomically).", show_default="none: no file")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing --out file.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No table.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Simulate the reduced (averaged) energy dynamics and compare with the closed forms."""
    from stochpend.files import io
    from stochpend.runs.reduced import ReducedConfig, simulate_reduced

    if out is not None:
        io.check_output_path(out, overwrite=overwrite)
    if times is not None and n_times is not None:
        raise ValueError(f"n_times={n_times!r} is not accepted with --times: give either --times "
                         "(explicit output times) or --n-times (log-spaced), not both")
    if n_times is None:
        n_times = 40
    kwargs: dict[str, Any] = {
        "D": D, "tau": tau, "omega": omega, "paths": paths, "t_max": t_max, "times": parse_times(times),
        "n_times": n_times, "seed": seed, "E0": E0, "h_max": h_max,
    }
    config = ReducedConfig.build(order, **kwargs)  # validate before the JIT compiles
    from stochpend.runs import resources

    # As simulate does (D02): a long run says what it will cost before it starts.
    estimate = resources.check_reduced(config, max_path_steps=max_path_steps, threads=threads)
    if estimate.seconds > resources.LONG_RUN_S:
        console.print(f"estimate: {markup(estimate.describe())}", highlight=False, soft_wrap=True)
    if order == "zeroth" and E0 == 0:
        note("the zeroth order keeps every energy at E0 (no randomness); from --E0 0 every statistic "
             "is 0 and S, F and the closed forms' ratios are undefined (nan): give --E0 > 0")
    ds = simulate_reduced(order, threads=threads, max_path_steps=max_path_steps, **kwargs)
    ds.attrs["command_line"] = " ".join(["stochpend", *sys.argv[1:]])
    if out is not None:
        io.to_netcdf(ds, out, overwrite=overwrite)
    if not quiet:
        results.print(summary_table(ds, width=results.width, more=rows_hint(out)))
        results.print(reduced_table(ds))
        if int(ds.nonfinite_paths[-1]) > 0:
            console.print(f"[yellow]{int(ds.nonfinite_paths[-1])} paths went non-finite and are excluded.[/]")
        if out is not None:
            console.print(f"wrote {markup(out)}", highlight=False, soft_wrap=True)


@handles_errors
def scaling_command(
    n: Annotated[int, typer.Option("--n", parser=integer, help=f"Exponent n of the power potential U = x^2n/2n, an integer in [2, {MAX_POWER_N}] (n = 1 is the harmonic row).")] = 2,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Print the predicted long-time growth of <E> for every oscillator, coupling and noise
    (stochpend.theory.scaling; derivations in docs/scaling.md)."""
    from stochpend.theory.scaling import NOISES, predicted_exponent

    if isinstance(n, bool) or not 2 <= n <= MAX_POWER_N:
        shown = repr(n) if len(repr(n)) <= 80 else repr(n)[:76] + " ..."
        raise ValueError(f"n={shown} is not accepted: an integer in [2, {MAX_POWER_N}] (n = 1 is the "
                         "harmonic potential, its own row)")
    models = [("pendulum", "force", "pendulum, U = -cos x"), ("harmonic", "force", "harmonic, U = x^2/2"),
              ("power", "position", f"U = x^{2 * n}/{2 * n}, noise on x"),
              ("power", "force", f"U = x^{2 * n}/{2 * n}, noise on the force")]
    table = Table(title="Predicted growth of <E> at long times (docs/scaling.md)", show_lines=True)
    table.add_column("oscillator")
    for noise in NOISES:
        table.add_column(noise)
    for potential, coupling, label in models:
        cells = []
        for noise in NOISES:
            p = predicted_exponent(potential, noise, coupling, n)
            if p.growth == "power":
                from fractions import Fraction

                f = Fraction(float(p.exponent or 0.0)).limit_denominator(64)
                cells.append(f"t^{f}")
            else:
                cells.append(p.growth)
        table.add_row(label, *cells)
    results.print(table)
