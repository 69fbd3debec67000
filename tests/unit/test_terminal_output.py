"""What a newcomer's terminal and pipes get: results on stdout, everything else on stderr, tables
that fit 80 columns without losing a value, every output time accounted for."""

from __future__ import annotations

import fcntl
import os
import pty
import re
import select
import struct
import subprocess
import sys
import termios
from pathlib import Path

import pytest

import stochpend
from stochpend import io
from tests.conftest import SEED

ANSI = re.compile(r"\x1b\[[0-9;?]*[A-Za-z]")


@pytest.fixture(scope="module")
def run_file(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("term")
    ds = stochpend.simulate(noise="ou", paths=2000, t_max=100.0, n_times=40, seed=SEED)
    return io.to_netcdf(ds, folder / "run.nc")


def _stochpend(*args: str) -> list[str]:
    return [sys.executable, "-m", "stochpend", *args]


def _in_pty(args: list[str], columns: int, rows: int = 24, *, cwd: Path | None = None,
            env: dict[str, str] | None = None, returns: str = "", wait_s: float = 120) -> str:
    """Run ``args`` with stdout and stderr on a pseudo-terminal of the given size; its screen
    output, escape codes removed, each carriage return replaced by ``returns`` (a progress
    bar's successive drawings: "\n" keeps them apart)."""
    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", rows, columns, 0, 0))
    if env is None:
        env = dict(os.environ)
    env = {k: v for k, v in env.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen(args, stdin=slave, stdout=slave, stderr=slave, env=env, cwd=cwd, close_fds=True)
    os.close(slave)
    chunks = []
    while True:
        ready, _, _ = select.select([master], [], [], wait_s)
        if not ready:
            proc.kill()
            raise AssertionError(f"no output for {wait_s:g} s: {args}")
        try:
            data = os.read(master, 65536)
        except OSError:  # the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    proc.wait(timeout=60)
    os.close(master)
    assert proc.returncode == 0, (args, b"".join(chunks).decode(errors="replace"))
    return ANSI.sub("", b"".join(chunks).decode("utf-8", errors="replace")).replace("\r", returns)


def test_show_in_a_pipe_puts_the_table_on_stdout(run_file):
    out = subprocess.run(_stochpend("show", str(run_file)), capture_output=True, text=True, check=True)
    assert "<E>" in out.stdout and "bias <E>" in out.stdout and "non-finite" in out.stdout
    assert "<E>" not in out.stderr and "┃" not in out.stderr
    assert "…" not in out.stdout


def test_show_in_an_80_column_terminal_loses_no_value(run_file):
    screen = _in_pty(_stochpend("show", str(run_file)), 80)
    lines = screen.splitlines()
    assert max(len(line) for line in lines) <= 80, max(lines, key=len)
    assert "…" not in screen
    body = [line for line in lines if line.startswith("│")]
    assert len(body) == 12
    for line in body:  # every value with its error: v(e) cells are whole
        cells = [c.strip() for c in line.strip("│").split("│")]
        assert all(re.fullmatch(r"[-0-9.e]+(\(\d+\)(e-?\d+)?)?|unresolved|[-0-9.e]+\(\d+\) !", c)
                   for c in cells), cells
    text = " ".join(screen.split())
    assert "12 of 40 output times shown (--rows 40 for all)" in text
    assert "Not shown at this width: non-finite (none)" in text


def test_show_at_200_columns_has_every_column(run_file):
    screen = _in_pty(_stochpend("show", str(run_file), "--rows", "40"), 200)
    header = next(line for line in screen.splitlines() if "<E>" in line and "┃" in line)
    for name in ("t", "<E>", "bias <E>", "<E2>", "<E2>/(Dt/tau^2)", "S", "F", "non-finite"):
        assert name in header, name
    assert sum(1 for line in screen.splitlines() if line.startswith("│")) == 40
    assert "output times shown" not in screen


def test_scaled_column_only_where_the_paper_predicts_its_constant():
    from stochpend.cli import summary_table

    def headers(**kw):
        ds = stochpend.simulate(paths=64, t_max=1.0, n_times=2, seed=SEED, bias_paths=0, **kw)
        return [c.header for c in summary_table(ds).columns]

    assert "<E>/(Dt/4)" in headers(noise="white")
    assert "<E2>/(Dt/tau^2)" in headers(noise="ou")
    for kw in (dict(noise="dichotomous"), dict(noise="harmonic"),
               dict(noise="ou", potential="power", coupling="position", theta0=1.0)):
        h = headers(**kw)
        assert "<E>/(Dt/4)" not in h and "<E2>/(Dt/tau^2)" not in h, kw


def test_show_reads_every_kind_of_file_the_tool_writes(tmp_path, run_file):
    """simulate, a checkpointed run, a sweep, a reduced run and a B.F.P.E. solution: each shown
    with its own table on stdout, exit 0, no traceback."""
    from typer.testing import CliRunner

    from stochpend.cli import app

    runner = CliRunner()
    (tmp_path / "sweep.toml").write_text('[base]\nnoise = "ou"\npaths = 100\nt_max = 2.0\n'
                                         'n_times = 3\nseed = 3\n[grid]\nD = [0.5, 1.0]\n')
    made = {
        "sweep": ["sweep", str(tmp_path / "sweep.toml"), "--out", str(tmp_path / "sweep.nc")],
        "bfpe": ["bfpe", "--D", "1", "--tau", "0.1", "--t-max", "10", "--n-cells", "100",
                 "--out", str(tmp_path / "bfpe.nc")],
        "reduced": ["reduced", "--order", "asymptotic", "--paths", "200", "--t-max", "2",
                    "--out", str(tmp_path / "reduced.nc")],
        "ckpt": ["simulate", "--paths", "200", "--t-max", "2", "--checkpoint",
                 str(tmp_path / "run.ckpt"), "--out", str(tmp_path / "ckpt.nc")],
    }
    for name, args in made.items():
        result = runner.invoke(app, args)
        assert result.exit_code == 0, (name, result.output)
    expect = {"sweep.nc": "parameter sets", "bfpe.nc": "B.F.P.E.", "reduced.nc": "<E>",
              "ckpt.nc": "bias <E>", str(run_file): "bias <E>"}
    # `show` in this process, stdout and stderr apart (a process of its own costs ~2 s each;
    # the pipe and terminal tests above run the real process).
    for name, needle in expect.items():
        path = name if name.startswith("/") else str(tmp_path / name)
        out = runner.invoke(app, ["show", path])
        assert out.exit_code == 0, (name, out.stderr, out.exception)
        assert needle in out.stdout and "Traceback" not in out.stderr, (name, out.stdout, out.stderr)
    other = tmp_path / "other.nc"
    import xarray as xr

    xr.Dataset({"x": ("t", [1.0, 2.0])}).to_netcdf(other, engine="h5netcdf")
    out = runner.invoke(app, ["show", str(other)])
    assert out.exit_code == 2 and "not a file stochpend writes" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_list_names_every_piece_on_stdout():
    from stochpend import noises, oscillators

    out = subprocess.run(_stochpend("list"), capture_output=True, text=True, check=True)
    # the built-in pieces (other tests register noises of their own in this process only)
    for name in (*(n.name for n in noises.BUILTIN), *oscillators.BUILTIN, "force", "position"):
        assert f" {name} " in out.stdout, name
    assert "Eq. (18)" in out.stdout and "eqOU" not in out.stdout  # the paper's numbers
    assert out.stderr == ""


def test_growth_is_judged_against_the_models_predicted_law():
    """Issue 20, item 8: the quartic with position coupling and OU noise (predicted t^1) was
    reported as 'exponential growth' while its late slope was 0.3 and climbing; the pendulum
    with white noise (t^1, reached) says nothing; a slope beyond the law is a warning."""
    import stochpend
    from stochpend.cli import growth_lines

    quartic = stochpend.simulate(potential="power", power_n=2, coupling="position", noise="ou", D=1.0, tau=1.0,
                                 omega=1.0, paths=2000, t_max=100.0, n_times=12, seed=1)
    lines = growth_lines(quartic)
    assert [k for k, _ in lines] == ["note"] and "rising towards the predicted t^1" in lines[0][1], lines
    pendulum = stochpend.simulate(noise="white", D=1.0, omega=1.0, paths=500, t_max=100.0, n_times=12, seed=1)
    assert growth_lines(pendulum) == []
    # The same accelerating data read against a slower law (the pendulum's OU t^1/2 is not it,
    # so claim the quartic's attributes say pendulum/ou): beyond t^1/2 + 4 SE -> a warning.
    relabelled = quartic.copy()
    relabelled.attrs.update(potential="pendulum", coupling="force")
    kinds = [k for k, _ in growth_lines(relabelled)]
    # the late slope 0.3 is below 1/2: still a note; a user's model (no law) gets the warning
    assert kinds == ["note"]
    relabelled.attrs.update(potential="my-model")
    assert [k for k, _ in growth_lines(relabelled)] == ["warning"]


def test_the_table_hint_of_simulate_and_reduced_works_as_printed(tmp_path):
    """N5: simulate's table said "(--rows 40 for all)", an option simulate does not have. The
    hint names the command that shows them all, run here as printed."""
    import shlex

    from typer.testing import CliRunner

    from stochpend.cli import app

    out = tmp_path / "r un.nc"
    runner = CliRunner()
    ran = runner.invoke(app, ["simulate", "--paths", "64", "--t-max", "2", "--n-times", "20", "--bias-paths", "0",
                              "--out", str(out)])
    assert ran.exit_code == 0, ran.output
    text = " ".join(ran.output.split())
    hint = re.search(r"12 of 20 output times shown \(for all: (.*? --rows 20)\)", text)
    assert hint is not None, text
    args = shlex.split(hint.group(1))
    assert args[:2] == ["stochpend", "show"] and args[2] == str(out), args
    shown = runner.invoke(app, args[1:])
    assert shown.exit_code == 0, shown.output
    assert sum(1 for line in shown.output.splitlines() if line.startswith("│")) == 20
    bare = runner.invoke(app, ["reduced", "--paths", "64", "--t-max", "2", "--n-times", "20"])
    assert bare.exit_code == 0, bare.output
    assert ("12 of 20 output times shown (for all, write them with --out FILE, then: stochpend show FILE "
            "--rows 20)") in " ".join(bare.output.split())


@pytest.mark.parametrize(("content", "kind"), [
    (b'{"mean_E": 1}', "JSON or other text"), (b"\x89PNG\r\n\x1a\n" + bytes(40), "a PNG image"),
    (b"%PDF-1.7\n", "a PDF document"), (b"t,mean_E\n1,2\n", "text"), (b"", "an empty file"),
    (b"<html><body>report</body></html>", "HTML, SVG or other XML text"), (b"CDF\x01" + bytes(40), "a NetCDF-3 file"),
    (b"\x00\xff\x13\x37" * 8, "a file of another format"),
])
@pytest.mark.parametrize("command", ["show", "plot"])
def test_a_file_of_another_kind_is_named_in_words(tmp_path, command, content, kind):
    """Walk-through C4: `show results.json` (or fig1.png, report.html) answered in HDF5's words,
    '(Unable to synchronously open file (file signature not found))'."""
    from typer.testing import CliRunner

    from stochpend.cli import app

    path = tmp_path / "results.json"
    path.write_bytes(content)
    result = CliRunner().invoke(app, [command, str(path)])
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 2 and len(lines) == 1, result.output
    assert f"it is {kind}, not a results file" in lines[0], lines[0]
    assert "signature" not in lines[0] and "synchronously" not in lines[0]


def test_an_hdf5_file_after_a_user_block_is_read_as_hdf5(tmp_path):
    """HDF5's signature may follow a user block (512, 1024, ... bytes): such a file is not
    called 'another format' (it is refused for what it holds)."""
    import h5py
    from typer.testing import CliRunner

    from stochpend.cli import app

    with h5py.File(tmp_path / "ub.nc", "w", userblock_size=512) as f:
        f["x"] = 1.0
    result = CliRunner().invoke(app, ["show", str(tmp_path / "ub.nc")])
    assert result.exit_code == 2 and "not a file stochpend writes" in result.output, result.output
    assert "another format" not in result.output


def test_info_names_cores_memory_and_the_kernel_cache(tmp_path):
    """Walk-through N13: info had no core count, memory or cache location."""
    env = {**os.environ, "COLUMNS": "300", "NUMBA_CACHE_DIR": str(tmp_path / "kc"),
           "PYTHONPATH": str(Path(stochpend.__file__).resolve().parents[1])}
    done = subprocess.run([sys.executable, "-m", "stochpend", "info"], capture_output=True, text=True, env=env,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    rows = {ln.split("│")[1].strip(): ln.split("│")[2].strip() for ln in done.stdout.splitlines() if ln.count("│") == 3}
    assert rows["cpus usable"] == str(len(os.sched_getaffinity(0)))
    assert re.fullmatch(r"[\d.]+ [KMGT]?i?B in all, [\d.]+ [KMGT]?i?B available", rows["memory"]), rows["memory"]
    assert rows["kernel cache"] == f"{tmp_path / 'kc'} (NUMBA_CACHE_DIR)"
    assert rows["calibration"].startswith(str(tmp_path / "kc"))


@pytest.mark.parametrize("args", [["show", "{run}"], ["show", "{run}", "--format", "csv"], ["theory"], ["scaling"],
                                  ["info"], ["list"]])
def test_results_go_to_stdout_whole_even_with_columns_80(run_file, args):
    """Walk-through B1, E1, M9: `COLUMNS=80 show run1.nc | head` gave the whole table (no value
    cut); `show > f`, `theory | wc`, `scaling`, `info`: results on stdout, at most notes on stderr."""
    env = {**os.environ, "COLUMNS": "80"}
    done = subprocess.run(_stochpend(*(a.format(run=run_file) for a in args)), capture_output=True, text=True,
                          env=env, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip(), done.stderr
    assert all(ln.startswith("note: ") for ln in done.stderr.splitlines() if ln.strip()), done.stderr  # notes only
    assert "…" not in done.stdout and "\x1b[" not in done.stdout
    if args[:2] == ["show", "{run}"] and len(args) == 2:
        assert "bias <E>" in done.stdout and "non-finite" in done.stdout  # no column dropped in a pipe


def test_the_datasets_verdicts_say_what_their_flags_mean(run_file):
    """Walk-through N11: repr(ds) is readable; each verdict variable names its flags."""
    ds = io.open_results(run_file)
    text = repr(ds)
    assert len(text.splitlines()) < 80
    verdicts = [v for v in ds.data_vars if v.endswith("_bias_verdict")]
    assert verdicts
    for name in verdicts:
        assert ds[name].attrs["flag_meanings"].split() == ["certified_small", "significant", "inconclusive"], name
        assert list(ds[name].attrs["flag_values"]) == [0, 1, 2], name


def test_ctrl_c_leaves_the_interrupted_line_last_and_the_prompt_on_its_own_line():
    """Walk-through I1: after Ctrl-C in a terminal the bar was drawn again below 'interrupted'
    and left without a newline, so the shell's prompt was glued to it ('ETA 0:02:03$')."""
    import signal
    import time

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 80, 0, 0))
    env = {k: v for k, v in os.environ.items() if k not in ("COLUMNS", "LINES")}
    proc = subprocess.Popen(_stochpend("simulate", "--paths", "200000", "--t-max", "300", "--n-times", "3",
                                       "--bias-paths", "0", "--seed", "1"),
                            stdin=slave, stdout=slave, stderr=slave, env=env, close_fds=True)
    os.close(slave)
    out, sent, start = b"", False, time.monotonic()
    try:
        while time.monotonic() - start < 300:
            ready, _, _ = select.select([master], [], [], 0.5)
            if ready:
                try:
                    data = os.read(master, 65536)
                except OSError:
                    break
                if not data:
                    break
                out += data
            if not sent and b"ETA" in out:  # the bar is drawn: interrupt as a user's Ctrl-C does
                proc.send_signal(signal.SIGINT)
                sent = True
        proc.wait(timeout=60)
    finally:  # a run that outlives the test would end another test (its Popen's ResourceWarning)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        os.close(master)
    assert sent and proc.returncode == 130, out[-2000:]
    after = out[out.rindex(b"interrupted"):]
    assert b"ETA" not in after and b"simulating" not in after, after
    assert after.endswith(b"\n"), after


def test_a_harmonic_noise_run_reads_in_an_80_column_terminal():
    """Walk-through R14: `simulate --noise harmonic --tau 1 --omega-noise 1.5` in 80x24: every
    line fits, no value cut, what is left out is said."""
    screen = _in_pty(_stochpend("simulate", "--noise", "harmonic", "--tau", "1", "--omega-noise", "1.5",
                                "--paths", "400", "--t-max", "20", "--n-times", "12", "--seed", "2"), 80, returns="\n",
                    wait_s=300)
    lines = screen.splitlines()
    assert max(len(line) for line in lines) <= 80, max(lines, key=len)
    assert "…" not in screen and "Traceback" not in screen
    assert len([line for line in lines if line.startswith("│")]) == 12
    assert "harmonic noise" in " ".join(screen.split())


@pytest.mark.slow  # the default run: 10 000 paths to t = 1000 (about 20 s on 2 cores)
def test_simulate_with_no_options_runs_the_default_and_prints_its_table():
    """Walk-through M24: `stochpend simulate` alone is a sensible run."""
    done = subprocess.run(_stochpend("simulate"), capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr
    assert "<E>" in done.stdout and "stochpend: pendulum, ou noise, D=1" in " ".join(done.stdout.split())
