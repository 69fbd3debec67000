"""The command line's help and messages (issue 20, item 6): help text that Rich does not eat,
every option's default, plain words citing the paper's equation numbers, errors that name the
command line's options, one name and one range per parameter, shell completion, and
``simulate --config``."""

from __future__ import annotations

import re
import subprocess
import sys
from typing import Any

import numpy as np
import pytest
import typer.core
import typer.main
from typer._click import Context
from typer.testing import CliRunner

from stochpend import cli
from stochpend.cli import _common as _cli_common
from stochpend.paper import EQUATIONS

WIDE = {"COLUMNS": "2000", "TERMINAL_WIDTH": "2000"}


def _group() -> Any:
    return typer.main.get_command(cli.app)


def _commands() -> list[tuple[str, Any, Context]]:
    """(name, command, context) of every subcommand."""
    group = _group()
    parent = Context(group, info_name="stochpend")
    return [(name, cmd, Context(cmd, info_name=name, parent=parent)) for name, cmd in group.commands.items()]


def _help(*args: str) -> str:
    result = CliRunner().invoke(cli.app, [*args, "--help"], env=WIDE)
    assert result.exit_code == 0, result.output
    return result.output


def _literal(text: str) -> str:
    """Help text as written (the command class escapes Rich markup once: ``\\[base]``)."""
    return re.sub(r"\\(\[)", r"\1", text)


def _texts() -> list[tuple[str, str]]:
    """(where, help text as written) of every command and every parameter."""
    out = []
    for name, cmd, ctx in _commands():
        out.append((name, _literal(cmd.help or "")))
        for p in cmd.get_params(ctx):
            if getattr(p, "help", None):
                out.append((f"{name} {p.opts[0]}", _literal(p.help)))
    return out


NAMES = [name for name, _, _ in _commands()]


# -- 1. no markup loss -------------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_bracketed_help_text_is_shown(name: str) -> None:
    shown = " ".join(_help(name).split())
    _, cmd, ctx = next(c for c in _commands() if c[0] == name)
    texts = [_literal(p.help) for p in cmd.get_params(ctx) if getattr(p, "help", None)]
    texts.append(_literal(cmd.help or ""))
    for text in texts:
        for segment in re.findall(r"\[[^\]]*\]+", text):
            assert segment in shown, (name, segment)


def test_sweep_help_names_the_tables() -> None:
    assert "a TOML file: [base], then [grid] or [[case]]" in " ".join(_help("sweep").split())


# -- 2. defaults and flags --------------------------------------------------------------------
@pytest.mark.parametrize("name", NAMES)
def test_every_option_shows_its_default(name: str) -> None:
    lines = _help(name).splitlines()
    _, cmd, ctx = next(c for c in _commands() if c[0] == name)
    for p in cmd.get_params(ctx):
        if not isinstance(p, typer.core.TyperOption) or p.is_flag or p.hidden:
            continue
        row = [ln for ln in lines if re.match(rf"^│ {re.escape(p.opts[0])}\s", ln)]
        assert len(row) == 1, (name, p.opts, lines)
        assert "[default: " in row[0] and "[default: (" not in row[0], (name, row[0])


@pytest.mark.parametrize("name", NAMES)
def test_flags_take_no_value(name: str) -> None:
    text = _help(name)
    assert "<bool>" not in text
    assert "--no-" not in text


@pytest.mark.parametrize("name", NAMES)
def test_no_python_type_shows_as_a_metavar(name: str) -> None:
    # Typer names a list option's value <list[str]>: every option says what it takes in words.
    assert not re.search(r"<(list|dict|tuple)\[", _help(name)), name


def test_root_help_has_no_bool_metavar() -> None:
    assert "<bool>" not in _help()


def test_help_defaults_match_the_api() -> None:
    from stochpend.model import settings

    assert (cli.DEFAULT_H_MAX, cli.DEFAULT_STEP_C, cli.DEFAULT_HIST_BINS) == (
        settings.DEFAULT_H_MAX, settings.DEFAULT_STEP_C, settings.DEFAULT_HIST_BINS)
    assert (cli.MAX_OMEGA, cli.MAX_POWER_N) == (settings.MAX_OMEGA, settings.MAX_POWER_N)
    simulate = _help("simulate")
    for option, default in (("--h-max", "0.05"), ("--step-c", "0.1"), ("--hist-bins", "100")):
        row = next(ln for ln in simulate.splitlines() if re.match(rf"^│ {option}\s", ln))
        assert f"[default: {default}]" in row, row


def test_help_does_not_import_numba() -> None:
    code = ("import sys; from typer.testing import CliRunner; from stochpend import cli; "
            "CliRunner().invoke(cli.app, ['simulate', '--help']); print('numba' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# -- 3. plain words, the paper's equation numbers ----------------------------------------------
#: Labels that are also words of the command line: the 'bfpe' command, 'OU' noise.
_NOT_LABELS = {"OU", "bfpe"}
_LABEL = re.compile(r"(?<![\w:.-])(" + "|".join(
    re.escape(k) for k in sorted(set(EQUATIONS) - _NOT_LABELS, key=len, reverse=True)) + r")(?![\w:])")


def test_help_cites_equation_numbers_not_source_labels() -> None:
    for where, text in _texts():
        assert not _LABEL.search(text), (where, _LABEL.search(text).group(1), text)
    cited = {m for _, text in _texts() for m in re.findall(r"\beqs?\. ([A0-9, ]+)", text)}
    assert cited, "no help text cites an equation"
    numbers = set(EQUATIONS.values())
    for group in cited:
        for n in group.split(","):
            assert n.strip() in numbers, group


def test_simulate_noise_help_cites_eq_18_and_4() -> None:
    row = " ".join(_help("simulate").split())
    assert "'ou' (Ornstein-Uhlenbeck, eq. 18)" in row and "'white' (Gaussian white noise, eq. 4)" in row


# -- 4. errors name the command line's options --------------------------------------------------
def _error_line(args: list[str]) -> str:
    result = CliRunner().invoke(cli.app, args)
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert "Traceback" not in result.output
    return lines[0]


@pytest.mark.parametrize("args,expected", [
    (["simulate", "--h-max", "0"], "error: --h-max 0.0 is not accepted: a finite number > 0"),
    (["simulate", "--backend", "cpux"], "error: --backend 'cpux' is not accepted: one of cpu"),
    (["simulate", "--n", "0"], "error: --n 0 is not accepted: an integer in [1, 1000]"),
    (["simulate", "--tau", "-1"], "error: --tau -1.0 is not accepted: a finite number > 0"),
    (["simulate", "--paths", "1e15.5"], "error: --paths '1e15.5' is not accepted: an integer"),
    (["simulate", "--omega-noise", "2"], "error: --omega-noise 2.0 is not accepted: --omega-noise applies to --noise 'harmonic'"),
    (["scaling", "--n", "0"], "error: --n 0 is not accepted: an integer in [2, 1000]"),
    (["theory", "--time", "-5"], "error: --time -5.0 is not accepted: a finite number >= 0"),
])
def test_errors_name_cli_options(args: list[str], expected: str) -> None:
    line = _error_line(args)
    assert line.startswith(expected), line
    for python_name in ("h_max", "power_n", "omega_noise=", "backend=", "t="):
        assert python_name not in line, line


def test_the_python_api_keeps_its_argument_names() -> None:
    import stochpend

    with pytest.raises(ValueError, match=r"^h_max=0\.0 is not accepted"):
        stochpend.simulate(h_max=0.0)


def test_cli_message_leaves_file_keys_and_arguments_alone() -> None:
    names = {"h_max": "--h-max", "noise": "--noise"}
    assert _cli_common.cli_message("run.toml: h_max=0.0 is not accepted: x", names) == "run.toml: h_max=0.0 is not accepted: x"
    assert _cli_common.cli_message("path='x' is not accepted: y", names) == "path='x' is not accepted: y"
    assert _cli_common.cli_message("tau=-1.0 is not accepted: use noise='white'", {"tau": "--tau", "noise": "--noise"}) \
        == "--tau -1.0 is not accepted: use --noise 'white'"


# -- 5. one name and one range per parameter ----------------------------------------------------
def test_theory_takes_time_and_keeps_t_as_hidden_alias() -> None:
    """--t is the former name; --t-max (simulate's last time) was refused (walk-through H3)."""
    for option in ("--time", "--t", "--t-max"):
        result = CliRunner().invoke(cli.app, ["theory", "--noise", "white", "--D", "2", option, "3"], env=WIDE)
        assert result.exit_code == 0, result.output
        assert "Predictions at t = 3" in result.output
    text = _help("theory")
    assert re.search(r"^│ --time\s", text, re.M) and not re.search(r"^│ --t(-max)?\s", text, re.M)


@pytest.mark.parametrize("command,low", [("simulate", 1), ("scaling", 2)])
def test_n_states_the_range_the_command_accepts(command: str, low: int) -> None:
    shown = " ".join(_help(command).split())
    assert f"an integer in [{low}, 1000]" in shown
    assert f"[{low}, 1000]" in _error_line([command, "--n", str(low - 1)])
    assert f"[{low}, 1000]" in _error_line([command, "--n", "1001"])


# -- 6. an empty name is an empty name -----------------------------------------------------------
@pytest.mark.parametrize("args,named", [
    (["simulate", "--out", ""], "--out ''"), (["show", ""], "path=''"), (["sweep", ""], "spec=''"),
    (["simulate", "--checkpoint", ""], "--checkpoint ''"), (["bfpe", "--out", ""], "--out ''"),
    (["reproduce", "--out", ""], "--out ''"), (["plot", ""], "path=''"),
])
def test_empty_file_name_is_refused_as_empty(args: list[str], named: str) -> None:
    line = _error_line(args)
    assert line == f"error: {named} is not accepted: the name is empty; give a file name", line
    assert "'.'" not in line


# -- shell completion ------------------------------------------------------------------------
def test_completion_script_and_completions():
    """`stochpend --show-completion bash` prints a script; the script's protocol completes
    commands and options."""
    import os

    # --show-completion detects the shell from the parent process (shellingham): run it from bash
    # (a second command keeps bash from exec'ing Python in its place).
    code = "from stochpend.cli import app; app(prog_name='stochpend')"
    proc = subprocess.run(["bash", "-c", f"'{sys.executable}' -c \"{code}\" --show-completion; exit $?"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0 and "_stochpend_completion" in proc.stdout, (proc.stdout, proc.stderr)
    env = {**os.environ, "COMP_WORDS": "stochpend simulate --noi", "COMP_CWORD": "2",
           "_STOCHPEND_COMPLETE": "complete_bash"}
    code = "import sys; sys.argv[0] = 'stochpend'; from stochpend.cli import app; app(prog_name='stochpend')"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert proc.stdout.split() == ["--noise"], (proc.stdout, proc.stderr)


# -- simulate --config run.toml ----------------------------------------------------------------
def _config(tmp_path, text: str):
    path = tmp_path / "run.toml"
    path.write_text(text, encoding="utf-8")
    return path


def test_config_file_sets_options_and_the_command_line_overrides(tmp_path):
    import stochpend
    from stochpend import io

    cfg = _config(tmp_path, 'noise = "white"\nD = 0.5\npaths = 120\nt-max = 5.0\nn_times = 3\nseed = 7\n')
    r = CliRunner().invoke(cli.app, ["simulate", "--config", str(cfg), "--quiet", "--out", str(tmp_path / "a.nc")])
    assert r.exit_code == 0, r.output
    a = io.open_results(tmp_path / "a.nc")
    direct = stochpend.simulate(noise="white", D=0.5, paths=120, t_max=5.0, n_times=3, seed=7)
    assert np.array_equal(a["mean_E"].values, direct["mean_E"].values)
    assert a.attrs["config_text"] == cfg.read_text() and a.attrs["config_file"] == str(cfg)
    r = CliRunner().invoke(cli.app, ["simulate", "--config", str(cfg), "--paths", "64", "--quiet",
                                     "--out", str(tmp_path / "b.nc")])
    assert r.exit_code == 0, r.output
    b = io.open_results(tmp_path / "b.nc")
    assert int(b.attrs["paths"]) == 64 and float(b.attrs["D"]) == 0.5


@pytest.mark.parametrize("text,needle", [
    ("overwrite = true\n", "run.toml: overwrite is not accepted in a configuration file: only the command line"),
    ('out = "/home/someone/precious.nc"\n', "run.toml: out is not accepted in a configuration file"),
    ('checkpoint = "x.ckpt"\n', "run.toml: checkpoint is not accepted in a configuration file"),
    ("tmax = 3\n", "run.toml: tmax is not accepted: unknown key; accepted: noise, D, tau"),
    ("D = -1\n", "run.toml: D=-1.0 is not accepted"),
    ("paths = [1, 2]\n", "run.toml: paths=[1, 2] is not accepted: a number or a string"),
    ("paths = 'abc'\n", "run.toml: paths='abc' is not accepted: an integer"),
    ("D = [\n", "--config='"),
])
def test_config_file_refusals_are_one_line_naming_the_key(tmp_path, text, needle):
    cfg = _config(tmp_path, text)
    r = CliRunner().invoke(cli.app, ["simulate", "--config", str(cfg), "--quiet", "--paths", "10", "--t-max", "1"]
                           if "paths" not in text and "D = -1" not in text else
                           ["simulate", "--config", str(cfg), "--quiet", "--t-max", "1"])
    assert r.exit_code == 2, r.output
    lines = r.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and needle in lines[0], r.output
    assert not list(tmp_path.glob("*.nc"))


def test_a_noise_name_in_capitals_gets_the_lower_case_name() -> None:
    """Walk-through M13: `--noise OU` was refused with no hint that the name is 'ou'."""
    assert _error_line(["simulate", "--noise", "OU"]).endswith("(names are lower case: 'ou')")
    assert "lower case" not in _error_line(["simulate", "--noise", "pink"])
