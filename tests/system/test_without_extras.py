"""The tool without its optional extras (matplotlib: ``stochpend[plot]``; dask and distributed:
``stochpend[dask]``): what needs no extra works, and what needs one says which in one line.

Each command runs in a subprocess in which those packages cannot be imported (their entries in
``sys.modules`` are None, which makes every import of them fail as if they were not installed),
so the test holds in the full test environment too; ``make test-minimal`` also runs it in a
virtual environment that has never installed them.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

import stochpend

_BLOCK = ("import sys\n"
          "for name in ('matplotlib', 'dask', 'distributed'):\n"
          "    sys.modules[name] = None\n"
          "sys.argv[0] = 'stochpend'\n"
          "from stochpend.cli import main\n"
          "main()\n")
SRC = str(Path(stochpend.__file__).resolve().parents[1])


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([SRC, os.environ.get("PYTHONPATH", "")]), "COLUMNS": "100"}
    return subprocess.run([sys.executable, "-c", _BLOCK, *args], cwd=cwd, env=env, capture_output=True, text=True,
                          timeout=300)


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    where = tmp_path_factory.mktemp("noextra")
    done = _cli("simulate", "--paths", "200", "--t-max", "5", "--n-times", "3", "--seed", "1", "--out", "r.nc",
                "-q", cwd=where)
    assert done.returncode == 0, done.stderr
    return where / "r.nc"


def test_simulate_and_show_need_no_extra(run_file):
    done = _cli("show", str(run_file), "--format", "csv", cwd=run_file.parent)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[0].startswith("time,")


@pytest.mark.parametrize("args, extra", [
    (("plot", "r.nc"), "stochpend[plot]"),
    (("reproduce", "fig1", "--quick", "--out", "rep"), "stochpend[plot]"),
])
def test_a_command_that_needs_an_extra_names_it_in_one_line(run_file, args, extra):
    done = _cli(*args, cwd=run_file.parent)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and extra in lines[0], done.stderr
    assert not (run_file.parent / "r.png").exists()


def test_a_sweep_runs_in_process_and_a_dask_scheduler_names_the_extra(run_file):
    toml = run_file.parent / "s.toml"
    toml.write_text('[base]\nnoise = "ou"\nD = 1\ntau = 1\npaths = 100\nt_max = 2\nn_times = 2\n'
                    '[grid]\nomega = [0, 1]\n')
    done = _cli("sweep", str(toml), "--out", "s.nc", "-q", cwd=run_file.parent)
    assert done.returncode == 0, done.stderr
    done = _cli("sweep", str(toml), "--out", "s2.nc", "--scheduler", "local", cwd=run_file.parent)
    assert done.returncode == 2 and "stochpend[dask]" in done.stderr and len(done.stderr.strip().splitlines()) == 1


def test_info_says_which_extra_installs_dask(run_file):
    done = _cli("info", cwd=run_file.parent)
    assert done.returncode == 0, done.stderr
    assert "pip install 'stochpend[dask]'" in done.stdout + done.stderr
