"""A new user's first hour, scripted (issue 20): the README's commands from a fresh directory,
in order, each in a real 80x24 terminal (a pty) and in a pipe, under the README doc test's
policies (tests/docs/test_readme.py: run scaled, or parsed where a line needs a GPU, a cluster
or the whole paper). Then the things a newcomer tries next: `--version`, `--help`, `show` of
every file written, `show --format csv`, a flipped byte, a bad option.

What must hold everywhere: exit 0 (or the one-line refusal with exit 2 / 1), no traceback, no
line wider than the terminal, no '…' where a value should be; in a pipe, results on stdout and
notes and progress on stderr, with no escape codes in either.
"""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from tests.docs.test_readme import PARSE_ONLY, _blocks, _scaled_args
from tests.unit.test_terminal_output import _in_pty

ROOT = Path(__file__).resolve().parents[2]
SRC = str(ROOT / "src")
ESCAPE = re.compile(r"\x1b\[")


def _cmd(args: list[str]) -> list[str]:
    return [sys.executable, "-m", "stochpend", *args]


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    env["PYTHONPATH"] = SRC
    return env


def _pty(args: list[str], cwd: Path) -> str:
    """The 80x24 terminal's output, escape codes removed, carriage returns kept as line breaks
    (a progress bar redraws its line: each drawing must fit)."""
    return _in_pty(_cmd(args), 80, 24, cwd=cwd, env=_env(), returns="\n", wait_s=300)


def _pipe(args: list[str], cwd: Path, code: int = 0) -> subprocess.CompletedProcess:
    proc = subprocess.run(_cmd(args), capture_output=True, text=True, cwd=cwd, env=_env(), timeout=600)
    assert proc.returncode == code, (args, proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr, (args, proc.stderr)
    assert not ESCAPE.search(proc.stdout) and not ESCAPE.search(proc.stderr), args
    return proc


def _check_screen(args: list[str], screen: str) -> None:
    assert "Traceback" not in screen, (args, screen)
    if "--format" in args:  # CSV/JSON are data for programs, one record per line, not a table
        return
    for line in screen.splitlines():
        assert len(line) <= 80, (args, line)
    assert "…" not in screen, (args, screen)


def _readme_commands() -> list[list[str]]:
    lines = []
    for raw in _blocks()[2][1].splitlines():
        line = raw.split("  #")[0].strip()
        if line and not any(p in line for p in PARSE_ONLY):
            lines.append(shlex.split(line.replace("[", " ").replace("]", " ").replace("|", " "))[1:])
    return lines


#: Commands whose results belong on stdout (a pipe to a file must not be empty).
RESULTS_ON_STDOUT = ("show", "theory", "scaling", "info", "list")


@pytest.mark.slow  # about 4 minutes on 2 cores: every README command twice
def test_the_readme_walkthrough_in_a_terminal_and_in_a_pipe(tmp_path):
    (tmp_path / "sweep.toml").write_text('[base]\nnoise = "ou"\npaths = 100\nt_max = 2.0\n'
                                         'n_times = 3\n[grid]\nD = [0.5, 1.0]\n')
    (tmp_path / "run.toml").write_text('noise = "ou"\nD = 1.0\ntau = 1.0\nt_max = 20.0\nn_times = 4\n')
    for words in _readme_commands():
        args = _scaled_args(words)
        if args[0] in ("simulate", "plot", "bfpe", "reduced", "sweep") and ("--out" in args or args[0] == "plot"):
            args.append("--overwrite")  # the walk-through writes run.nc, run.png, ... more than once
        screen = _pty(args, tmp_path)
        _check_screen(args, screen)
        proc = _pipe(args, tmp_path)
        if args[0] in RESULTS_ON_STDOUT or (args[0] == "simulate" and "--quiet" not in args):
            assert proc.stdout.strip(), (args, proc.stderr)
    # What a newcomer tries next.
    assert _pipe(["--version"], tmp_path).stdout.startswith("stochpend ")
    help_screen = _pty(["--help"], tmp_path)
    _check_screen(["--help"], help_screen)
    for name in ("run.nc", "white.nc", "big.nc", "bfpe.nc", "sweep.nc"):
        if (tmp_path / name).exists():
            _check_screen(["show", name], _pty(["show", name], tmp_path))
            assert _pipe(["show", name], tmp_path).stdout.strip()
    csv = _pipe(["show", "run.nc", "--format", "csv"], tmp_path).stdout.splitlines()
    assert csv[0].startswith("time,mean_E,mean_E_stderr")
    damaged = bytearray((tmp_path / "run.nc").read_bytes())
    import h5py

    with h5py.File(tmp_path / "run.nc", "r") as f:
        offset = f["mean_E"].id.get_offset()
    damaged[offset + 3] ^= 0x20
    (tmp_path / "damaged.nc").write_bytes(bytes(damaged))
    proc = _pipe(["show", "damaged.nc"], tmp_path, code=1)
    assert proc.stdout == "" and len(proc.stderr.strip().splitlines()) == 1
    proc = _pipe(["simulate", "--h-max", "0"], tmp_path, code=2)
    assert proc.stderr.strip().startswith("error: --h-max 0.0 is not accepted") and len(proc.stderr.splitlines()) == 1
