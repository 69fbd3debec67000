"""The command line's shared layer: the consoles, one-line errors and notes, the error
handling every command wears, and the tables and number formats that several commands print.

:mod:`stochpend.cli` and the command modules (``_cli_scale``, ``_cli_theory``,
``_cli_reproduce``) import from here; nothing here imports them, so the command line's modules
form no import cycle. Rich is imported here and in the command modules only.
"""

from __future__ import annotations

import functools
import math
import re
import sys
import time
from collections.abc import Callable
from typing import Any, TypeVar

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from stochpend.text._notation import ve
from stochpend.text._terminal import markup

# sys.stderr is None when file descriptor 2 is closed (`2>&-`): Rich then prints nothing.
#: Progress, notes, warnings and errors: standard error.
console = Console(stderr=True, width=None if sys.stderr is not None and sys.stderr.isatty() else 140)
#: Results (tables): standard output, so that ``stochpend show run.nc > table.txt`` and pipes
#: get them; not wrapped when it is not a terminal.
class _ResultsConsole(Console):
    """Rich's console on standard output whose failed write names what failed: stdout on a
    full device gave "[Errno 28] No space left on device" after the result file was written,
    which read as if the result had failed."""

    def print(self, *args: Any, **kwargs: Any) -> None:
        from stochpend.files._files import WriteError, reason

        try:
            super().print(*args, **kwargs)
        except BrokenPipeError:
            raise
        except OSError as exc:
            raise WriteError(f"cannot write the results to standard output: {reason(exc)} (files the "
                             "command wrote before this are complete)", getattr(exc, "errno", None)) from None


results = _ResultsConsole(width=None if sys.stdout is not None and sys.stdout.isatty() else 200)

F = TypeVar("F", bound=Callable[..., Any])

# stochpend.model.settings's defaults and limits, as the help shows them (importing params would load
# Numba before '--help'; tests/unit/test_cli_help.py checks that they agree).
DEFAULT_H_MAX, DEFAULT_STEP_C, DEFAULT_HIST_BINS = 0.05, 0.1, 100
MAX_OMEGA, MAX_POWER_N = 1e150, 1000


def note(message: str) -> None:
    """Print one yellow line (a fallback the user should know about): folded to a terminal's
    width, one line in a pipe or a log (for grep)."""
    console.print(f"[yellow]note:[/] {escape(message)}", highlight=False, soft_wrap=not console.is_terminal)


def fail(message: str, code: int = 2) -> None:
    """Print one red line and exit; a refusal the Python API words with its argument names
    (``h_max=0.0 is not accepted: h_max must be ...``) names the running command's options
    instead (``--h-max 0.0 is not accepted: ...``), see :func:`cli_message`."""
    from stochpend.text._terminal import short

    # An error may quote text from a file (a crafted variable name, a header value): shortened
    # well above any path's length (PATH_MAX 4096), so that it stays one readable line.
    message = short(cli_message(message, _option_names()), 8192)
    console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


#: Arguments of the Python API that a command's option of another name sets (API name: the
#: command's parameter): simulate's --n is power_n, theory's --time is t.
_API_NAMES = {"power_n": "n", "t": "time"}


def _option_names() -> dict[str, str]:
    """``{python name: '--option'}`` of the running command (empty outside one)."""
    import importlib

    try:  # Typer >= 0.29 carries its own copy of Click
        click_globals = importlib.import_module("typer._click.globals")
    except ImportError:  # a Typer that uses Click itself
        click_globals = importlib.import_module("click.globals")
    ctx = click_globals.get_current_context(silent=True)
    names: dict[str, str] = {}
    if ctx is None:
        return names
    for param in ctx.command.params:
        longs = [o for o in getattr(param, "opts", ()) if o.startswith("--")]
        if longs and not getattr(param, "hidden", False) and param.name:
            names[param.name] = longs[0]
    for api, name in _API_NAMES.items():
        if name in names and api not in names:
            names[api] = names[name]
    for name, source in ctx.meta.get("stochpend.config_keys", {}).items():
        names[name] = f"{source}: {name}="  # set by --config FILE: the file's key, as written
    return names


_ASSIGNED = re.compile(r"(?<![\w.:-])([A-Za-z_]\w*)=")


def cli_message(message: str, names: dict[str, str]) -> str:
    """A one-line refusal of the Python API in the command line's words: ``NAME=VALUE is not
    accepted: NAME must be X`` -> ``--option VALUE is not accepted: X``; further ``NAME=VALUE``
    that name an option become ``--option VALUE``. Messages that do not start with an option's
    name (a file's key, an argument) are unchanged."""
    # "raise the limit with max_path_steps= (--max-path-steps)": the option alone
    message = re.sub(r"\b\w+= \((--[\w-]+)\)", r"\1", message)
    m = _ASSIGNED.match(message)
    if not m or m.group(1) not in names:
        return message
    name = m.group(1)
    rest = message[m.end():].replace(f"is not accepted: {name} must be ", "is not accepted: ", 1)
    if not names[name].endswith("="):
        rest = rest.replace(f"is not accepted: {name} ", f"is not accepted: {names[name]} ", 1)

    def option(match: re.Match[str]) -> str:
        opt = names.get(match.group(1))
        if opt is None:
            return match.group(0)
        return opt if opt.endswith("=") else opt + " "

    return option(m) + _ASSIGNED.sub(option, rest)


#: Whether this process is the command line's own (``main``), not a Python caller of ``app``
#: (a test's CliRunner): only then may a command change the process's signal dispositions.
_OWNS_PROCESS = False


def _stop_listening() -> None:
    """Ignore further Ctrl-C and SIGTERM/SIGHUP: the command is already exiting after one. Only
    in the tool's own process: an ignored signal would outlive the call in a caller's process,
    and its child processes would inherit it."""
    if not _OWNS_PROCESS:
        return
    import signal

    for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):
        try:
            signal.signal(sig, signal.SIG_IGN)
        except (ValueError, OSError):  # not the main thread
            pass


#: NUMBA_NUM_THREADS above this starts no run (1e6 made Numba's thread pool die with SIGSEGV).
MAX_NUMBA_THREADS = 4096


def _check_numba_threads() -> None:
    """NUMBA_NUM_THREADS is read when Numba is imported: 0 gave a traceback, 1e6 a segfault."""
    import os

    text = os.environ.get("NUMBA_NUM_THREADS")
    if text is None or not text.strip():
        return
    try:
        n = int(text)
    except ValueError:
        return  # Numba ignores it with its own warning and uses the CPU count
    if not 1 <= n <= MAX_NUMBA_THREADS:
        fail(f"NUMBA_NUM_THREADS={text!r} is not accepted: an integer in [1, {MAX_NUMBA_THREADS}] "
             "(the environment variable; or unset it to use every CPU)")


#: The commands that compile kernels (their functions' names).
_COMPILING = ("simulate", "resume_command", "sweep_command", "bfpe_command", "reduced_command",
              "reproduce_command")


def _check_jit(command: str) -> None:
    """NUMBA_DISABLE_JIT=1 runs the kernels as Python, where their intrinsics cannot run: a
    71-line traceback after the checks. Refused in one line before the work."""
    import os

    text = os.environ.get("NUMBA_DISABLE_JIT", "").strip()
    try:
        disabled = bool(int(text)) if text else False
    except ValueError:
        return  # Numba ignores it with its own warning
    if disabled and command in _COMPILING:
        fail(f"NUMBA_DISABLE_JIT={text!r} is not accepted: stochpend's kernels run only compiled "
             "(the environment variable; unset it or set it to 0)")


def handles_errors(fn: F) -> F:
    """Turn the API's ValueError into one line and exit code 2, and a file that cannot be
    written or read (``OSError``: a full disk, an I/O error) into one line and exit code 1
    (traceback with --debug)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        import warnings

        _check_jit(fn.__name__)
        try:
            # NumPy's and other libraries' warnings (an overflow while checking extreme input)
            # are caught: a refusal is one line, not a warning's two lines and then the error
            # (T04, D01); a command that succeeds prints each once, as one note line.
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("default")
                value = fn(*args, **kwargs)
            seen: set[str] = set()
            for w in caught:
                text = " ".join(str(w.message).split())
                line = text if w.category.__name__ == "StochpendWarning" else f"{w.category.__name__}: {text}"
                if line not in seen:
                    seen.add(line)
                    note(line)
            return value
        except ValueError as exc:
            if "--debug" in sys.argv:
                raise
            fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        except OSError as exc:
            if "--debug" in sys.argv:
                raise
            fail(" ".join(str(exc).split()) or type(exc).__name__, code=1)
        except ArithmeticError as exc:  # values each valid alone, beyond the floats together
            if "--debug" in sys.argv:
                raise
            given = [a for a in sys.argv[1:] if a.startswith("--") and a not in ("--quiet", "--debug")]
            fail(f"the values of {' '.join(given) or 'the defaults'} are not accepted: "
                 f"a result lies beyond the floating-point range ({type(exc).__name__}: {exc}); "
                 "use less extreme values")
        except KeyboardInterrupt as exc:
            _stop_listening()
            for bar in list(_BARS):  # the bar first: redrawn after the line, it hid the prompt's line (I1)
                bar.finish()
            console.print("[yellow]interrupted[/]")
            raise typer.Exit(128 + getattr(exc, "signum", 2)) from None

    return wrapper  # type: ignore[return-value]


def parse_params(values: list[str] | None) -> dict[str, Any]:
    """``--param NAME=VALUE`` options as a mapping (the noise validates names and values)."""
    out: dict[str, Any] = {}
    for item in values or ():
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name or not value.strip():
            raise ValueError(f"--param {item!r} is not accepted: NAME=VALUE, a parameter the noise declares")
        if name in out:
            raise ValueError(f"--param {item!r} is not accepted: {name} is given twice")
        out[name] = value.strip()
    return out


def load_plugins(names: list[str] | None) -> None:
    """Load each ``--plugin`` (:func:`stochpend.plugins.load`): code runs only when the command
    line asks for it, never because a file names a piece."""
    from stochpend.model import plugins

    for name in names or ():
        plugins.load(name)


def parse_times(text: str | None) -> list[float] | None:
    """'10,100,1000' -> [10.0, 100.0, 1000.0]."""
    if text is None:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"times={text!r} is not accepted: a comma-separated list of numbers, e.g. 10,100,1000") from None


def parse_pair(name: str, text: str | None, accepted: str) -> list[str] | None:
    """``--joint-bins 40,30`` and the like: two comma-separated values (validated, with the
    parameter's name, by ``SimulationConfig.build``); None when not given."""
    if text is None:
        return None
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 2 or not all(parts):
        raise ValueError(f"{name}={text!r} is not accepted: {accepted}")
    return parts


def parse_theta0(text: str) -> float | str:
    if text == "uniform":
        return text
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"theta0={text!r} is not accepted: a number (radians) or 'uniform'") from None


class RichProgress:
    """A Rich progress bar with rate and ETA; implements :class:`stochpend.text.progress.Progress`.

    ``announce``: a line printed when the run starts (after every check), even when the bar
    is disabled (--quiet): the estimate of a long run. A long run without a bar (--quiet, or
    stderr not a terminal, e.g. a batch job's log) also prints a heartbeat every
    ``heartbeat_s`` seconds, so that a run that lasts is seen to be alive:
    ``progress: simulating 37.0 % after 5.0 min, about 8.5 min left``.
    """

    def __init__(self, enabled: bool, announce: str | None = None, heartbeat_s: float = 60.0,
                 clock: Any = None, long_run: bool = False) -> None:
        self.enabled = enabled
        self.announce = announce
        # long_run: a run known to last (a resumed checkpointed run) beats without an announce
        self.heartbeat = heartbeat_s if ((announce or long_run) and not enabled) else None
        self._clock = clock or time.monotonic
        self._progress: Any = None
        self._task: Any = None
        self._beat: tuple[float, float, str, float] | None = None  # started, total, what, next

    def start(self, total: float, description: str) -> None:
        if self.announce:  # folded to a terminal's width, one line in a pipe
            console.print(self.announce, highlight=False, soft_wrap=not console.is_terminal)
            self.announce = None
        if self.heartbeat is not None:
            now = self._clock()
            self._beat = (now, float(total), description, now + self.heartbeat)
        if not self.enabled:
            return
        from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=True,
        )
        self._progress.start()
        _BARS.append(self)
        self._task = self._progress.add_task(description, total=total)

    def update(self, done: float) -> None:
        if self._progress is not None:
            self._progress.update(self._task, completed=done)
        if self._beat is not None and self._clock() >= self._beat[3]:
            started, total, what, _ = self._beat
            now = self._clock()
            elapsed = now - started
            frac = min(max(done / total, 0.0), 1.0) if total > 0 else 0.0
            left = f", about {_minutes(elapsed * (1.0 - frac) / frac)} left" if frac > 0 else ""
            console.print(f"progress: {what} {100.0 * frac:.1f} % after {_minutes(elapsed)}{left}",
                          highlight=False, soft_wrap=True)
            self._beat = (started, total, what, now + (self.heartbeat or 0.0))

    def finish(self) -> None:
        self._beat = None
        if self in _BARS:
            _BARS.remove(self)
        if self._progress is not None:
            self._progress.stop()
            self._progress = None


#: The bars drawing now (:class:`RichProgress`), stopped before an 'interrupted' line.
_BARS: list[RichProgress] = []


def _minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60.0:.1f} min"


def _fmt(value: float, se: float | None = None) -> str:
    """Value with its standard error in the one notation of every table (:func:`stochpend.
    _notation.ve`), e.g. 0.3482(22)."""
    return ve(value, se)


def observable_variables(ds: Any) -> list[str]:
    """The result's variables of user observables and accumulators (``attrs["observables"]``:
    mean_, passed_, var_ and n_ of each name, those present), in order; from the file alone, so
    ``show`` lists them in a process that never registered them."""
    names = str(ds.attrs.get("observables", "") or "")
    out = []
    for name in (n.strip() for n in names.split(",")):
        for prefix in ("mean", "passed", "var", "rate", "diffusion", "n"):
            v = f"{prefix}_{name}"
            if name and v in ds and f"{v}_stderr" in ds and v not in out:
                out.append(v)
    return out


def observables_table(ds: Any, max_rows: int = 12, width: int | None = None) -> Table | None:
    """The user observables' statistics at the summary table's times (value(error)), None
    without any; one table a few columns wide at a time, so that it fits ``width``."""
    variables = observable_variables(ds)
    if not variables:
        return None
    idx = shown_rows(ds, max_rows)
    columns: dict[str, list[str]] = {"t": [f"{float(ds.time.values[i]):.4g}" for i in idx]}
    for v in variables:
        columns[markup(v)] = [_fmt(float(ds[v].values[i]), float(ds[f"{v}_stderr"].values[i])) for i in idx]
    dropped: list[str] = []
    if width is not None:
        def needed() -> int:
            return 1 + sum(3 + max(len(n), *(len(c) for c in cells)) for n, cells in columns.items())

        while needed() > width and len(columns) > 2:
            dropped.append(list(columns)[-1])
            del columns[list(columns)[-1]]
    table = Table(title="user observables")
    for name in columns:
        table.add_column(name, justify="right", no_wrap=True)
    for k in range(len(idx)):
        table.add_row(*(cells[k] for cells in columns.values()))
    caption = ("Values as v(e), e one standard error (jackknife). Per-path accumulators (time averages, "
               "first passages, running sums) have no bias estimate: the coupled pairs do not carry them.")
    if dropped:
        caption += f" Not shown at this width: {', '.join(dropped)} (a wider terminal or a pipe shows them)."
    table.caption = caption
    return table


#: Rows of a first passage's histogram on the terminal (more bins are merged for the display).
_PASSAGE_HIST_ROWS = 20


def passage_tables(ds: Any) -> list[Table]:
    """Two tables per first-passage observable of a run (``fpt_<name>_...``, stochpend.model.passage):
    its quantiles with their 95 % intervals, and its histogram with the paths censored; each
    four columns, within 80. From the file alone (the names from ``attrs["observables"]``, every
    text escaped); none for a sweep, whose variables carry the sets' dimensions."""
    names = [n.strip() for n in str(ds.attrs.get("observables", "") or "").split(",") if n.strip()]
    out: list[Table] = []
    for name in names:
        pre = f"fpt_{name}"
        if f"{pre}_quantile" not in ds or ds[f"{pre}_quantile"].ndim != 1 or f"{pre}_hist" not in ds:
            continue
        p = ds[f"{pre}_probability"].values
        q, lo, hi = (ds[f"{pre}_quantile{s}"].values for s in ("", "_lower", "_upper"))
        n, passed, censored = (int(ds[f"{pre}_{s}"].values) for s in ("paths", "passed", "censored"))
        edges = ds[f"{pre}_bin_edges"].values
        t_end = float(edges[-1])
        table = Table(title=f"τ_{markup(name)}: quantiles")
        for column in ("p", "τ_p", "95% interval", ""):
            table.add_column(column, justify="right" if column else "left", no_wrap=True)
        for k in range(p.size):
            if math.isnan(float(q[k])):
                table.add_row(f"{float(p[k]):.4g}", "censored", "", f"p > {passed}/{n} passed")
                continue
            upper = "> t_end" if math.isnan(float(hi[k])) else f"{float(hi[k]):.4g}"
            table.add_row(f"{float(p[k]):.4g}", f"{float(q[k]):.4g}", f"[{float(lo[k]):.4g}, {upper}]", "")
        table.caption = (f"First-passage time of {markup(name)}: {passed} of {n} finite paths passed by "
                         f"t_end = {t_end:.4g}, {censored} censored (no quantile beyond the fraction passed). "
                         "τ_p: the order statistic of rank ceil(n p); interval: distribution-free "
                         "(binomial). Step error O(√h): no bias estimate.")
        out.append(table)
        counts = [int(c) for c in ds[f"{pre}_hist"].values]
        group = max(1, -(-len(counts) // _PASSAGE_HIST_ROWS))
        hist = Table(title=f"τ_{markup(name)}: histogram")
        for column in ("τ from", "to", "paths", "share"):
            hist.add_column(column, justify="right", no_wrap=True)
        for start in range(0, len(counts), group):
            stop = min(start + group, len(counts))
            c = sum(counts[start:stop])
            hist.add_row(f"{float(edges[start]):.4g}", f"{float(edges[stop]):.4g}", str(c),
                         f"{c / n:.4f}" if n else "nan")
        hist.add_row("> t_end", "", str(censored), f"{censored / n:.4f}" if n else "nan")
        hist.caption = ("Paths by passage time (share of the finite paths); '> t_end': censored."
                        + (f" Bins merged {group} by {group} here; all {len(counts)} are in the file."
                           if group > 1 else ""))
        out.append(hist)
    return out


def shown_rows(ds: Any, max_rows: int = 12) -> list[int]:
    """The output-time indices a table of at most ``max_rows`` rows shows (evenly spread, the
    first and last always)."""
    n = ds.sizes["time"]
    shown = min(max_rows, n)
    return sorted({round(k * (n - 1) / max(shown - 1, 1)) for k in range(shown)})


def _bias_cell(value: float, bias_stderr: float, verdict: int | None) -> str:
    """The bias column: the estimate where it says something (certified small, or significant,
    marked '!'), 'unresolved' where it cannot tell (:func:`stochpend.bias.assess`)."""
    from stochpend.runs import bias as _bias

    if verdict == _bias.INCONCLUSIVE:
        return "unresolved"
    cell = _fmt(value, bias_stderr)
    return cell + " !" if verdict == _bias.SIGNIFICANT else cell


def _scaled_column(ds: Any) -> tuple[str, str, Callable[[float], float]] | None:
    """(header, variable, normalisation of t) of the scaled column the paper predicts a constant
    for: <E>/(Dt/4) -> 1 for the pendulum with white noise (Eq. (9)), <E2>/(Dt/tau^2) -> 1/4 with
    OU noise (Eq. (55)); None for every other model, whose prefactors are not predicted."""
    attrs = ds.attrs
    if attrs.get("potential", "pendulum") != "pendulum" or attrs.get("coupling", "force") != "force":
        return None
    if attrs.get("dynamics_parameters"):  # damping, drives, a second noise: the paper's laws do not apply
        return None
    D = float(attrs.get("D", 1.0))
    if D <= 0:
        return None
    if attrs.get("noise") == "white":
        return "<E>/(Dt/4)", "mean_E", lambda t: D * t / 4.0
    if attrs.get("noise") == "ou":
        tau = float(attrs.get("tau", 1.0))
        return "<E2>/(Dt/tau^2)", "mean_E2", lambda t: D * t / tau**2
    return None


#: Columns a narrow terminal drops first (the last first), with what the caption then says.
_DROP_ORDER = ("non-finite", "F", "scaled", "S", "<E2>")


def rows_hint(out: Any) -> str:
    """How a command without ``--rows`` (simulate, resume, reduced) shows every output time:
    the hint names the command that has the option, as it must be typed."""
    import shlex

    if out is None:
        return "for all, write them with --out FILE, then: stochpend show FILE --rows {n}"
    return f"for all: stochpend show {shlex.quote(str(out))} --rows {{n}}"


def summary_table(ds: Any, max_rows: int = 12, width: int | None = None,
                  more: str = "--rows {n} for all") -> Table:
    """A table of the main statistics of a result at up to ``max_rows`` times, fitted to
    ``width`` columns (a terminal's; None: no limit): columns that do not fit are left out, the
    least needed first, and the caption says which and how many times are shown, and ``more``
    (``{n}``: the number of times) how to see them all (:func:`rows_hint`)."""
    attrs = ds.attrs
    noise = attrs.get("noise", "ou")
    D = float(attrs.get("D", 1.0))
    tau = attrs.get("tau", "none")
    potential = attrs.get("potential", "pendulum")
    model = potential if potential != "power" else f"U = x^{2 * int(attrs.get('power_n', 2))}/{2 * int(attrs.get('power_n', 2))}"
    if potential != "pendulum":
        model += f" ({attrs.get('coupling', 'force')} coupling)"
    # Attributes come from a file: escaped (terminal control characters, Rich markup).
    title = f"stochpend: {markup(model)}, {markup(noise)} noise, D={D:g}" + (f", tau={float(tau):g}" if tau != "none" else "")
    if str(attrs.get("title", "")).startswith("stochpend reduced dynamics"):  # not the pendulum's own run
        title = title.replace("stochpend: ", f"stochpend reduced dynamics ({markup(str(attrs.get('order', '?')))} order): ", 1)
    if attrs.get("omega_noise", "none") != "none":
        title += f", W={float(attrs['omega_noise']):g}"
    if attrs.get("noise_parameters"):  # the noise's own parameters (stochpend.model.parameters)
        title += f", {markup(str(attrs['noise_parameters']))}"
    if attrs.get("potential_parameters"):  # the oscillator's own parameters
        title += f", {markup(str(attrs['potential_parameters']))}"
    if attrs.get("dynamics_parameters"):  # the family's terms that are on (damping, drives, ...)
        title += f", {markup(str(attrs['dynamics_parameters']))}"
    if attrs.get("additive_noise"):  # the additive channel's noise, when the run named one
        title += f", additive {markup(str(attrs['additive_noise']))} noise"
    title += f", omega={float(attrs.get('omega', 0.0)):g}, {int(attrs.get('paths', 0))} paths, seed {markup(attrs.get('seed'))}"
    scaled: Any = _scaled_column(ds)  # (header, variable, norm) or None
    has_bias = "mean_E_bias" in ds
    idx = shown_rows(ds, max_rows)
    verdicts = None
    if has_bias:
        from stochpend.runs import bias as _bias

        verdicts = _bias.assess_dataset(ds)
    columns: dict[str, list[str]] = {"t": [], "<E>": []}
    if has_bias:
        columns["bias <E>"] = []
    columns["<E2>"] = []
    if scaled is not None:
        columns["scaled"] = []
    columns.update({"S": [], "F": [], "non-finite": []})
    for i in idx:
        row = ds.isel(time=i)
        t = float(row.time)
        columns["t"].append(f"{t:.4g}")
        columns["<E>"].append(_fmt(float(row.mean_E), float(row.mean_E_stderr)))
        if has_bias:
            columns["bias <E>"].append(_bias_cell(float(row.mean_E_bias), float(row.mean_E_bias_stderr),
                                                  int(verdicts.verdict["mean_E"][i]) if verdicts else None))
        columns["<E2>"].append(_fmt(float(row.mean_E2), float(row.mean_E2_stderr)))
        if scaled is not None:
            norm = scaled[2](t) if t > 0 else float("nan")
            columns["scaled"].append(_fmt(float(row[scaled[1]]) / norm, float(row[f"{scaled[1]}_stderr"]) / norm))
        columns["S"].append(_fmt(float(row.skewness), float(row.skewness_stderr)))
        columns["F"].append(_fmt(float(row.flatness), float(row.flatness_stderr)))
        columns["non-finite"].append(str(int(row.nonfinite_paths)))
    headers = {name: (scaled[0] if name == "scaled" else name) for name in columns}
    dropped = []
    if width is not None:
        def needed() -> int:  # Rich's box: one border and two spaces of padding a column
            return 1 + sum(3 + max(len(headers[n]), *(len(c) for c in cells)) for n, cells in columns.items())

        for name in _DROP_ORDER:
            if needed() <= width:
                break
            if name == "non-finite" and any(c != "0" for c in columns[name]):
                continue  # paths were lost: that stays in view
            if name in columns:
                del columns[name]
                dropped.append("non-finite (none)" if name == "non-finite" else headers[name])
    table = Table(title=title)
    for name in columns:
        table.add_column(headers[name], justify="right", no_wrap=True)
    for k in range(len(idx)):
        table.add_row(*(cells[k] for cells in columns.values()))
    n_times = ds.sizes["time"]
    caption = ""
    if len(idx) < n_times:
        caption += f"{len(idx)} of {n_times} output times shown ({markup(more.format(n=n_times))}). "
    if dropped:
        caption += (f"Not shown at this width: {', '.join(dropped)} (a wider terminal or a pipe "
                    "shows them). ")
    caption += (
        f"Values as v(e): e is one standard error in the last digits (jackknife over {int(attrs.get('n_batches', 0))} batches). "
        f"Wall time {float(attrs.get('wall_time_s', float('nan'))):.3g} s, "
        f"{float(attrs.get('path_steps', 0)):.3g} path-steps."
    )
    if has_bias:
        caption += (f" bias: estimated discretisation bias (value minus zero-step limit) from "
                    f"{int(attrs.get('bias_paths', 0))} coupled pairs; '!' significant, "
                    "'unresolved' where the estimate cannot tell")
        if attrs.get("accuracy") == "auto":
            caption += (f"; accuracy auto: h_max={float(attrs.get('h_max', 0)):g}, "
                        f"c={float(attrs.get('step_c', 0)):g} (level {int(attrs.get('accuracy_level', 0))})")
        caption += "."
        from stochpend.runs import bias as _bias

        line = _bias.summary_line(ds, shown=idx)
        if line:
            caption += " " + line[0].upper() + line[1:]
    table.caption = caption
    return table


def bias_warnings(ds: Any, shown: list[int] | None = None) -> list[str]:
    """The bias estimate's warnings (:func:`stochpend.bias.warnings_for`: significant biases
    only, family-wise controlled), naming times among the rows ``shown``, and what ``auto``
    could not do."""
    from stochpend.runs import bias as _bias

    lines = _bias.warnings_for(ds, _fmt, shown)
    if ds.attrs.get("accuracy") == "auto" and not int(ds.attrs.get("accuracy_reached", 1)):
        lines.append(f"accuracy auto stopped at level {int(ds.attrs.get('accuracy_level', 0))} "
                     "(64x the steps): the bias may exceed the target; see the bias columns")
    return lines


def bias_notes(ds: Any) -> list[str]:
    """What ``accuracy="auto"`` did not certify: the times from the pilot's horizon on."""
    from stochpend.runs import bias as _bias

    horizon = float(ds.attrs.get("accuracy_horizon", math.nan))
    if ds.attrs.get("accuracy") != "auto" or not math.isfinite(horizon):
        return []
    verdicts = _bias.assess_dataset(ds)
    need = _bias.independent_paths_to_certify(int(ds.attrs.get("paths", 0)), verdicts.width) if verdicts else 0
    return [f"accuracy auto chose the step from the times before t = {horizon:.4g}: from there on "
            "the coupled pairs have decorrelated and the bias is not certified; two independent "
            f"ensembles of {need:.2g} paths each, at the step and at half of it, would be needed"]


def joint_lines(ds: Any) -> list[str]:
    """A few lines (at most 80 columns) on the joint (x, Omega) histogram of a result that has
    one (``joint_hist``), at its last output time: the bin grid, the paths counted against
    the finite paths (they must agree), and the Omega marginal's <Omega^2> from the bin
    centres beside ``mean_Omega2``. Only numbers from the file: nothing to escape."""
    import numpy as np

    if "joint_hist" not in ds or "x_bin_edges" not in ds or ds["joint_hist"].ndim != 3:
        return []
    hist = np.asarray(ds["joint_hist"].values[-1], dtype=np.int64)
    x_edges = np.asarray(ds["x_bin_edges"].values[-1], dtype=np.float64)
    O_edges = np.asarray(ds["Omega_bin_edges"].values[-1], dtype=np.float64)
    t = float(ds.time.values[-1])
    inside = int(hist.sum())
    outside = int(ds["joint_hist_outside"].values[-1])
    finite = int(ds["n_finite_paths"].values[-1])
    agree = "equal" if inside + outside == finite else "DIFFER"
    lines = [
        f"joint (x, Omega) histogram: {hist.shape[0]} x {hist.shape[1]} bins at each output time",
        f"  at t = {t:.4g}: x in [{x_edges[0]:.4g}, {x_edges[-1]:.4g}), "
        f"Omega in [{O_edges[0]:.4g}, {O_edges[-1]:.4g})",
        f"  {inside} paths in the bins + {outside} outside = {inside + outside}; "
        f"finite paths {finite}: {agree}",
    ]
    if inside > 0 and "mean_Omega2" in ds:
        centres = 0.5 * (O_edges[1:] + O_edges[:-1])
        m2 = float((hist.sum(axis=0) * centres**2).sum() / inside)
        mean = _fmt(float(ds["mean_Omega2"].values[-1]), float(ds["mean_Omega2_stderr"].values[-1]))
        lines.append(f"  Omega marginal: <Omega^2> {m2:.4g} from bin centres; mean_Omega2 {mean}")
    return [line[:80] for line in lines]
