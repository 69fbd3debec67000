"""Help and docstrings from one source (issue 36, item 7).

``help(stochpend.simulate)`` shows the signature's defaults (stochpend.text._docs writes them into the
docstring at import) and documents every parameter; the command line's declared defaults are
the API's, checked here option by option, so that neither can drift from the code; nothing a
user reads (help, docstring, console tables) shows the paper's internal labels (eq:pdfEcolor),
Python types (<str>, <Path>) or Typer's {path}.
"""

from __future__ import annotations

import inspect
import re
from pathlib import Path
from typing import Any

import pytest
import typer.main
from typer._click import Context
from typer.testing import CliRunner

import stochpend
from stochpend import bias, cli
from stochpend.cli import _common as _cli_common
from stochpend.model import settings
from stochpend.runs import resources
from stochpend.text import _docs
from stochpend.text.equations import _CITED, with_numbers

WIDE = {"COLUMNS": "2000", "TERMINAL_WIDTH": "2000"}
API = inspect.signature(stochpend.simulate).parameters
#: simulate's options whose API keyword has another name
CLI_TO_API = {"n": "power_n"}
#: options of the command line only (no API keyword), or whose API default is None and which
#: the CLI shows in words: what the words must say, from the code's own constants.
SHOWN = {
    "h_max": f"{settings.DEFAULT_H_MAX:g}",
    "step_c": f"{settings.DEFAULT_STEP_C:g}",
    "hist_bins": f"{settings.DEFAULT_HIST_BINS}",
    "n_times": f"{API['n_times'].default}",
    "bias_paths": f"paths/{bias.PAIRS_FRACTION}, at least {bias.MIN_PAIRS}",
    "max_path_steps": f"{resources.DEFAULT_MAX_PATH_STEPS:g}".replace("e+", "e"),
}
CLI_ONLY = {"out", "overwrite", "checkpoint", "checkpoint_every", "quiet", "debug", "param", "plugin", "config_file",
            "ctx", "joint_bins", "joint_x_range", "joint_Omega_max", "observable", "times", "theta0"}


def _simulate_options() -> list[Any]:
    group = typer.main.get_command(cli.app)
    cmd = group.commands["simulate"]
    ctx = Context(cmd, info_name="simulate", parent=Context(group, info_name="stochpend"))
    return [p for p in cmd.get_params(ctx) if p.name != "help"]


# -- the docstring -------------------------------------------------------------------------------
def test_every_parameter_of_simulate_is_documented():
    assert _docs.undocumented(stochpend.simulate) == []


def test_the_docstring_headings_carry_the_signatures_defaults():
    headings = _docs.headings(stochpend.simulate)
    for name, p in API.items():
        if p.default is inspect.Parameter.empty or p.default is None or name == "noise_params":
            continue
        shown = _docs._shown(p.default)
        assert re.search(rf"defaults? (.*\b)?{re.escape(name)}={re.escape(shown)}|default {re.escape(shown)}$",
                         headings[name]), (name, headings[name])


def _entry(fn: Any, name: str) -> str:
    """The docstring's text of one parameter (heading and body), on one line."""
    lines = (fn.__doc__ or "").splitlines()
    i = next(k for k, ln in enumerate(lines) if ln.strip() == _docs.headings(fn)[name])
    indent = len(lines[i]) - len(lines[i].lstrip())
    body = [lines[i]]
    for ln in lines[i + 1:]:
        if ln.strip() and len(ln) - len(ln.lstrip()) <= indent:
            break
        body.append(ln)
    return " ".join(" ".join(body).split())


def test_defaults_described_in_words_are_the_codes():
    assert f"paths/{bias.PAIRS_FRACTION}, at least {bias.MIN_PAIRS}" in _entry(stochpend.simulate, "bias_paths")
    assert f"({resources.DEFAULT_MAX_PATH_STEPS:g})".replace("e+", "e") in _entry(stochpend.simulate, "max_path_steps")
    assert bias.default_bias_paths(48 * 1000) == 1000 and bias.default_bias_paths(100) == bias.MIN_PAIRS


def test_the_docstring_cites_equation_numbers_not_labels():
    doc = stochpend.simulate.__doc__ or ""
    assert with_numbers(doc) == doc
    assert "Eqs. (1), (2)" in doc


def test_documented_writes_defaults_and_numbers():
    def f(a: int = 3, b: str = "x", c: float | None = None, d: float = 0.5) -> None:
        """Do it (Eq. `eqOU`).

        Parameters
        ----------
        a : int
            A.
        b : str, optional
            B.
        c : float, optional
            C, in words.
        d
            D.
        """

    _docs.documented(f)
    assert _docs.headings(f) == {"a": "a : int, default 3", "b": 'b : str, default "x"',
                                 "c": "c : float, optional", "d": "d : default 0.5"}
    assert "(Eq. (18))" in (f.__doc__ or "")
    assert _docs.undocumented(f) == []

    def g(a: int = 1, e: int = 2) -> None:
        """G.

        Parameters
        ----------
        a : int
            A.
        """

    assert _docs.undocumented(g) == ["e"]  # the drift the first test catches


def _public_functions() -> list[Any]:
    """The API entry points whose parameters the command line shares (simulate, sweep, bfpe,
    reduced, theory, scaling) and the growth diagnosis: their help() must not drift either."""
    from stochpend.runs.reduced import simulate_reduced

    return [stochpend.simulate, stochpend.sweep.sweep, stochpend.theory.solve_bfpe, simulate_reduced,
            stochpend.theory.predictions, stochpend.theory.predicted_exponent,
            stochpend.exponents.diagnose_growth]


#: "default 1000", "(default: 0.5)", "default ``40``" in a parameter's text.
# A number's digits, decimals and exponent; a full stop after it ends the sentence ("default 0.95.").
_DEFAULT_IN_WORDS = re.compile(r"\bdefault:? (?:``)?(-?\d[\d_]*(?:\.[\d_]+)?(?:e[+-]?\d+)?)(?:``)?(?!\w|\.\d)")


def _stale_defaults(fn: Any) -> list[str]:
    """Parameters whose entry states a number as its default that is not the signature's."""
    stale = []
    signature = inspect.signature(fn).parameters
    for name in _docs.headings(fn):
        p = signature.get(name)
        if p is None or isinstance(p.default, bool) or not isinstance(p.default, int | float):
            continue
        for m in _DEFAULT_IN_WORDS.finditer(_entry(fn, name)):
            if float(m.group(1).replace("_", "")) != float(p.default):
                stale.append(f"{name}: {m.group(0)!r}, signature {p.default!r}")
    return stale


@pytest.mark.parametrize("fn", _public_functions(), ids=lambda f: f.__qualname__)
def test_public_functions_document_every_parameter_with_the_signatures_defaults(fn):
    assert _docs.undocumented(fn) == [], fn.__qualname__
    headings = _docs.headings(fn)
    for name, p in inspect.signature(fn).parameters.items():
        if p.default is inspect.Parameter.empty or p.default is None or name == "noise_params":
            continue
        shown = re.escape(_docs._shown(p.default))
        assert re.search(rf"defaults? (.*\b)?{re.escape(name)}={shown}|default {shown}$", headings[name]), \
            (fn.__qualname__, name, headings[name])
    assert _stale_defaults(fn) == []
    text = "\n".join(ln for ln in (fn.__doc__ or "").splitlines() if not _docs._HEADING.match(ln))  # names are code
    assert _docs.numbered(text) == text, f"{fn.__qualname__}: an equation label, not its number"


def test_a_stale_default_in_words_is_found():
    def f(n_cells: int = 1000, u_max: float = 5.0) -> None:
        """F.

        Parameters
        ----------
        n_cells : int
            Cells (default 500).
        u_max : float
            Extent (default 5).
        """

    assert _stale_defaults(_docs.documented(f)) == ["n_cells: 'default 500', signature 1000"]


# -- the command line against the API -----------------------------------------------------------
def test_cli_constants_are_the_apis():
    assert (_cli_common.DEFAULT_H_MAX, _cli_common.DEFAULT_STEP_C, _cli_common.DEFAULT_HIST_BINS) == (
        settings.DEFAULT_H_MAX, settings.DEFAULT_STEP_C, settings.DEFAULT_HIST_BINS)
    assert (_cli_common.MAX_OMEGA, _cli_common.MAX_POWER_N) == (settings.MAX_OMEGA, settings.MAX_POWER_N)


@pytest.mark.parametrize("option", _simulate_options(), ids=lambda p: p.name)
def test_simulate_option_defaults_are_the_apis(option):
    name = option.name
    if name in CLI_ONLY:
        return
    api_name = CLI_TO_API.get(name, name)
    assert api_name in API, f"--{name}: no API keyword {api_name!r} (add it to CLI_ONLY if it is the CLI's own)"
    api_default = API[api_name].default
    if option.default is not None:
        assert option.default == api_default, (name, option.default, api_default)
    elif name in SHOWN:
        assert option.show_default == SHOWN[name], (name, option.show_default)
    else:
        assert api_default is None, (name, api_default)


def test_the_check_can_fail(monkeypatch):
    """A CLI default that differs from the API's is caught."""
    option = next(p for p in _simulate_options() if p.name == "paths")
    monkeypatch.setattr(option, "default", 999)
    with pytest.raises(AssertionError):
        test_simulate_option_defaults_are_the_apis(option)


# -- what a user reads ---------------------------------------------------------------------------
_PYTHON_TYPE = re.compile(r"<(?:str|int|float|bool|Path|list\[[^\]]*\]|tuple[^>]*)>")
_BRACED = re.compile(r"\{[a-z_]+\}")


def _clean(where: str, text: str) -> None:
    assert not _PYTHON_TYPE.search(text), (where, _PYTHON_TYPE.findall(text))
    assert not _BRACED.search(text), (where, _BRACED.findall(text))
    labels = [m.group(2) for m in _CITED.finditer(text)
              if not (m.start() > 0 and (text[m.start() - 1].isalnum() or text[m.start() - 1] in "_:"))]
    # "bfpe" is also a command's name (and the word the help uses for it)
    assert [label for label in labels if label != "bfpe"] == [], (where, "equation labels, not their numbers")


@pytest.mark.parametrize("name", [None, *typer.main.get_command(cli.app).commands])
def test_help_shows_no_python_types_labels_or_braces(name):
    result = CliRunner().invoke(cli.app, [*([name] if name else []), "--help"], env=WIDE)
    assert result.exit_code == 0, result.output
    _clean(f"{name} --help", result.output)


@pytest.mark.parametrize("args", [["theory"], ["theory", "--noise", "white"], ["theory", "--family"],
                                  ["scaling"], ["list"]])
def test_console_tables_cite_numbers(args):
    result = CliRunner().invoke(cli.app, args, env=WIDE)
    assert result.exit_code == 0, result.output
    _clean(" ".join(args), result.output)


@pytest.mark.parametrize("order", ["first", "asymptotic"])
def test_reduced_caption_cites_numbers(order):
    result = CliRunner().invoke(cli.app, ["reduced", "--order", order, "--paths", "200", "--t-max", "10",
                                          "--n-times", "2"], env=WIDE)
    assert result.exit_code == 0, result.output
    _clean(f"reduced --order {order}", result.output)


def _api_of(command: str) -> Any:
    if command == "reduced":
        from stochpend.runs.reduced import simulate_reduced

        return simulate_reduced
    if command == "bfpe":
        from stochpend.theory import solve_bfpe

        return solve_bfpe
    if command == "sweep":
        return stochpend.sweep.sweep
    if command == "theory":
        return stochpend.theory.predictions
    from stochpend.paper.reproduce import reproduce

    return reproduce


@pytest.mark.parametrize("command", ["reduced", "bfpe", "reproduce", "sweep", "theory"])
def test_other_commands_defaults_are_their_apis(command):
    """Every option of the command that the API function also takes, with a default on both
    sides, has the same default."""
    group = typer.main.get_command(cli.app)
    cmd = group.commands[command]
    ctx = Context(cmd, info_name=command, parent=Context(group, info_name="stochpend"))
    api = inspect.signature(_api_of(command)).parameters
    compared = []
    for option in cmd.get_params(ctx):
        p = api.get(option.name)
        if p is None or p.default is inspect.Parameter.empty or option.default is None or p.default is None:
            continue
        same = str(option.default) == str(p.default) if isinstance(option.default, Path) else option.default == p.default
        assert same, (command, option.name, option.default, p.default)
        compared.append(option.name)
    assert compared, f"{command}: no option compared"
