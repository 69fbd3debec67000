"""Command line: a thin layer over the Python API (Typer + Rich).

Known errors print one red line on stderr and exit with code 2 (bad input) or 1 (a file
that cannot be written: full disk, I/O error); ``--debug`` shows the traceback. Usage errors
(a value the option's type refuses, an unknown option, a missing argument) are one such line
too. Integer options accept whole numbers in scientific notation
(``--paths 1e6``). Human output goes to stderr, so that stdout stays clean for pipes.
"""

from __future__ import annotations

import math
import shlex
import sys
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.markup import escape
from rich.table import Table
from typer.core import TyperCommand, TyperGroup

from stochpend.cli import _common as _cli_common
from stochpend.cli._common import (  # the shared layer; several are also used as cli.NAME
    DEFAULT_H_MAX,
    DEFAULT_HIST_BINS,
    DEFAULT_STEP_C,
    MAX_OMEGA,
    MAX_POWER_N,
    RichProgress,
    _check_numba_threads,
    _stop_listening,
    bias_notes,
    bias_warnings,
    console,
    fail,
    handles_errors,
    joint_lines,
    load_plugins,
    note,
    observables_table,
    parse_pair,
    parse_params,
    parse_theta0,
    parse_times,
    passage_tables,
    results,
    shown_rows,
    summary_table,
)
from stochpend.cli._types import fast_coercion, file_name, integer, usage_message
from stochpend.files._plain import Plain
from stochpend.text._terminal import markup
from stochpend.text.equations import eq

#: The help's words for a value's type, instead of Typer's Python types (``<float>``, ``<Path>``).
METAVARS = {"<float>": "NUMBER", "<int>": "INTEGER", "<str>": "TEXT", "<Path>": "FILE",
            "<list[str]>": "TEXT", "<list[Path]>": "FILE"}


def _usage_name(param: Any) -> str:
    """An argument in the usage line as a user writes it: PATH, [FIGURE]... (Typer: {path})."""
    name = (param.metavar or param.name or "").rstrip(".").upper()
    if param.nargs != 1:
        name += "..."
    return name if param.required else f"[{name}]"


def _plain_flags(params: list[Any]) -> list[Any]:
    """Help in the command line's words: boolean flags show no ``<bool>`` metavar (they take no
    value); other options show a word for their value (:data:`METAVARS`), never a Python type;
    an argument shows no type and is written PATH in the usage line, not ``{path}``; a default
    given as text (``show_default="every CPU"``, for an option whose None stands for it) is
    shown as ``[default: every CPU]``, without the parentheses Typer adds."""
    for param in params:
        if getattr(param, "is_flag", False) and param.metavar is None:
            param.metavar = ""
        elif getattr(param, "param_type_name", "") == "option" and param.metavar is None:
            shown = param.display_type(None)
            param.metavar = METAVARS.get(shown, shown.strip("<>").upper() if isinstance(shown, str) else None)
        if getattr(param, "param_type_name", "") == "argument":
            # An argument is named in words (PATH, FIGURE...): no Python type beside it (<Path>).
            param.display_type_rich = lambda *args, **kwargs: None
            param._usage_display_name = lambda _param=param: _usage_name(_param)
        text = getattr(param, "show_default", None)
        if isinstance(text, str):
            param._get_default_string = lambda *args, _text=text, **kwargs: _text
        fast_coercion(param)  # no Pydantic where the option's own parser decides
    return params


def _escape_help(command: Any) -> None:
    """Help text is literal: Rich markup in it is escaped, once, when the command is built
    ("a TOML file: [base], then [grid]" lost its bracketed words to Rich markup)."""
    for param in getattr(command, "params", ()):
        if getattr(param, "help", None):
            param.help = escape(param.help)
    for attr in ("help", "short_help"):
        if getattr(command, attr, None):
            setattr(command, attr, escape(getattr(command, attr)))


class _Deferred(type):
    """The type of a stand-in for a class not imported yet: calling it or reading an attribute
    of it imports the real class (``_real``: its module and name)."""

    _real: tuple[str, str]

    def _load(cls) -> Any:
        import importlib

        module, name = cls._real
        return getattr(importlib.import_module(module), name)

    def __call__(cls, *args: Any, **kwargs: Any) -> Any:
        return cls._load()(*args, **kwargs)

    def __getattr__(cls, attr: str) -> Any:
        return getattr(cls._load(), attr)


#: What Typer's help renderer (typer.rich_utils) imports for what this app does not use: Markdown
#: help text (rich_markup_mode="markdown") and Rich tracebacks (pretty_exceptions_enable=False);
#: with markdown-it and Pygments, 0.05 s of --help's 0.2 s on a 2-core machine (issue 36, item 1).
_NOT_FOR_HELP = {"rich.markdown": "Markdown", "rich.traceback": "Traceback"}


def _import_help_renderer() -> None:
    """Import typer.rich_utils without :data:`_NOT_FOR_HELP`: stand-ins (:class:`_Deferred`) sit
    in ``sys.modules`` during that import only, so any later import of those modules gets the
    real ones, as does the renderer if it ever uses one."""
    if "typer.rich_utils" in sys.modules or any(m in sys.modules for m in _NOT_FOR_HELP):
        return
    import types

    for module, name in _NOT_FOR_HELP.items():
        stand_in = types.ModuleType(module)
        setattr(stand_in, name, _Deferred(name, (), {"_real": (module, name)}))
        sys.modules[module] = stand_in
    try:
        import typer.rich_utils  # noqa: F401
    finally:
        for module in _NOT_FOR_HELP:
            del sys.modules[module]


class _LightHelp:
    """The help of a command or the group, rendered by Typer without :data:`_NOT_FOR_HELP`."""

    def format_help(self, ctx: Any, formatter: Any) -> None:
        _import_help_renderer()
        super().format_help(ctx, formatter)  # type: ignore[misc]


class HelpCommand(_LightHelp, TyperCommand):
    """Every subcommand's class: literal help text and flags without a metavar."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        _escape_help(self)

    def get_params(self, ctx: Any) -> list[Any]:
        return _plain_flags(super().get_params(ctx))


class OneLineErrorsGroup(_LightHelp, TyperGroup):
    """The app's command group: usage errors become the project's one red line and exit
    code 2, instead of Typer's usage block and boxed message (``--help`` is unchanged).

    Both hooks are needed: the group's own arguments are parsed in ``make_context``, a
    subcommand's options in ``invoke``.
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        _escape_help(self)

    def get_params(self, ctx: Any) -> list[Any]:
        return _plain_flags(super().get_params(ctx))

    def make_context(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().make_context(*args, **kwargs)
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":  # 'stochpend' alone: the help
                raise
            fail(usage_message(exc))

    def invoke(self, ctx: Any) -> Any:
        from stochpend.files._files import signals_interrupt, take_pending

        _check_numba_threads()
        try:
            # SIGTERM, SIGHUP: unwind, remove temporaries, exit 128+n; each signal recorded until
            # taken back (Python drops one whose exception lands in a weakref callback)
            with signals_interrupt():
                value = super().invoke(ctx)
                missed = take_pending()
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":
                raise
            fail(usage_message(exc))
        except KeyboardInterrupt as exc:
            # A second Ctrl-C while the first was being handled (I3): still exit 128 + n, not
            # Click's "Aborted!" or death by the signal.
            _stop_listening()
            raise typer.Exit(128 + getattr(exc, "signum", 2)) from None
        if missed is not None:
            # A signal whose exception was dropped after the command's last boundary: the work
            # is done and what it printed and wrote is complete; the exit status still says so.
            _stop_listening()
            console.print(f"[yellow]interrupted[/] by signal {missed} as the command finished: "
                          "what it printed and wrote is complete", highlight=False, soft_wrap=True)
            raise typer.Exit(128 + missed)
        return value


app = typer.Typer(
    name="stochpend",
    help="Ensembles of the stochastic pendulum with parametric white or Ornstein-Uhlenbeck noise "
    "(Mallick & Marcq 2004): simulate, compare with theory, reproduce the paper.",
    no_args_is_help=True,
    add_completion=True,
    pretty_exceptions_enable=False,
    cls=OneLineErrorsGroup,
)


def _version(value: bool) -> None:
    if value:
        from stochpend._version import __version__

        typer.echo(f"stochpend {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
    cpu_target: Annotated[str | None, typer.Option(
        "--cpu-target", metavar="host|baseline",
        help="Instruction set the CPU kernels are compiled for: host (this machine's, the default) or "
             "baseline (x86-64-v3: AVX2 and FMA, the same on every machine). Same as "
             "STOCHPEND_CPU_TARGET; the result's cpu_target attribute names it.")] = None,
) -> None:
    """Ensembles of the stochastic pendulum with parametric white or Ornstein-Uhlenbeck noise
    (Mallick & Marcq 2004): simulate, compare with theory, reproduce the paper."""
    if cpu_target is not None:
        from stochpend.numerics import _cputarget

        try:
            _cputarget.select(cpu_target.strip().lower())
        except ValueError as exc:
            fail(str(exc).replace("cpu_target=", "--cpu-target ", 1))


#: What a `simulate --config` file may set: physics and numerics (and where they run), by the
#: options' names. Never what to overwrite or where to write (`out`, `overwrite`, `checkpoint`),
#: nor code to load: those come from the command line that runs.
CONFIG_KEYS = ("noise", "D", "tau", "omega_noise", "omega", "potential", "n", "coupling", "paths", "t_max",
               "n_times", "times", "seed", "theta0", "Omega0", "h_max", "step_c", "hist_bins", "bias_paths",
               "accuracy", "rtol", "max_path_steps", "backend", "precision", "threads", "joint_bins",
               "joint_x_range", "joint_Omega_max", "additive_noise", "target_error", "target_confidence",
               "target_statistics", "target_times", "max_seconds")
_CONFIG_REFUSED = {"out": "the output file is named on the command line (--out)",
                   "overwrite": "only the command line that runs may allow overwriting (--overwrite)",
                   "checkpoint": "the checkpoint file is named on the command line (--checkpoint)",
                   "checkpoint_every": "checkpointing is set on the command line (--checkpoint-every)",
                   "config": "a configuration file does not name another",
                   "config_file": "a configuration file does not name another",
                   "quiet": "output is set on the command line", "debug": "output is set on the command line"}


def _config_value(key: str, value: Any, source: str) -> str:
    """A configuration file's value as the text the option would be given on the command line."""
    if key in ("times", "joint_bins", "joint_x_range", "joint-bins", "joint-x-range") and isinstance(value, list):
        value = ",".join(repr(v) if isinstance(v, float) else str(v) for v in value)
    if isinstance(value, bool) or not isinstance(value, str | int | float):
        raise ValueError(f"{source}: {key}={value!r} is not accepted: a number or a string"
                         + (" (times, joint_bins, joint_x_range: a list of numbers)" if isinstance(value, list) else ""))
    return repr(value) if isinstance(value, float) else str(value)


def _load_config(ctx: typer.Context, value: Path | None) -> Path | None:
    """`--config FILE` (eager): the file's keys become the command's defaults (Click's
    ``default_map``), so that an option given on the command line overrides them; refusals name
    the file and its key."""
    if value is None or ctx.resilient_parsing:
        return value
    from stochpend.files._toml import read_toml

    try:
        text, data = read_toml(value, "--config")
        source = value.name
        defaults: dict[str, str] = {}
        for raw_key, item in data.items():
            key = raw_key.replace("-", "_")
            if key in _CONFIG_REFUSED:
                raise ValueError(f"{source}: {raw_key} is not accepted in a configuration file: {_CONFIG_REFUSED[key]}")
            if key not in CONFIG_KEYS:
                raise ValueError(f"{source}: {raw_key} is not accepted: unknown key; accepted: {', '.join(CONFIG_KEYS)}")
            if key in defaults:  # t_max and t-max both: one would silently win
                other = next(k for k in data if k != raw_key and k.replace("-", "_") == key)
                raise ValueError(f"{source}: {raw_key} is not accepted: the file also sets {other}, the same "
                                 "option; keep one of them")
            defaults[key] = _config_value(raw_key, item, source)
    except ValueError as exc:
        fail(str(exc))
    ctx.default_map = {**(ctx.default_map or {}), **defaults}
    ctx.meta["stochpend.config_file"] = (value.name, set(defaults))
    ctx.meta["stochpend.config_text"] = text
    return value


def _config_keys_in_use(ctx: typer.Context) -> None:
    """Errors about a value the configuration file set name the file's key, not the option."""
    source, keys = ctx.meta.get("stochpend.config_file", ("", set()))
    used = {}
    for key in keys:
        source_of_key = ctx.get_parameter_source(key)
        if source_of_key is not None and source_of_key.name == "DEFAULT_MAP":
            used[key] = source
    ctx.meta["stochpend.config_keys"] = used


def _joint_options(bins: str | None, x_range: str | None, Omega_max: float | None) -> dict[str, Any]:
    """``--joint-bins``, ``--joint-x-range`` and ``--joint-Omega-max`` as the API's keywords
    (those given); a piece that is not a number stays text, so the API's refusal names it."""
    out: dict[str, Any] = {}

    def number(text: str, parse: Any) -> Any:
        try:
            return parse(text)
        except (ValueError, OverflowError):
            return text

    pair = parse_pair("joint_bins", bins, "two integers NX,NO, e.g. 40,30")
    if pair is not None:
        out["joint_bins"] = [number(p, integer) for p in pair]
    pair = parse_pair("joint_x_range", x_range, "two numbers LO,HI with LO < HI, e.g. -5,5")
    if pair is not None:
        out["joint_x_range"] = [number(p, float) for p in pair]
    if Omega_max is not None:
        out["joint_Omega_max"] = Omega_max
    return out


@app.command()
@handles_errors
def simulate(
    noise: Annotated[str, typer.Option(help=f"Noise: 'ou' (Ornstein-Uhlenbeck, {eq('eqOU')}), 'white' (Gaussian white noise, {eq('defbruitblanc')}), 'dichotomous' (telegraph +-sqrt(D/2tau), same correlation as OU) or 'harmonic' (spectrum ~ nu^-4); docs/models.md.")] = "ou",
    D: Annotated[float, typer.Option("--D", help="Noise amplitude D >= 0 (every noise has spectral density D at zero frequency).")] = 1.0,
    tau: Annotated[float, typer.Option("--tau", help="Correlation time tau > 0 of the colored noises (ignored for white noise).")] = 1.0,
    omega_noise: Annotated[float | None, typer.Option("--omega-noise", help="Harmonic noise only: its oscillator frequency W > 0.", show_default="2/tau, critical damping")] = None,
    omega: Annotated[float, typer.Option("--omega", help=f"Oscillator frequency omega in [0, {MAX_OMEGA:g}] ({eq('dynOmega')}).")] = 1.0,
    potential: Annotated[str, typer.Option(help="Oscillator: 'pendulum' (U = -cos x), 'harmonic' (x^2/2) or 'power' (x^2n/2n, see --n).")] = "pendulum",
    n: Annotated[int, typer.Option("--n", parser=integer, help=f"Exponent n of the power potential U = x^2n/2n, an integer in [1, {MAX_POWER_N}].")] = 2,
    coupling: Annotated[str, typer.Option(help="The noise multiplies the force U'(x) ('force', the pendulum's) or x ('position', the random-frequency oscillator).")] = "force",
    paths: Annotated[int, typer.Option(parser=integer, help="Number of realizations (1e6 is accepted).")] = 10_000,
    t_max: Annotated[float, typer.Option("--t-max", help="Final time (units of the paper).")] = 1000.0,
    n_times: Annotated[int | None, typer.Option("--n-times", parser=integer, help="Number of log-spaced output times from t_max/1000 to t_max (not with --times).", show_default="40")] = None,
    times: Annotated[str | None, typer.Option(help="Explicit output times, comma-separated, e.g. 10,100,1000.", show_default="none: see --n-times")] = None,
    seed: Annotated[int, typer.Option(parser=integer, help="Seed in [0, 2^64): fixes every number, whatever threads or chunks.")] = 0,
    theta0: Annotated[str, typer.Option("--theta0", help="Initial angle (radians) or 'uniform' on [-pi, pi).")] = "uniform",
    Omega0: Annotated[float, typer.Option("--Omega0", help="Initial angular velocity.")] = 0.0,
    h_max: Annotated[float | None, typer.Option("--h-max", help="Largest time step, > 0.", show_default=f"{DEFAULT_H_MAX:g}")] = None,
    step_c: Annotated[float | None, typer.Option("--step-c", help="Step control c >= 0: h <= c/|Omega| and c/sqrt(|omega^2+xi|); 0 = fixed step.", show_default=f"{DEFAULT_STEP_C:g}")] = None,
    hist_bins: Annotated[int | None, typer.Option("--hist-bins", parser=integer, help="Energy histogram bins, >= 1.", show_default=f"{DEFAULT_HIST_BINS}")] = None,
    backend: Annotated[str, typer.Option(help="Where to run: cpu, cuda, or auto (the GPU when usable).")] = "cpu",
    precision: Annotated[str, typer.Option(help="float64 or float32 (CUDA backend only).")] = "float64",
    threads: Annotated[int | None, typer.Option(parser=integer, help="CPU threads (results do not depend on it).", show_default="every CPU")] = None,
    bias_paths: Annotated[int | None, typer.Option("--bias-paths", parser=integer, help="Coupled coarse/fine pairs estimating each statistic's discretisation bias (0: none).", show_default="paths/48, at least 64")] = None,
    accuracy: Annotated[str, typer.Option(help="'fixed': the step control as given; 'auto': refine it until every estimated |bias| is within half a standard error.")] = "fixed",
    rtol: Annotated[float | None, typer.Option("--rtol", help="With --accuracy auto (implied): accept a bias up to this fraction of each value instead.", show_default="none: half a standard error")] = None,
    max_path_steps: Annotated[float | None, typer.Option("--max-path-steps", help="Refuse runs needing more than this many path-steps, paths x t_max / h_max (1e13: hours on a GPU; inf: no limit).", show_default="1e13")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", parser=file_name, help="Write the results as NetCDF (atomically).", show_default="none: no file")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing --out file.")] = False,
    checkpoint: Annotated[Path | None, typer.Option(parser=file_name, help="Save the run's state to this file periodically and on Ctrl-C; continue with 'stochpend resume FILE'.", show_default="none: no checkpoint")] = None,
    checkpoint_every: Annotated[str | None, typer.Option("--checkpoint-every", help="Checkpoint interval, e.g. 30s, 5m, 1h (needs --checkpoint).", show_default="5m")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no table.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
    param: Annotated[list[str] | None, typer.Option("--param", "-p", metavar="NAME=VALUE", help="A parameter the noise or the oscillator declares for itself, NAME=VALUE (repeat it; 'stochpend list' shows each piece's).", show_default="the pieces' defaults")] = None,
    plugin: Annotated[list[str] | None, typer.Option("--plugin", metavar="NAME", help="Load a noise, model or observable from outside stochpend: an installed stochpend plugin or a module's dotted name (repeat it).", show_default="none")] = None,
    joint_bins: Annotated[str | None, typer.Option("--joint-bins", metavar="NX,NO", help="Also histogram (x, Omega) jointly at every output time on NX x NO uniform bins (each 1..500): counts, density and its error in the result.", show_default="none")] = None,
    joint_x_range: Annotated[str | None, typer.Option("--joint-x-range", metavar="LO,HI", help="With --joint-bins, a non-periodic oscillator: the x range (a periodic one's angle is binned over [-pi, pi)).", show_default="+-joint Omega max/omega")] = None,
    joint_Omega_max: Annotated[float | None, typer.Option("--joint-Omega-max", help="With --joint-bins: the Omega range [-W, W).", show_default="every Omega the energy histogram covers")] = None,
    additive_noise: Annotated[str | None, typer.Option("--additive-noise", metavar="NAME", help="The additive noise xi_a's noise (with --param additive_D=...): a registered noise, e.g. harmonic or dichotomous; its parameters are --param additive_tau=, additive_omega_noise=, additive_<its own>=.", show_default="white, or ou when additive_tau > 0")] = None,
    observable: Annotated[list[str] | None, typer.Option("--observable", metavar="NAME", help="Also report a registered observable or per-path accumulator ('displacement', or one a --plugin registers; repeat it; 'stochpend list' shows them).", show_default="none")] = None,
    target_error: Annotated[float | None, typer.Option("--target-error", help="Ask for an accuracy instead: the relative total error (statistical + discretisation bias) of each target statistic at each output time, met by multilevel Monte Carlo on fixed steps h_max/2^l (--paths, --step-c, --bias-paths are not used; docs/numerics.md).", show_default="none: paths and steps as given")] = None,
    target_confidence: Annotated[float, typer.Option("--target-confidence", help="Confidence of --target-error's total error, in (0.5, 1).")] = 0.95,
    target_statistics: Annotated[str | None, typer.Option("--target-statistics", metavar="NAMES", help="With --target-error: the statistics to control, comma-separated: means (mean_E, mean_E2, ... or mean_<observable>, a time average's or running sum's too), a running sum's var_, rate_ and diffusion_<name>, and the paper's skewness and flatness.", show_default="mean_E,mean_E2")] = None,
    target_times: Annotated[str | None, typer.Option("--target-times", metavar="TIMES", help="With --target-error: the output times to control, comma-separated, among the run's.", show_default="every output time")] = None,
    max_seconds: Annotated[str | None, typer.Option("--max-seconds", metavar="DURATION", help="With --target-error: the wall-time budget (90, 30s, 5m, 1h30m); a target that would take longer at this machine's rate is refused before that work, saying what it would take.", show_default="none")] = None,
    config_file: Annotated[Path | None, typer.Option("--config", parser=file_name, is_eager=True, callback=_load_config,
                                                help="A TOML file of physics and numerics options, by their names here "
                                                "(noise, D, tau, t_max, paths, h_max, ...); options on the command "
                                                "line override it. It cannot set --out, --overwrite or --checkpoint.",
                                                show_default="none")] = None,
    ctx: typer.Context = None,  # type: ignore[assignment]
) -> None:
    """Simulate an ensemble and print the energy statistics (optionally save them as NetCDF)."""
    from stochpend.files import io
    from stochpend.model import settings
    from stochpend.runs import resources

    if ctx is not None:
        _config_keys_in_use(ctx)
    from stochpend.runs.lifecycle import RunOptions, execute, resolve_backend

    load_plugins(plugin)
    if out is not None:
        io.check_output_path(out, overwrite=overwrite)
    if times is not None and n_times is not None:
        raise ValueError(f"n_times={n_times!r} is not accepted with --times: give either --times "
                         "(explicit output times) or --n-times (log-spaced), not both")
    if n_times is None:
        n_times = 40
    kwargs: dict[str, Any] = {}
    if h_max is not None:
        kwargs["h_max"] = h_max
    if step_c is not None:
        kwargs["step_c"] = step_c
    if hist_bins is not None:
        kwargs["hist_bins"] = hist_bins
    kwargs.update(_joint_options(joint_bins, joint_x_range, joint_Omega_max))
    # Validate everything before any work (and before the JIT compiles).
    kwargs.update(potential=potential, power_n=n, coupling=coupling, omega_noise=omega_noise)
    if additive_noise is not None:
        kwargs["additive_noise"] = additive_noise
    noise_params = parse_params(param)
    config = settings.SimulationConfig.build(
        noise_params=noise_params,
        noise=noise, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max,
        times=parse_times(times), n_times=n_times, seed=seed, theta0=parse_theta0(theta0),
        Omega0=Omega0, observables=tuple(observable or ()), **kwargs,
    )
    if target_error is not None:
        from stochpend.cli._scale import parse_duration
        from stochpend.cli._target import simulate_target

        _check_checkpoint_every(checkpoint, checkpoint_every)
        simulate_target(config, target_error=target_error, target_confidence=target_confidence,
                        target_statistics=target_statistics, target_times=target_times,
                        backend=backend, precision=precision, max_path_steps=max_path_steps,
                        accuracy=accuracy, rtol=rtol, out=out, overwrite=overwrite, quiet=quiet,
                        config_file=config_file, ctx=ctx,
                        max_seconds=None if max_seconds is None else parse_duration(str(max_seconds), "max_seconds"),
                        checkpoint=checkpoint,
                        checkpoint_every=parse_duration("5m" if checkpoint_every is None else checkpoint_every))
        return
    if max_seconds is not None:
        raise ValueError(f"max_seconds={max_seconds!r} is not accepted without --target-error: the "
                         "wall-time budget is a target run's (bound other runs' work with --max-path-steps)")
    accuracy, rtol, bias_paths = _checked_accuracy(config, accuracy, rtol, bias_paths)
    _check_checkpoint_every(checkpoint, checkpoint_every)
    backend = resolve_backend(backend, note=note)  # 'auto' on a broken CUDA stack: a note
    # Memory and work, before any work: a run that cannot fit or would not end is refused.
    estimate = resources.check(config, backend=backend, precision=precision, max_path_steps=max_path_steps,
                               threads=threads)
    # The kernels it will compile (a cold Numba cache) count: a first run is mostly compiling.
    # The pair kernel counts also where the compile helper compiles it: the run waits for it, and
    # the compile figures are calibrated against the same sum (stochpend.numerics._calibration).
    estimate = resources.with_compile(estimate, config, pairs=bias_paths != 0 or accuracy == "auto")
    # A long run prints its estimate when it starts (after the remaining checks), even with --quiet.
    announce = (f"estimate: {estimate.describe()}" if estimate.total_seconds > resources.LONG_RUN_S
                else None)
    progress = RichProgress(enabled=not quiet and console.is_terminal, announce=announce)
    if checkpoint is not None:
        from stochpend.cli._scale import parse_duration, simulate_with_checkpoint

        # Checks the checkpoint path before any work; writes --out itself (as 'stochpend
        # resume' does), then removes the checkpoint; Ctrl-C saves it and exits 130.
        ds = simulate_with_checkpoint(
            config, checkpoint_path=checkpoint, every_s=parse_duration("5m" if checkpoint_every is None else checkpoint_every),
            out=out, overwrite=overwrite, progress=progress, threads=threads, backend=backend,
            precision=precision, bias_paths=bias_paths, accuracy=accuracy, rtol=rtol,
            max_path_steps=max_path_steps,
        )
    else:
        import warnings

        from stochpend.text._warnings import StochpendWarning

        # The API raises its notes as warnings; the command prints them itself, below the table.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StochpendWarning)
            ds = execute(RunOptions.build(config, backend=backend, precision=precision, threads=threads,
                                   bias_paths=bias_paths, accuracy=accuracy, rtol=rtol,
                                   max_path_steps=max_path_steps), progress=progress)[0]
        _provenance(ds, config_file, ctx)
        if out is not None:
            io.to_netcdf(ds, out, overwrite=overwrite)
    if not quiet:
        _print_run(ds, out)


def _provenance(ds: Any, config_file: Path | None, ctx: typer.Context | None) -> None:
    """The command line, and the --config file as it was read, in the result's attrs."""
    ds.attrs["command_line"] = " ".join(["stochpend", *sys.argv[1:]])
    if config_file is not None and ctx is not None:
        ds.attrs["config_file"] = str(config_file)
        ds.attrs["config_text"] = ctx.meta.get("stochpend.config_text", "")


def _print_run(ds: Any, out: Path | None) -> None:
    """A run's results on stdout (the summary table, the observables', the joint histogram's
    lines, the first passages') and its warnings and notes on stderr."""
    results.print(summary_table(ds, width=results.width, more=_cli_common.rows_hint(out)))
    extra = observables_table(ds, width=results.width)
    if extra is not None:
        results.print(extra)
    for line in joint_lines(ds):
        results.print(line, markup=False, highlight=False)
    for table in passage_tables(ds):
        results.print(table)
    for line in bias_warnings(ds, shown_rows(ds)):
        console.print(f"[yellow]{escape(line)}[/]", highlight=False, soft_wrap=True)
    for line in bias_notes(ds):
        note(line)
    nonfinite_line(ds)
    for kind, line in growth_lines(ds):
        if kind == "warning":
            console.print(f"[yellow]{escape(line)}[/]", highlight=False, soft_wrap=True)
        else:
            note(line)
    if out is not None:
        console.print(f"wrote {markup(out)}", highlight=False, soft_wrap=True)


def _checked_accuracy(config: Any, accuracy: str, rtol: float | None,
                      bias_paths: int | None) -> tuple[str, float | None, int | None]:
    """--accuracy, --rtol and --bias-paths, checked (stochpend.bias) before any work."""
    from stochpend.runs import bias

    accuracy, rtol = bias.check_accuracy(accuracy, rtol)
    if bias_paths is not None:
        bias_paths = bias.check_bias_paths(bias_paths, config.paths)
    return accuracy, rtol, bias_paths


def _check_checkpoint_every(checkpoint: Path | None, checkpoint_every: str | None) -> None:
    if checkpoint_every is not None and checkpoint is None:
        raise ValueError(f"checkpoint_every={checkpoint_every!r} is not accepted: it needs --checkpoint FILE")


def growth_lines(ds: Any) -> list[tuple[str, str]]:
    """What a run's growth of <E> says beside the model's predicted law (:func:`stochpend.
    theory.scaling.predicted_exponent`), as ("warning" | "note", line) pairs.

    A finite-time blow-up (non-finite paths) is a warning. An accelerating growth
    (:func:`stochpend.exponents.diagnose_growth` "exponential") is a warning only where it
    contradicts the prediction: none where the model predicts exponential growth; where it
    predicts t^nu and the late log-log slope is still below nu + 4 standard errors, a note that
    the run is approaching the law (a quartic oscillator's slope climbs towards 1 over decades);
    a warning where the slope is beyond it, or where no law is predicted (a user's model)."""
    import numpy as np  # here, not at the top: --help and --version need no NumPy (0.1 s)

    from stochpend.theory.exponents import diagnose_growth, fit_exponent
    from stochpend.theory.scaling import predicted_exponent

    growth = diagnose_growth(ds, detail=True)
    if growth.startswith("finite-time blow-up"):
        return [("warning", f"growth of <E>: {growth}")]
    if not growth.startswith("exponential"):
        return []
    attrs = ds.attrs
    if attrs.get("dynamics_parameters"):  # damping, drives, a second noise: no law predicted here to contradict
        return [("note", f"growth of <E>: {growth}")]
    try:
        law = predicted_exponent(str(attrs.get("potential", "pendulum")), str(attrs.get("noise", "ou")),
                                 str(attrs.get("coupling", "force")), int(attrs.get("power_n", 2)))
    except (ValueError, TypeError, KeyError):
        law = None
    if law is None or law.growth not in ("power", "exponential"):
        return [("warning", f"growth of <E>: {growth}")]
    if law.growth == "exponential":
        return []
    t = np.asarray(ds["time"].values, dtype=float)
    late = t[-max(3, t.size // 4):]
    try:
        fit = fit_exponent(ds, float(late[0]), float(late[-1]))
    except ValueError:
        return [("warning", f"growth of <E>: {growth}")]
    nu = float(law.exponent or 0.0)  # a power law has an exponent
    if fit.exponent < nu + 4 * fit.se:
        return [("note", f"the late log-log slope of <E> is {fit.exponent:.3g} +- {fit.se:.2g} and still rising "
                         f"towards the predicted t^{nu:.4g} ({law.regime}): a longer --t-max reaches the law")]
    return [("warning", f"growth of <E> faster than the predicted t^{nu:.4g}: late log-log slope "
                        f"{fit.exponent:.3g} +- {fit.se:.2g}, still rising ({growth.split(': ', 1)[-1]})")]


def result_kind(ds: Any) -> str | None:
    """What wrote ``ds``: "sweep" (a parameter dimension beside time), "bfpe" (the averaged
    B.F.P.E.'s solution), "reduced" (the reduced dynamics), "simulation" (simulate, a
    checkpointed run, resume, reproduce's runs), or None (not a file of stochpend's)."""
    title = str(ds.attrs.get("title", ""))
    if "target_error" in ds.attrs and "n_samples" in ds:  # simulate --target-error (stochpend.runs.multilevel)
        return "sweep" if title == "stochpend parameter sweep" else "target"  # or a sweep of them
    if "mean_E" not in ds:
        return None
    if title == "stochpend parameter sweep" or any(d not in ("time", "E_bin", "E_bin_edge", "batch")
                                                     for d in ds["mean_E"].dims):
        return "sweep"
    if "identity_residual" in ds and "phi" in ds:
        return "bfpe"
    if "mean_E_stderr" not in ds:
        return None
    return "reduced" if title.startswith("stochpend reduced dynamics") else "simulation"


def open_result(path: Path, plain: bool = False) -> tuple[Any, list[str]]:
    """:func:`stochpend.io.open_results` (``plain``: without xarray where it can) and its notes
    (a file without a checksum), for the caller to print once it knows the file is one it can use."""
    import warnings

    from stochpend.files import io
    from stochpend.text._warnings import StochpendWarning

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", StochpendWarning)
        ds = io.open_results(path, plain=plain)
    return ds, [str(w.message) for w in caught if issubclass(w.category, StochpendWarning)]


#: What `show --format` writes.
SHOW_FORMATS = ("table", "csv", "json")


def _csv_text(ds: Any) -> tuple[str, list[str]]:
    """(CSV text, variables left out): every variable over the dimensions of ``mean_E`` (one
    row per output time, or per parameter set and time), full precision. Names and text cells
    come from a file and are made safe for a terminal (:func:`stochpend.text._terminal.plain`)."""
    import csv
    import io as _text_io

    from stochpend.text._terminal import plain

    dims = ds["mean_E"].dims
    names = [str(n) for n in ds.data_vars if ds[n].dims == dims]
    left_out = sorted(plain(n) for n in ds.data_vars if ds[n].dims != dims)
    frame = ds[names].to_dataframe().reset_index()
    buffer = _text_io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow([plain(c) for c in frame.columns])
    for row in frame.itertuples(index=False):
        writer.writerow([plain(v) if isinstance(v, str) else repr(float(v)) if isinstance(v, float) else v
                         for v in row])
    return buffer.getvalue(), left_out


def _json_text(ds: Any) -> str:
    """The whole result as JSON (xarray's ``to_dict``: dims, coords, data_vars, attrs); NaN and
    infinities as null, every non-ASCII or control character escaped."""
    import json

    import numpy as np

    def clean(x: Any) -> Any:
        if isinstance(x, dict):
            return {str(k): clean(v) for k, v in x.items()}
        if isinstance(x, list | tuple):
            return [clean(v) for v in x]
        if isinstance(x, np.ndarray):
            return clean(x.tolist())
        if isinstance(x, np.generic):
            return clean(x.item())
        if isinstance(x, float) and not np.isfinite(x):
            return None
        if isinstance(x, bytes):
            return x.decode("utf-8", "backslashreplace")
        return x

    return json.dumps(clean(ds.to_dict(data="list")), ensure_ascii=True, allow_nan=False)


@app.command()
@handles_errors
def show(
    path: Annotated[Path, typer.Argument(parser=file_name, help="A file stochpend wrote: simulate, resume, sweep, reduced or bfpe --out.")],
    rows: Annotated[int, typer.Option(parser=integer, help="Maximum number of output times shown, >= 1.")] = 12,
    format: Annotated[str, typer.Option("--format", help="table (for reading), csv (every output time, full "
                                        "precision) or json (the whole file: data, coordinates, attributes).")] = "table",
) -> None:
    """Print the table of a saved result (a run, a sweep, a reduced run or a B.F.P.E. solution)."""
    if rows < 1:
        raise ValueError(f"rows={rows!r} is not accepted: an integer >= 1")
    if format not in SHOW_FORMATS:
        raise ValueError(f"--format={format!r} is not accepted: one of {', '.join(SHOW_FORMATS)}")
    # A run's table is shown without xarray where the file allows (stochpend.files._plain: 0.45 s
    # less to start); a sweep's, a solution's and the CSV and JSON texts use the Dataset.
    ds, notes = open_result(path, plain=format == "table")
    kind = result_kind(ds)
    if kind is None:
        raise ValueError(f"path={str(path)!r} is not accepted: not a file stochpend writes (a simulation, "
                         "checkpointed run, sweep, reduced run or B.F.P.E. solution)")
    for line in notes:
        note(line)
    if isinstance(ds, Plain) and kind not in ("simulation", "reduced"):
        ds = ds.to_xarray()
    if format != "table":
        try:
            if format == "json":
                text, left_out = _json_text(ds) + "\n", list[str]()
            else:
                text, left_out = _csv_text(ds)
        except (KeyError, AttributeError, TypeError, ValueError, OverflowError, IndexError) as exc:
            why = " ".join(str(exc).split()) or type(exc).__name__
            raise ValueError(f"path={str(path)!r} is not accepted: not a stochpend result this "
                             f"command can write as {format} ({why})") from None
        sys.stdout.write(text)
        sys.stdout.flush()
        if left_out:
            note(f"the CSV holds the variables over ({', '.join(ds['mean_E'].dims)}); "
                 f"{', '.join(left_out)} are in --format json")
        return
    try:
        shown = _shown(path, ds, kind, rows)
    except Exception:
        if not isinstance(ds, Plain):
            raise
        # What a file lacks is said in xarray's words, as before: the Dataset says it again.
        ds = ds.to_xarray()
        shown = _shown(path, ds, kind, rows)
    tables, lines, warned, notes = shown
    for table in tables:
        results.print(table)
    for line in lines:
        results.print(line, markup=False, highlight=False)
    for line in warned:
        console.print(f"[yellow]{escape(line)}[/]", highlight=False, soft_wrap=True)
    for line in notes:
        note(line)
    if kind in ("simulation", "reduced"):
        nonfinite_line(ds)


def _shown(path: Path, ds: Any, kind: str, rows: int) -> tuple[list[Any], list[str], list[str], list[str]]:
    """What ``show`` prints of ``ds`` (a result of ``kind``), built whole before anything is
    printed: its tables, the joint histogram's lines, the bias warnings and notes."""
    warned: list[str] = []
    tables: list[Any]
    try:
        if kind == "target":
            from rich.text import Text

            from stochpend.runs.multilevel import summary_lines

            # A Text, not a string: Rich would read a statistic's name from the file as markup.
            tables = [Text("\n".join(summary_lines(ds)))]
        elif kind == "sweep":
            from stochpend.cli._scale import sweep_table

            tables = [sweep_table(ds)]
        elif kind == "bfpe":
            from stochpend.cli._theory import bfpe_table

            tables = [bfpe_table(ds, max_rows=rows, width=results.width)]
        else:
            tables = [summary_table(ds, max_rows=rows, width=results.width)]
            extra = observables_table(ds, max_rows=rows, width=results.width)
            if extra is not None:
                tables.append(extra)
            tables += passage_tables(ds)
            if kind == "reduced":
                from stochpend.cli._theory import reduced_table

                tables.append(reduced_table(ds))
            warned = bias_warnings(ds, shown_rows(ds, rows))
    except (KeyError, AttributeError, TypeError, ValueError, OverflowError, IndexError) as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"path={str(path)!r} is not accepted: not a stochpend result this "
                         f"command can show ({why})") from None
    lines = joint_lines(ds) if kind not in ("sweep", "target") else []
    return tables, lines, warned, bias_notes(ds)


def nonfinite_line(ds: Any) -> None:
    """The warning ``simulate`` prints of paths that escaped, printed by ``show`` of its file too
    (63 of 100 escaped paths went unmentioned)."""
    try:
        count = int(ds["nonfinite_paths"].values.reshape(-1)[-1])
    except (KeyError, IndexError, TypeError, ValueError, OverflowError):
        return
    if count > 0:
        console.print(f"[yellow]{count} paths went non-finite (or ran away) and are excluded.[/]")


@app.command("list")
@handles_errors
def list_pieces(
    plugin: Annotated[list[str] | None, typer.Option("--plugin", metavar="NAME", help="Load a plugin first (an installed stochpend plugin or a module's dotted name), to list its pieces.", show_default="none")] = None,
) -> None:
    """The noises (with the parameters they declare), oscillators and couplings a run can use
    (--noise, --param, --potential, --coupling), with the pieces of the plugins loaded."""
    load_plugins(plugin)
    from stochpend.model import noises, oscillators
    from stochpend.model import user_models as models
    from stochpend.text._terminal import plain as _plain
    from stochpend.text.equations import with_numbers

    def plain(text: str) -> str:
        return _plain(with_numbers(text))

    table = Table(title="stochpend: the pieces a run is built from")
    for col in ("option", "name", "what it is"):
        table.add_column(col)
    from stochpend.model.parameters import own

    for name in noises.names():
        piece = noises.get(name)
        text = plain(getattr(piece, "description", ""))
        for p in own(piece):  # its own parameters: --param NAME=VALUE
            text += f"; --param {p.name}=... ({p.default:g}): {plain(p.meaning)}"
        table.add_row("--noise", name, text)
    for name in oscillators.names():
        table.add_row("--potential", name, plain(getattr(oscillators.get(name), "description", "")))
    for name in models.names():
        model = models.get(name)
        text = "user model: " + plain(getattr(model, "description", None) or "")
        for p in own(model):  # its own parameters: --param NAME=VALUE
            text += f"; --param {p.name}=... ({p.default:g}): {plain(p.meaning)}"
        table.add_row("--potential", name, text)
    table.add_row("--coupling", "force", "the noise multiplies the force U'(x) (the paper's pendulum)")
    table.add_row("--coupling", "position", "the noise multiplies x (the random-frequency oscillator)")
    from stochpend.model import dynamics

    for p in dynamics.FAMILY.parameters:  # the family's terms, on any model: --param NAME=VALUE
        table.add_row("--param", f"{p.name}=...", plain(f"({p.default:g}) {p.meaning}"))
    from stochpend.model import observables

    for name in observables.names():
        o = observables.get(name)
        kind = {"Observable": "mean of a per-path value", "TimeAverage": "per-path time average",
                "FirstPassage": "first-passage time", "RunningSum": "per-path running sum"}.get(type(o).__name__, "")
        table.add_row("--observable", name, plain(f"{kind}: {o.description or o.name}"))
    table.caption = ("A noise, oscillator or observable of your own: stochpend.noises.register / "
                     "stochpend.models.register / stochpend.observables.register (docs/models.md), "
                     "loaded with --plugin MODULE.")
    results.print(table)


PLOT_FORMATS = ("png", "pdf", "svg")


@app.command()
@handles_errors
def plot(
    path: Annotated[Path, typer.Argument(parser=file_name, help="A results file written by 'stochpend simulate --out'.")],
    out: Annotated[Path | None, typer.Option("--out", parser=file_name, help="The figure to write.", show_default="the results file's name with the format's extension")] = None,
    format: Annotated[str | None, typer.Option("--format", help="png, pdf or svg.", show_default="from --out's extension, else png")] = None,
    band: Annotated[float, typer.Option("--band", help="Width of the shaded band in standard errors, >= 0 (0: none).")] = 2.0,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing figure file.")] = False,
) -> None:
    """Plot <E>(t) of a saved run, log-log, with its error band and the predicted law."""
    from stochpend.files import io
    from stochpend.paper import plotting

    try:  # an optional extra: say so in one line, before any work
        import matplotlib  # noqa: F401
    except ImportError:
        raise ValueError("matplotlib is not installed: pip install 'stochpend[plot]'") from None
    if format is None:
        suffix = (out.suffix.lstrip(".").lower() if out is not None else "") or "png"
        format = suffix if suffix in PLOT_FORMATS else None
        if format is None:
            raise ValueError(f"--out={str(out)!r} is not accepted: its extension must be one of "
                             f"{', '.join('.' + f for f in PLOT_FORMATS)} (or give --format)")
    if format not in PLOT_FORMATS:
        raise ValueError(f"--format={format!r} is not accepted: one of {', '.join(PLOT_FORMATS)}")
    if not (math.isfinite(band) and band >= 0):
        raise ValueError(f"--band={band!r} is not accepted: a number >= 0 (standard errors)")
    target = out if out is not None else Path(path).with_suffix("." + format)
    io.check_output_path(target, overwrite=overwrite, name="out")
    ds, notes = open_result(path)
    kind = result_kind(ds)
    if kind not in ("simulation", "reduced", "target"):
        # One line for a file it cannot draw (a sweep's IndexError and a B.F.P.E. solution's
        # KeyError were tracebacks): what the file is, and what shows it.
        what = {"sweep": "a parameter sweep's result", "bfpe": "a B.F.P.E. solution"}.get(str(kind))
        shown = f"; `stochpend show {shlex.quote(str(path))}` prints its table" if what else ""
        raise ValueError(f"path={str(path)!r} is not accepted: plot draws one run's <E>(t) (simulate, "
                         f"resume, reduced, reproduce's runs/*.nc); this is "
                         f"{what or 'not a result stochpend writes'}{shown}")
    for line in notes:
        note(line)
    import io as _bytes_io

    buffer = _bytes_io.BytesIO()
    try:
        figure = plotting.plot_target(ds) if kind == "target" else plotting.plot_run(ds, band=band)
    except (KeyError, AttributeError, TypeError, ValueError, OverflowError, IndexError) as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"path={str(path)!r} is not accepted: not a run this command can draw ({why})") from None
    figure.savefig(buffer, format=format, dpi=150)
    written = io.write_bytes_atomic(buffer.getvalue(), target, overwrite=overwrite)
    console.print(f"wrote {markup(written)}", highlight=False, soft_wrap=True)


def _version_of(package: str) -> str | None:
    """An installed package's version from its metadata (importing it would take seconds); None
    where it cannot be imported (no module found, or an import blocked by sys.modules[name] = None)."""
    import importlib.util
    from importlib import metadata

    try:
        if importlib.util.find_spec(package) is None:  # locates the package, imports nothing
            return None
        return metadata.version(package)
    except (metadata.PackageNotFoundError, ImportError, ValueError):
        return None


def _numba_threads() -> str:
    """Numba's thread count and layer as Numba reads them (numba.core.config), without importing
    Numba: NUMBA_NUM_THREADS (checked by _check_numba_threads) or the CPUs this process may use."""
    import os

    text = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    try:
        threads = int(text)
    except ValueError:
        threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    layer = os.environ.get("NUMBA_THREADING_LAYER", "").strip() or "default"
    return f"{threads} (layer: {layer})"


def _no_cuda_driver() -> str | None:
    """Why CUDA cannot be usable here, seen without importing Numba (seconds), or None where it
    may be (then Numba's own check and a test kernel decide): on Linux, no NVIDIA device node
    (/dev/nvidiactl, or WSL's /dev/dxg) and no Numba CUDA simulator."""
    import os

    if not sys.platform.startswith("linux"):
        return None
    if os.environ.get("NUMBA_ENABLE_CUDASIM", "0").strip() not in ("", "0"):
        return None
    if any(os.path.exists(p) for p in ("/dev/nvidiactl", "/dev/nvidia0", "/dev/dxg", "/proc/driver/nvidia")):
        return None
    return "no NVIDIA driver on this machine (no /dev/nvidiactl)"


def _machine_rows() -> list[tuple[str, str]]:
    """(item, value) rows of ``info``: the CPUs this process may use, the memory (total, and
    available to a run: less under a cgroup limit), and where compiled kernels are cached,
    each read without importing Numba."""
    import os

    from stochpend.numerics import _calibration
    from stochpend.runs import resources

    rows = [("cpus usable", str(_calibration.cores()))]
    try:
        total: int | None = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = None
    available = resources.available_memory()
    rows.append(("memory", f"{resources.format_bytes(total) if total else 'unknown'} in all, "
                           f"{resources.format_bytes(available) if available else 'unknown'} available"))
    cache = os.environ.get("NUMBA_CACHE_DIR", "").strip()
    where = (f"{cache} (NUMBA_CACHE_DIR)" if cache else
             f"the __pycache__ folders of {Path(__file__).resolve().parents[1]} (Numba's default; a temporary "
             "folder, per process, where they are not writable)")
    rows.append(("kernel cache", markup(where)))
    rows.append(("calibration", markup(str(_calibration.path()))))
    return rows


@app.command()
def info() -> None:
    """Versions, threads, and which backends are usable here."""
    import platform

    from stochpend._version import __version__

    def version(package: str) -> str:
        return _version_of(package) or "not installed"

    table = Table(title="stochpend info")
    table.add_column("item")
    # folded, never cut: a cache or calibration path is longer than an 80-column row leaves
    table.add_column("value", overflow="fold")
    table.add_row("stochpend", __version__)
    table.add_row("python", platform.python_version())
    table.add_row("numpy / numba / xarray", f"{version('numpy')} / {version('numba')} / {version('xarray')}")
    table.add_row("numba threads", _numba_threads())
    table.add_row("machine", f"{platform.machine()} {platform.processor()}")
    for item, value in _machine_rows():  # walk-through N13: cores, memory and the kernel cache
        table.add_row(item, value)
    from stochpend.numerics import _cputarget

    table.add_row("cpu target", _cputarget.planned())  # what the CPU kernels compile for (--cpu-target)
    table.add_row("backend cpu", "usable")
    why_not = _no_cuda_driver()
    if why_not is not None:  # nothing to probe: Numba (seconds to import) is not needed
        table.add_row("backend cuda", "not usable: " + why_not)
    else:
        from stochpend.runs.simulate import cuda_status

        # The driver and the device, then a tiny kernel compiled and launched (a CUDA stack that
        # imports but cannot compile is "unusable").
        usable, why, broken = cuda_status()
        table.add_row("backend cuda", ("usable: " if usable else "unusable: " if broken else "not usable: ") + why)
    dask, distributed = _version_of("dask"), _version_of("distributed")
    if dask and distributed:
        table.add_row("dask / distributed", f"{dask} / {distributed}")
    else:
        table.add_row("dask / distributed", markup("not installed (pip install 'stochpend[dask]')"))
    results.print(table)


# Scale-out commands (stochpend.cli._scale imports this module lazily, so either order works).
from stochpend.cli._scale import resume_command, sweep_command  # noqa: E402

app.command("sweep")(sweep_command)
app.command("resume")(resume_command)


def main() -> None:  # pragma: no cover
    """The ``stochpend`` command (the console script and ``python -m stochpend``)."""
    _cli_common._OWNS_PROCESS = True
    app()


if __name__ == "__main__":  # pragma: no cover
    main()


# -- commands defined beside their subject (they import the helpers above) ---------------------
from stochpend.cli._theory import bfpe_command, reduced_command, scaling_command, theory_command  # noqa: E402

app.command("theory")(theory_command)
app.command("scaling")(scaling_command)
app.command("bfpe")(bfpe_command)
app.command("reduced")(reduced_command)

from stochpend.cli._reproduce import reproduce_command  # noqa: E402

app.command("reproduce")(reproduce_command)

# Every command: literal help text, flags without a metavar (HelpCommand).
for _info in app.registered_commands:
    if _info.cls in (None, TyperCommand):
        _info.cls = HelpCommand

