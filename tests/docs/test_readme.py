"""Every code block of README.md runs in the suite, under a stated policy per block and line.

Policies:

* ``setup`` -- the ``make`` block: CI itself runs ``make test`` from a fresh clone (.ci/run), and
  ``make demo`` runs the demo; not repeated here.
* ``python, scaled`` -- the Python block runs as written with the ensemble scaled down
  (paths 10_000 -> 400, t_max 1000 -> 20), in a temporary directory.
* command lines: ``run, scaled`` -- run as written with ``--paths`` at most 400 and times cut to
  t <= 20 (the output files of one line feed the next: ``show run.nc``, ``plot run.nc``);
  ``parse`` -- lines with placeholders (``DIR``, ``tcp://HOST``), a GPU, 10^8 paths, the whole
  paper or a crash to resume from: the command and every option the line names must exist
  (``stochpend CMD --help`` lists them), nothing runs.

A line the policies do not cover fails the test, so a new README line needs a policy.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest
from typer.testing import CliRunner

README = Path(__file__).resolve().parents[2] / "README.md"

PARSE_ONLY = ("--backend cuda", "--paths 1e8", "reproduce all", "tcp://", "resume big.ckpt",
              "--precision float32", "--install-completion")


def _blocks() -> list[tuple[str, str]]:
    text = README.read_text(encoding="utf-8")
    return re.findall(r"^```(\w*)\n(.*?)^```", text, flags=re.S | re.M)


def _scaled_python(code: str) -> str:
    return code.replace("paths=10_000", "paths=400").replace("t_max=1000.0", "t_max=20.0")


def _scaled_args(args: list[str]) -> list[str]:
    out = list(args)
    for i, a in enumerate(out[:-1]):
        if a == "--paths":
            out[i + 1] = str(min(400, int(float(out[i + 1]))))
        elif a == "--t-max":
            out[i + 1] = str(min(20.0, float(out[i + 1])))
        elif a == "--times":
            out[i + 1] = ",".join(t for t in out[i + 1].split(",") if float(t) <= 20) or "1,2,5"
        elif a in ("--t", "--time") and out[0] == "theory":
            pass  # one evaluation time of closed forms: cheap as written
    return out


def test_readme_has_the_blocks_these_policies_cover():
    kinds = [lang for lang, _ in _blocks()]
    assert kinds == ["", "python", ""], kinds


def test_readme_python_block_runs(tmp_path, monkeypatch):
    (_, _), (lang, code), _ = _blocks()
    assert lang == "python"
    monkeypatch.chdir(tmp_path)
    exec(compile(_scaled_python(code), "README.md", "exec"), {})
    assert (tmp_path / "run.nc").is_file()


@pytest.mark.slow  # 100 s on 2 cores: every README command, scaled down
def test_readme_command_lines_run_or_parse(tmp_path, monkeypatch):
    from stochpend.cli import app

    monkeypatch.chdir(tmp_path)
    (tmp_path / "sweep.toml").write_text('[base]\nnoise = "ou"\npaths = 100\nt_max = 2.0\n'
                                         'n_times = 3\n[grid]\nD = [0.5, 1.0]\n')
    (tmp_path / "run.toml").write_text('noise = "ou"\nD = 1.0\ntau = 1.0\nt_max = 20.0\nn_times = 4\n')
    block = _blocks()[2][1]
    runner = CliRunner()
    ran = parsed = 0
    for raw in block.splitlines():
        line = raw.split("  #")[0].strip()
        if not line:
            continue
        assert line.startswith("stochpend"), line
        words = shlex.split(line.replace("[", " ").replace("]", " ").replace("|", " "))[1:]
        if any(p in line for p in PARSE_ONLY):
            command = words[0] if not words[0].startswith("-") else None
            helptext = runner.invoke(app, ([command] if command else []) + ["--help"]).output
            helptext = " ".join(helptext.split())
            for option in (w.split("=")[0] for w in words if w.startswith("--")):
                assert option in helptext, (line, option)
            parsed += 1
            continue
        args = _scaled_args(words)
        if args and args[0] == "simulate" and "--out" in args:
            args.append("--overwrite")
        result = runner.invoke(app, args)
        assert result.exit_code == 0, (line, result.output)
        assert "Traceback" not in result.output, line
        ran += 1
    assert ran >= 12 and parsed >= 4, (ran, parsed)
    for name in ("run.nc", "white.nc", "run.png", "big.nc", "bfpe.nc"):
        assert (tmp_path / name).is_file(), name
