"""Hostile inputs and real faults, from the case list behind the hostile-files issue
(``shared/reports/hostile-cases.md``; case ids in each docstring).

Real processes, real signals and, where this machine lets us mount one, a real small tmpfs
that fills *during* the write (not a free-space check beforehand). Every run is tiny.
"""

from __future__ import annotations

import hashlib
import json
import os
import select
import shutil
import signal
import stat
import struct
import subprocess
import sys
import time
from pathlib import Path
from unittest import mock

import pytest
from typer.testing import CliRunner

from stochpend import cli, io
from stochpend.model.settings import SimulationConfig
from stochpend.runs import checkpoint as ck

pytestmark = pytest.mark.system

SRC = Path(__file__).resolve().parents[2] / "src"
TINY = ["--paths", "200", "--t-max", "2", "--n-times", "2", "--seed", "3"]
#: A run of a few seconds on one thread, long enough to be signalled mid-run.
LONG = ["--paths", "40000", "--t-max", "400", "--n-times", "3", "--seed", "7", "--threads", "1"]


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    env["PYTHONPATH"] = os.pathsep.join([str(SRC), *filter(None, [env.get("PYTHONPATH")])])
    return env


def _cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "stochpend", *args]


def _run(*args: str, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(_cmd(*args), capture_output=True, text=True, cwd=cwd, env=_env(), timeout=timeout)


def _one_line(text: str) -> str:
    # The note of a first use's compilation comes before any error when the kernel is not in the
    # cache yet: whether it is depends on which tests ran before on this xdist worker, and the
    # note is not part of the error. Nor is the start's "estimate:" line, which a cold start
    # prints when this machine's compile calibration (stochpend.numerics._calibration) expects over 10 s.
    lines = [ln for ln in text.splitlines()
             if ln.strip() and not ln.startswith(("compiling kernels for ", "estimate: "))]
    assert len(lines) == 1, text
    assert "Traceback" not in text
    return lines[0]


# -- a real full disk ------------------------------------------------------------------------
def _mount_prefix() -> list[str] | None:
    """A command prefix that gives a private mount namespace where ``mount -t tmpfs`` works:
    as root directly, otherwise through an unprivileged user namespace; None if neither."""
    if shutil.which("unshare") is None:
        return None
    for prefix in (["unshare", "--mount", "--propagation", "private"],
                   ["unshare", "--user", "--map-root-user", "--mount"]):
        r = subprocess.run([*prefix, "sh", "-c", "d=$(mktemp -d) && mount -t tmpfs -o size=64k tmpfs $d"],
                           capture_output=True)
        if r.returncode == 0:
            return prefix
    return None


MOUNT = _mount_prefix()
needs_tmpfs = pytest.mark.skipif(MOUNT is None, reason="cannot mount a tmpfs here (not root, no user namespaces)")


def _on_full_disk(tmp_path: Path, size: str, args: list[str]) -> tuple[int, str, list[str], Path]:
    """Run ``stochpend ARGS`` (``{disk}`` in them is the tmpfs) with a tmpfs of ``size`` at
    ``disk``; returns the exit status, stderr, the tmpfs's listing (recursive, with sizes) and
    the directory the run's files outside the tmpfs live in."""
    disk, saved = tmp_path / "disk", tmp_path / "saved"
    disk.mkdir()
    saved.mkdir()
    cmd = " ".join(f"'{a.format(disk=disk)}'" for a in _cmd(*args))
    script = (f"mount -t tmpfs -o size={size} tmpfs {disk} && cd {tmp_path} && "
              f"{cmd} 2> {saved}/err; echo $? > {saved}/rc; "
              f"find {disk} -mindepth 1 -printf '%P %s %y\\n' > {saved}/listing")
    subprocess.run([*MOUNT, "sh", "-c", script], env=_env(), timeout=600, check=True)
    listing = (saved / "listing").read_text().splitlines()
    return int((saved / "rc").read_text()), (saved / "err").read_text(), listing, saved


SWEEP = 'description = "tiny"\n[base]\npaths = 200\nt_max = 2\nn_times = 2\n[grid]\nD = [1.0, 2.0]\n'

FULL_DISK = {  # each result is larger than the 40 KiB tmpfs, so the disk fills during its write
    "simulate": ["simulate", *TINY, "--quiet", "--out", "{disk}/a.nc"],
    "sweep": ["sweep", "small.toml", "--quiet", "--out", "{disk}/a.nc"],
    "bfpe": ["bfpe", "--t-max", "100", "--n-cells", "100", "--quiet", "--out", "{disk}/a.nc"],
    "reduced": ["reduced", "--paths", "100", "--t-max", "10", "--quiet", "--out", "{disk}/a.nc"],
}


@needs_tmpfs
@pytest.mark.parametrize("command", list(FULL_DISK))
def test_full_disk_during_the_write_is_one_line_and_exit_1(tmp_path, command):
    """F01-F04: on a 40 KiB tmpfs every NetCDF write died with SIGSEGV (exit 139) inside libhdf5,
    bfpe and reduced after 30-100 traceback lines."""
    (tmp_path / "small.toml").write_text(SWEEP)
    rc, err, listing, _ = _on_full_disk(tmp_path, "40k", FULL_DISK[command])
    assert rc == 1, err
    line = _one_line(err)
    assert line.startswith("error: cannot write out=") and "No space left on device" in line, line
    assert line.endswith("nothing was written there"), line
    assert listing == [], "a partial or temporary file was left on the full disk"


@needs_tmpfs
def test_full_disk_at_the_end_of_a_checkpointed_run_keeps_the_checkpoint(tmp_path):
    """F05: the result cannot be written; the finished run is kept in the checkpoint (on
    another disk) and exit code 1, not 139; resuming it elsewhere writes the result."""
    ckpt = tmp_path / "f5.ckpt"
    rc, err, listing, _ = _on_full_disk(tmp_path, "40k", ["simulate", *TINY, "--quiet", "--checkpoint",
                                                          str(ckpt), "--out", "{disk}/a.nc"])
    assert rc == 1, err
    line = _one_line(err)
    assert "No space left on device" in line and f"the finished run is kept in {str(ckpt)!r}" in line, line
    assert listing == []
    r = _run("resume", str(ckpt), "--out", str(tmp_path / "f5.nc"), "--quiet", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "f5.nc").is_file() and not ckpt.exists()


@needs_tmpfs
def test_full_disk_in_reproduce_leaves_no_empty_file(tmp_path):
    """F06, F06b: reproduce wrote its figures, tables and report in place, so a full disk left
    a 0-byte report.html, and the error named no file."""
    rc, err, listing, _ = _on_full_disk(tmp_path, "1365k", ["reproduce", "fig1", "--quick", "--out", "{disk}/r"])
    assert rc == 1, err
    last = err.strip().splitlines()[-1]
    assert "Traceback" not in err
    assert last.startswith("error: cannot write out=") and "No space left on device" in last, last
    files = [entry.split() for entry in listing if entry.endswith(" f")]
    assert files, listing
    assert all(int(size) > 0 for _, size, _ in files), listing
    assert not [name for name, _, _ in files if name.endswith(".tmp")], listing


# -- outputs that must not be replaced, and names refused before any work ------------------------
def _invoke(args: list[str]):
    return CliRunner().invoke(cli.app, args)


def _work_started(*args, **kwargs):
    raise AssertionError("the work started before the refusal")


def _invoke_before_work(args: list[str]):
    """``_invoke`` with every way into the work failing the command: the kernels' batches (a
    run, a resume, a bias estimate), a sweep's blocks and the B.F.P.E.'s time steps. A refusal
    must come before all of them (a bound on work, where these tests had wall-time limits that
    a busy machine could break: issue 37)."""
    # Imported before the patches: a module first imported under them binds the patched
    # run_batches by name (``from stochpend.engine.runner import run_batches``) and keeps it for good,
    # failing every later test of this process that does work.
    import stochpend.runs._blocks  # noqa: F401
    import stochpend.sweep  # noqa: F401
    import stochpend.theory.bfpe  # noqa: F401
    with mock.patch("stochpend.engine.runner.run_batches", _work_started), \
            mock.patch("stochpend.runs._blocks.run_batches", _work_started), \
            mock.patch("stochpend.sweep.run_block", _work_started), \
            mock.patch("stochpend.theory.bfpe._sdirk2_step", _work_started):
        return _invoke(args)


@pytest.mark.parametrize("kind", ["fifo", "device", "dangling-symlink", "symlink", "directory"])
def test_out_that_is_not_a_regular_file_is_never_replaced(tmp_path, kind):
    """X01, X03: --overwrite replaced a device node or FIFO by a regular file (as root, --out
    /dev/null --overwrite would replace the system's /dev/null); X02: a dangling symlink was
    refused only after the work, as 'another process wrote it'."""
    out = tmp_path / "out.nc"
    if kind == "fifo":
        os.mkfifo(out)
    elif kind == "device":
        try:
            os.mknod(out, stat.S_IFCHR | 0o666, os.makedev(1, 3))
        except PermissionError:
            pytest.skip("creating a device node needs root")
    elif kind == "dangling-symlink":
        out.symlink_to(tmp_path / "nowhere" / "target")
    elif kind == "symlink":
        (tmp_path / "real.nc").write_text("a user's file")
        out.symlink_to(tmp_path / "real.nc")
    else:
        out.mkdir()
    before = os.lstat(out)
    for extra in ([], ["--overwrite"]):
        # --paths 1e9 would run for hours: the refusal must come before any work.
        result = _invoke_before_work(["simulate", "--paths", "1e9", "--t-max", "1", "--quiet", "--out", str(out),
                                      *extra])
        assert result.exit_code == 2, result.output
        line = _one_line(result.output)
        assert line.startswith(f"error: --out {str(out)!r} is not accepted: it is "), line
        after = os.lstat(out)
        assert (after.st_ino, after.st_mode) == (before.st_ino, before.st_mode)
    if kind == "symlink":
        assert (tmp_path / "real.nc").read_text() == "a user's file"


def test_non_utf8_out_is_refused_before_any_work(tmp_path):
    """E09, E09b, E10: a name that is not UTF-8 was refused after the whole run (exit 2, no
    parameter named) and a checkpointed run could then never be written."""
    out = tmp_path / os.fsdecode(b"r\xff.nc")
    for cmd in (["simulate", "--paths", "1e9", "--t-max", "1", "--out", str(out)],
                ["simulate", *TINY, "--checkpoint", str(out)],
                ["sweep", str(tmp_path / "s.toml"), "--out", str(out)]):
        (tmp_path / "s.toml").write_text(SWEEP)
        result = _invoke(cmd)
        assert result.exit_code == 2, result.output
        line = _one_line(result.output)
        assert "is not accepted: the name is not valid UTF-8" in line and "\\udcff" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.toml"]


def test_out_directory_removed_during_the_run_is_a_failure_not_bad_input(tmp_path, monkeypatch):
    """F09: the --out directory removed mid-run was reported as bad input (exit 2)."""
    gone = tmp_path / "gone"
    gone.mkdir()
    real = io.to_netcdf

    def remove_then_write(ds, path, **kwargs):
        shutil.rmtree(gone)  # the fault strikes after the work, before the write
        return real(ds, path, **kwargs)

    monkeypatch.setattr(io, "to_netcdf", remove_then_write)
    result = _invoke(["simulate", *TINY, "--quiet", "--out", str(gone / "x.nc")])
    assert result.exit_code == 1, result.output
    line = _one_line(result.output)
    assert line == f"error: cannot write out={str(gone / 'x.nc')!r}: its directory does not exist (any more); " \
                   "nothing was written there", line


def test_markup_in_a_file_name_is_printed_as_written(tmp_path):
    """S06: --out 'run[old].nc' was reported as 'wrote run.nc'; S07: 'd[/]x.nc' gave a
    MarkupError traceback after the result was written."""
    (tmp_path / "d[").mkdir()
    for name in ("run[old].nc", "d[/]x.nc"):
        out = tmp_path / name
        result = _invoke(["simulate", *TINY, "--bias-paths", "0", "--out", str(out)])
        assert result.exit_code == 0, result.output
        assert out.is_file()
        assert result.output.rstrip().splitlines()[-1] == f"wrote {out}"


def test_closed_stderr(tmp_path):
    """O2, O7, O9: with file descriptor 2 closed every command failed at import (exit 1), so a
    detached --quiet run did no work and bad input gave 1, not 2."""
    def closed(*args: str) -> int:
        cmd = " ".join(f"'{a}'" for a in _cmd(*args))
        return subprocess.run(["sh", "-c", f"{cmd} 2>&-"], cwd=tmp_path, env=_env(), timeout=300).returncode

    assert closed("simulate", "--paths", "0") == 2
    assert closed("simulate", *TINY, "--quiet", "--out", "closed.nc") == 0
    assert (tmp_path / "closed.nc").is_file()


# -- one run per checkpoint, and signals -------------------------------------------------------
def _start(args: list[str], cwd: Path) -> subprocess.Popen:
    # SIGHUP delivered even when this suite runs under nohup (an ignored signal stays ignored).
    return subprocess.Popen(_cmd(*args), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=cwd, env=_env(), preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_DFL))


def _wait_for(path: Path, proc: subprocess.Popen, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while not path.exists():
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, f"{path} did not appear"
        time.sleep(0.05)


def _first_line(args: list[str], cwd: Path, timeout: float) -> str:
    """The first line the command prints on stderr within ``timeout`` seconds ('' if none; a
    note of a first use's compilation skipped); then the command is killed. For runs that must
    say what they will cost before they start: the old code printed nothing for minutes."""
    proc = _start(args, cwd)
    fd, text = proc.stderr.fileno(), b""  # type: ignore[union-attr]
    deadline = time.monotonic() + timeout
    try:
        while True:
            while b"\n" in text:
                line, text = text.split(b"\n", 1)
                if not line.startswith(b"compiling kernels for "):
                    return line.decode()
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([fd], [], [], left)[0]:
                return ""
            chunk = os.read(fd, 65536)
            if not chunk:
                return text.decode()
            text += chunk
    finally:
        proc.kill()
        proc.communicate()


def test_one_run_per_checkpoint_and_signals_save_it(tmp_path):
    """F13: two runs on one --checkpoint overwrote each other's state and the winner deleted
    it; I2: SIGHUP killed a checkpointed run without saving; F12: two resumes both computed and
    the loser claimed a deleted file kept the run; X08: resume CK --out CK --overwrite destroyed
    the finished run and exited 0."""
    ckpt, lock = tmp_path / "run.ckpt", ck.lock_path(tmp_path / "run.ckpt")
    a = _start(["simulate", *LONG, "--checkpoint", "run.ckpt", "--checkpoint-every", "1h", "--out", "a.nc",
                "--quiet"], tmp_path)
    _wait_for(lock, a)
    b = _run("simulate", *LONG, "--checkpoint", "run.ckpt", "--out", "b.nc", "--quiet", cwd=tmp_path)
    assert b.returncode == 2, b.stderr
    line = _one_line(b.stderr)
    assert line.startswith("error: --checkpoint 'run.ckpt' is not accepted: it is in use by "
                           f"pid {a.pid} on host "), line
    a.send_signal(signal.SIGHUP)  # the SSH session dropped: save the state, then exit 128 + 1
    _, err = a.communicate(timeout=120)
    assert a.returncode == 128 + signal.SIGHUP, err
    assert err.splitlines()[-1] == "interrupted: state saved to run.ckpt; continue with: stochpend resume run.ckpt"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.ckpt"], "a temporary or lock file was left"

    first = _start(["resume", "run.ckpt", "--quiet"], tmp_path)
    _wait_for(lock, first)
    second = _run("resume", "run.ckpt", "--quiet", cwd=tmp_path)
    assert second.returncode == 2, second.stderr
    assert f"it is in use by pid {first.pid} on host " in _one_line(second.stderr)
    first.send_signal(signal.SIGTERM)
    _, err = first.communicate(timeout=120)
    assert first.returncode == 128 + signal.SIGTERM, err
    assert not (tmp_path / "a.nc").exists() and ckpt.is_file()
    saved = ckpt.read_bytes()

    r = _run("resume", "run.ckpt", "--out", "run.ckpt", "--overwrite", cwd=tmp_path)
    assert r.returncode == 2, r.stderr
    assert "it is the checkpoint itself" in _one_line(r.stderr)
    assert ckpt.read_bytes() == saved


# -- the trust boundary: a checkpoint someone hands you -------------------------------------------
SMALL = {"noise": "ou", "D": 1.0, "tau": 1.0, "omega": 1.0, "paths": 300, "t_max": 20.0, "n_times": 4, "seed": 5}


class _StopAfterOne(ck.FileCheckpointer):
    def maybe_save(self, state):
        self.save(state)
        raise KeyboardInterrupt


@pytest.fixture(scope="module")
def handed_over(tmp_path_factory):
    """A mid-run checkpoint whose recorded output is run.nc beside it."""
    folder = tmp_path_factory.mktemp("ckpt")
    config = SimulationConfig.build(**SMALL)
    path = folder / "run.ckpt"
    cp = _StopAfterOne(path, None, config=config, out=folder / "run.nc", chunk_paths=90,
                       command_line="stochpend simulate --out run.nc")
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, checkpointer=cp, chunk_paths=90,
                            out=folder / "run.nc")
    return path.read_bytes()


def _crafted(data: bytes, dest: Path, **changes) -> Path:
    """``data`` with header fields changed and a valid SHA-256, as an attacker would make it."""
    n = len(ck.MAGIC)
    (head_len,) = struct.unpack_from("<Q", data, n)
    header = json.loads(data[n + 8:n + 8 + head_len])
    header.update(changes)
    head = json.dumps(header).encode()
    body = ck.MAGIC + struct.pack("<Q", len(head)) + head + data[n + 8 + head_len:-32]
    dest.write_bytes(body + hashlib.sha256(body).digest())
    return dest


def test_a_crafted_checkpoint_cannot_choose_or_overwrite_the_destination(tmp_path, handed_over):
    """S01, S02: a checkpoint with `out` set to a user's file and `overwrite` true replaced
    that file, and 'resuming ...' showed the checkpoint's own command line."""
    victim = tmp_path / "home" / "victim.txt"
    victim.parent.mkdir()
    victim.write_text("precious user data")
    work = tmp_path / "work"
    work.mkdir()
    evil = _crafted(handed_over, work / "evil.ckpt", out=str(victim), overwrite=True)
    result = _invoke(["resume", str(evil)])
    assert result.exit_code == 2, result.output
    line = _one_line(result.output)
    assert "outside the checkpoint's own directory; pass --out FILE" in line, line
    # The same name inside the checkpoint's own directory: used, but not overwritten on its say.
    (work / "victim.txt").write_text("precious user data")
    evil = _crafted(handed_over, work / "evil2.ckpt", out=str(work / "victim.txt"), overwrite=True)
    result = _invoke(["resume", str(evil)])
    assert result.exit_code == 2 and "the file exists (pass --overwrite" in _one_line(result.output)
    assert victim.read_text() == (work / "victim.txt").read_text() == "precious user data"


def test_text_from_a_checkpoint_is_escaped(tmp_path, handed_over):
    """S03: command_line '[/]' gave a MarkupError traceback; S04: escape sequences (window
    title, clear screen) and [link=...] from the header reached the terminal."""
    hostile = "stochpend [/] \x1b]0;PWNED\x07\x1b[2J[link=https://evil.example]x[/link]"
    path = _crafted(handed_over, tmp_path / "run.ckpt", out=str(tmp_path / "run.nc"), command_line=hostile)
    result = _invoke(["resume", str(path)])
    assert result.exit_code == 0, result.output
    first = result.output.splitlines()[0]
    assert "\x1b" not in result.output and "\x07" not in result.output
    assert first.startswith("resuming stochpend [/] \\x1b]0;PWNED\\x07\\x1b[2J[link=https://evil.example]x[/link]")
    assert first.endswith(f"; writing {tmp_path / 'run.nc'}"), first
    assert (tmp_path / "run.nc").is_file()


def test_a_checkpoint_whose_command_line_is_not_unicode_can_be_written(tmp_path, handed_over):
    """E09c: a checkpoint from before names were checked kept a lone surrogate (an undecodable
    byte of the command line): `resume --out ok.nc`, the advice given, failed the same way
    forever. The text is now written escaped."""
    path = _crafted(handed_over, tmp_path / "k.ckpt", out=str(tmp_path / "r.nc"),
                    command_line="stochpend simulate --out r\udcff.nc")
    result = _invoke(["resume", str(path), "--out", str(tmp_path / "ok.nc")])
    assert result.exit_code == 0, result.output
    ds = io.open_results(tmp_path / "ok.nc")
    texts = " ".join(str(v) for v in ds.attrs.values())
    assert "r\\udcff.nc" in texts, texts


def test_a_refusal_is_one_line_without_numpy_warnings_before_it():
    """T04, D01: NumPy's overflow warnings (two lines each) came before the error line."""
    for args in (["theory", "--bfpe", "--t", "1e308"],
                 ["reduced", "--order", "second", "--h-max", "1e-300", "--paths", "10", "--t-max", "1"]):
        proc = subprocess.run(_cmd(*args), capture_output=True, text=True, env=_env(), timeout=120)
        assert proc.returncode == 2, proc.stderr
        assert _one_line(proc.stderr).startswith("error: "), proc.stderr
        assert "Warning" not in proc.stderr


def _crafted_raw(data: bytes, dest: Path, edit) -> Path:
    """``data`` with its header text passed through ``edit`` and a valid SHA-256."""
    n = len(ck.MAGIC)
    (head_len,) = struct.unpack_from("<Q", data, n)
    head = edit(data[n + 8:n + 8 + head_len].decode()).encode()
    body = ck.MAGIC + struct.pack("<Q", len(head)) + head + data[n + 8 + head_len:-32]
    dest.write_bytes(body + hashlib.sha256(body).digest())
    return dest


def _set(path: list[str], value: str):
    """An edit of the header text setting the field at ``path`` to the raw JSON ``value``."""
    def edit(text: str) -> str:
        header = json.loads(text)
        target = header
        for key in path[:-1]:
            target = target[key] if not isinstance(target, list) else target[int(key)]
        target[path[-1] if not isinstance(target, list) else int(path[-1])] = "@@"
        return json.dumps(header).replace('"@@"', value)
    return edit


def _array_dtype(name: str, dtype: str):
    """An edit declaring the array ``name`` with ``dtype`` (same size: the bytes still fit)."""
    def edit(text: str) -> str:
        header = json.loads(text)
        (entry,) = [a for a in header["arrays"] if a["name"] == name]
        entry["dtype"] = dtype
        return json.dumps(header)
    return edit


MALFORMED = {  # case id: (edit, what the one line names)
    "S15": (_array_dtype("x", "<i8"), "array 'x' has dtype <i8 and shape"),
    "S16": (_array_dtype("status", "|b1"), "array 'status' has dtype |b1 and shape"),
    "S08": (_set(["arrays", "0", "offset"], "Infinity"), "Infinity is not a valid value"),
    "S09": (_set(["run", "path_steps"], "Infinity"), "Infinity is not a valid value"),
    "S10": (_set(["extra"], "[" * 100_000 + "]" * 100_000), "nested too deeply"),
    "S11": (_set(["threads"], '"abc"'), "malformed header: threads='abc'"),
    "S12": (_set(["every_s"], '"abc"'), "malformed header: every_s='abc'"),
    "S14": (_set(["elapsed_s"], '"abc"'), "malformed header: elapsed_s='abc'"),
    "S18": (_set(["run", "done_work"], "NaN"), "NaN is not a valid value"),
    "S19": (_set(["bias_paths"], '"abc"'), "malformed header: bias_paths='abc'"),
    "S19b": (_set(["bias_paths"], "1"), "malformed header: bias_paths=1"),
    "S19c": (_set(["bias_paths"], "true"), "malformed header: bias_paths=True"),
    "S20": (_set(["accuracy"], '"auto"'), "malformed header: accuracy='auto'"),
    "S20b": (_set(["accuracy"], '{"level": 99}'), "malformed header: accuracy={'level': 99}"),
    "S20c": (_set(["accuracy"], '{"level": 1, "rtol": null, "pilot_paths": 64, "pilot_path_steps": 1, '
                                '"pilot_wall_time_s": 0.1, "pilot_batches": 32}'),
             "missing arrays ['pilot_bias', 'pilot_coarse', 'pilot_decorrelation', 'pilot_nonfinite']"),
    "S09b": (_set(["run", "path_steps"], "1" + "0" * 400), "inconsistent run position"),
}


@pytest.mark.parametrize("case", list(MALFORMED))
def test_malformed_but_checksummed_checkpoint_is_one_line(tmp_path, handed_over, case):
    """S08-S12, S14, S18-S20: header fields with Infinity, NaN, deep nesting or wrong types, under
    a valid SHA-256, gave tracebacks or failed after the work had started; S15, S16: a per-path
    array declared with another dtype of the same size was accepted and reinterpreted."""
    edit, needle = MALFORMED[case]
    path = _crafted_raw(handed_over, tmp_path / "c.ckpt", edit)
    result = _invoke(["resume", str(path), "--out", str(tmp_path / "o.nc")])
    assert result.exit_code == 2, result.output
    line = _one_line(result.output)
    assert line.startswith(f"error: checkpoint={str(path)!r} is not accepted: ") and needle in line, line
    assert not (tmp_path / "o.nc").exists()


# -- show and open_results on crafted NetCDF files ---------------------------------------------
@pytest.fixture(scope="module")
def crafted_nc(tmp_path_factory):
    """The crafted results files of the case list (N01-N16), beside a genuine one."""
    import h5py
    import numpy as np
    import xarray as xr

    d = tmp_path_factory.mktemp("nc")
    result = _invoke(["simulate", *TINY, "--n-times", "5", "--quiet", "--out", str(d / "base.nc")])
    assert result.exit_code == 0, result.output
    base = io.open_results(d / "base.nc")

    def save(ds, name):
        # An adversary recomputes the checksum (it guards against damage, not forgery): these
        # files test what show does with crafted contents that verify.
        ds.to_netcdf(d / name, engine="h5netcdf")
        with xr.open_dataset(d / name, engine="h5netcdf") as back:
            digest = io.checksum(back.load())
        with h5py.File(d / name, "a") as f:
            f.attrs[io.CHECKSUM_ATTR] = digest

    def with_attr(name, key, value):
        ds = base.copy()
        ds.attrs[key] = value
        save(ds, name)

    with_attr("N01.nc", "noise", "ou\x1b]0;PWNED\x07\x1b[2J\x1b[1;31mFAKE")
    with_attr("N02.nc", "noise", "ou [/]")
    with_attr("N03.nc", "paths", np.inf)
    with_attr("N04.nc", "D", "abc")
    with_attr("N05.nc", "seed", "[link=https://evil.example]click me[/link]")
    save(base.drop_vars("mean_E_stderr"), "N06.nc")
    save(xr.Dataset({"mean_E": ("x", np.arange(3.0))}), "N07.nc")
    with_attr("N08.nc", "n_batches", np.inf)
    shutil.copy(d / "base.nc", d / "N09.nc")
    with h5py.File(d / "N09.nc", "a") as f:  # 1e11 declared elements, no data written
        f.create_dataset("junk", shape=(10**11,), dtype="f8", chunks=(10**6,), maxshape=(None,))
    os.mkfifo(d / "fifo")
    (d / "secret.txt").write_text("a private file " * 8)
    for name, target in (("N11.nc", d / "fifo"), ("N12.nc", d / "secret.txt")):
        base.drop_vars("mean_E").to_netcdf(d / name, engine="h5netcdf")
        with h5py.File(d / name, "a") as f:
            ds = f.create_dataset("mean_E", shape=(5,), dtype="<f8", external=[(str(target), 0, h5py.h5f.UNLIMITED)])
            ds.dims[0].attach_scale(f["time"])
    shutil.copy(d / "base.nc", d / "N15.nc")
    with h5py.File(d / "N15.nc", "a") as f:
        f["loop"] = h5py.SoftLink("/loop")
    shutil.copy(d / "base.nc", d / "N16.nc")
    with h5py.File(d / "N16.nc", "a") as f:
        f["other"] = h5py.ExternalLink(str(d / "base.nc"), "/mean_E")
    return d


REFUSED_NC = {  # case id: what the one line says
    "N03": "cannot convert float infinity to integer", "N04": "could not convert string to float",
    "N06": "not a file stochpend writes", "N07": "'time'", "N08": "cannot convert float infinity to integer",
    "N09": "it declares 8e+11 bytes of data in a file of ", "N11": "'/mean_E' keeps its data in another file",
    "N12": "'/mean_E' keeps its data in another file", "N15": "'/loop' is a link to another place or file",
    "N16": "'/other' is a link to another place or file",
}


@pytest.mark.parametrize("case", list(REFUSED_NC))
def test_show_refuses_a_crafted_results_file_in_one_line(crafted_nc, case):
    """N09-N12, N15, N16: a crafted file made show hang (data in a FIFO), print a private
    file's bytes as numbers, ask for 745 GiB, or end in tracebacks; N03-N08: tracebacks."""
    path = crafted_nc / f"{case}.nc"
    proc = subprocess.run(_cmd("show", str(path)), capture_output=True, text=True, env=_env(), timeout=60)
    assert proc.returncode == 2, proc.stderr
    line = _one_line(proc.stderr)
    assert line.startswith(f"error: path={str(path)!r} is not accepted: ") and REFUSED_NC[case] in line, line
    assert proc.stdout == ""


@pytest.mark.parametrize("case", ["N01", "N02", "N05"])
def test_show_escapes_text_from_the_file(crafted_nc, case):
    """N01: escape sequences from an attribute reached the terminal; N02: '[/]' gave a
    MarkupError traceback; N05: [link=...] became a hyperlink and its text vanished."""
    result = _invoke(["show", str(crafted_nc / f"{case}.nc")])
    assert result.exit_code == 0, result.output
    assert "\x1b" not in result.output and "\x07" not in result.output
    title = {"N01": "ou\\x1b]0;PWNED\\x07\\x1b[2J\\x1b[1;31mFAKE noise", "N02": "ou [/] noise",
             "N05": "seed [link=https://evil.example]click me[/link]"}[case]
    assert title in " ".join(result.output.split()), result.output


# -- sweeps: bounded before expanding, text escaped, TOML that cannot be parsed ----------------
def test_sweep_grid_is_counted_before_it_is_expanded(tmp_path):
    """W11c: a 742-byte TOML of 5 axes x 25 values expanded to 9.8 million parameter sets
    (3.7 GB, 173 s) before a MemoryError traceback."""
    lines = ["[base]", "paths = 2", "t_max = 0.05", "n_times = 1", "[grid]"]
    for axis in ("D", "tau", "omega", "seed", "Omega0"):
        values = ", ".join(str(i) if axis == "seed" else f"{1 + i}.0" for i in range(25))
        lines.append(f"{axis} = [{values}]")
    (tmp_path / "g.toml").write_text("\n".join(lines) + "\n")
    result = _invoke_before_work(["sweep", str(tmp_path / "g.toml"), "--out", str(tmp_path / "g.nc")])
    assert result.exit_code == 2, result.output
    assert _one_line(result.output) == ("error: g.toml: grid is not accepted: 25 D x 25 tau x 25 omega x 25 seed "
                                        "x 25 Omega0 make 9.77e+06 parameter sets, more than 100,000; split it "
                                        "into several sweeps")


@pytest.mark.parametrize("case", ["W06", "W06b", "W16"])
def test_sweep_toml_that_cannot_be_parsed_is_one_line(tmp_path, case):
    """W06, W06b: deeply nested TOML gave a 3000-line RecursionError traceback; W16: a
    5000-digit integer gave a line naming neither the file nor the key."""
    text = {"W06": "[base]\npaths=10\n[grid]\nD = " + "[" * 5000 + "1" + "]" * 5000 + "\n",
            "W06b": "[base]\npaths=10\n[grid]\nx = " + "{a=" * 3000 + "1" + "}" * 3000 + "\n",
            "W16": "[base]\npaths = " + "9" * 5000 + "\n[grid]\nD = [1.0]\n"}[case]
    (tmp_path / "bad.toml").write_text(text)
    result = _invoke(["sweep", str(tmp_path / "bad.toml")])
    assert result.exit_code == 2, result.output
    line = _one_line(result.output)
    assert line.startswith(f"error: sweep={str(tmp_path / 'bad.toml')!r} is not accepted: invalid TOML"), line


def test_sweep_description_is_escaped(tmp_path):
    """W03: description '[/]' gave a MarkupError after the sweep was written; W04: escape
    sequences reached the terminal; W05: '[draft]' vanished."""
    text = SWEEP.replace('"tiny"', '"Fig [/] [draft] \\u001b]0;PWNED\\u0007"')
    (tmp_path / "m.toml").write_text(text)
    result = _invoke(["sweep", str(tmp_path / "m.toml"), "--out", str(tmp_path / "m.nc")])
    assert result.exit_code == 0, result.output
    assert "(Fig [/] [draft] \\x1b]0;PWNED\\x07)" in result.output
    assert "\x1b" not in result.output


def test_sweep_workers_bounded_by_the_machine(tmp_path):
    """W24: --workers 1e6 went straight to LocalCluster(n_workers=1000000)."""
    (tmp_path / "s.toml").write_text(SWEEP)
    result = _invoke(["sweep", str(tmp_path / "s.toml"), "--scheduler", "local", "--workers", "1e6"])
    assert result.exit_code == 2, result.output
    assert f"--workers 1000000 is not accepted: an integer in [1, {os.cpu_count()}]" in _one_line(result.output)


# -- bounded work, strict parsing --------------------------------------------------------------
@pytest.mark.parametrize("case", ["R03b", "R02", "B01", "R10g", "R10h", "R10i"])
def test_work_and_settings_refused_before_any_work(tmp_path, case):
    """R03b: the work limit ignored that every path stops at every output time (1e14
    path-steps estimated as 20); R02: --step-c 1e-300 was reported as a blow-up; B01: bfpe
    --n-cells 1e7 --steps-per-decade 1e5 ran for days with no estimate; R10g-i:
    --checkpoint-every '1.5.5s', '1 2 3' and '' were read as 2 s, 6 s and 5 min."""
    args, needle = {
        "R03b": (["simulate", "--paths", "1e9", "--t-max", "1e-9", "--n-times", "1e5"],
                 "--paths 1000000000 is not accepted: the run needs at least 1e+14 path-steps (paths x output times"),
        "R02": (["simulate", "--step-c", "1e-300", "--paths", "1", "--t-max", "1", "--n-times", "1"],
                "--step-c 1e-300 is not accepted: 0 (fixed step) or a number >= 1e-06"),
        "B01": (["bfpe", "--n-cells", "1e7", "--t-max", "10", "--steps-per-decade", "1e5"],
                "--n-cells 10000000 is not accepted: the solve needs about 6e+12 cell-steps"),
        "R10g": ([*TINY, "--checkpoint", "x.ckpt", "--checkpoint-every", "1.5.5s"], "--checkpoint-every '1.5.5s'"),
        "R10h": ([*TINY, "--checkpoint", "x.ckpt", "--checkpoint-every", "1 2 3"], "--checkpoint-every '1 2 3'"),
        "R10i": ([*TINY, "--checkpoint", "x.ckpt", "--checkpoint-every", ""], "--checkpoint-every ''"),
    }[case]
    if case.startswith("R10"):
        args = ["simulate", *args]
    result = _invoke_before_work([*args, "--out", str(tmp_path / "o.nc")])
    assert result.exit_code == 2, result.output
    assert needle in _one_line(result.output)
    assert list(tmp_path.iterdir()) == []


def test_a_checkpoint_larger_than_memory_is_refused_before_reading(tmp_path):
    """S20, S21: a sparse 64 GiB file with the magic bytes was read whole: MemoryError traceback."""
    path = tmp_path / "big.ckpt"
    with open(path, "wb") as f:
        f.write(ck.MAGIC)
        f.truncate(1 << 40)  # 1 TiB, sparse: more than twice any memory here
    result = _invoke(["resume", str(path)])
    assert result.exit_code == 2, result.output
    line = _one_line(result.output)
    assert "is not accepted: it is 1.0 TiB, and reading it needs 3 times that" in line, line


@pytest.mark.parametrize("value", ["1000000", "0"])
def test_absurd_numba_thread_count_is_one_line(value):
    """E03: NUMBA_NUM_THREADS=1000000 made simulate die with SIGSEGV and no message; E01: 0
    gave a traceback at import (Numba is now imported after the CLI's check)."""
    env = {**_env(), "NUMBA_NUM_THREADS": value}
    proc = subprocess.run(_cmd("simulate", *TINY, "--quiet"), capture_output=True, text=True, env=env, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert _one_line(proc.stderr).startswith(f"error: NUMBA_NUM_THREADS={value!r} is not accepted: an integer in [1, ")


@pytest.mark.skipif(MOUNT is None or os.geteuid() != 0, reason="needs root to bind-mount the package read-only")
def test_read_only_install_and_home_fall_back_to_a_temporary_cache(tmp_path):
    """E05: with the package and HOME read-only every simulation failed with 'cannot cache
    function ...: no locator available'. Compiles cold (~16 s here)."""
    home = tmp_path / "home"
    home.mkdir()
    cmd = " ".join(f"'{a}'" for a in _cmd("simulate", "--paths", "50", "--t-max", "1", "--n-times", "2",
                                              "--quiet", "--out", str(tmp_path / "ro.nc")))
    script = (f"mount --bind {SRC} {SRC} && mount -o remount,bind,ro {SRC} && "
              f"mount --bind {home} {home} && mount -o remount,bind,ro {home} && HOME={home} {cmd}")
    env = {k: v for k, v in _env().items() if k != "NUMBA_CACHE_DIR"}
    proc = subprocess.run([*MOUNT, "sh", "-c", script], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    # The fallback's note, then (a cold cache: it is a temporary one) the compiling line, after
    # the estimate where the calibrated compile time makes the start a long one (issue 36).
    line, *rest = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert line.startswith("note: no writable Numba cache") and "set NUMBA_CACHE_DIR to keep them" in line, line
    rest = [ln for ln in rest if not ln.startswith("estimate: ")]
    assert all(ln.startswith("compiling kernels for ") for ln in rest) and len(rest) <= 1, proc.stderr
    assert (tmp_path / "ro.nc").is_file()


def test_resume_refuses_bad_threads_in_one_line(tmp_path, handed_over):
    """X06: `resume --threads 1e6` printed its 'resuming ...' line before the error."""
    path = tmp_path / "run.ckpt"
    path.write_bytes(handed_over)
    result = _invoke(["resume", str(path), "--threads", "1e6", "--out", str(tmp_path / "o.nc")])
    assert result.exit_code == 2, result.output
    assert _one_line(result.output).startswith("error: --threads 1000000 is not accepted: an integer in [1, ")


@pytest.mark.parametrize("kind", ["directory", "device"])
def test_checkpoint_that_is_not_a_regular_file_says_what_it_is(tmp_path, kind):
    """X04, X05: --checkpoint naming a directory or /dev/null said 'the file exists; continue
    that run with stochpend resume ...'."""
    path = tmp_path / "adir" if kind == "directory" else Path("/dev/null")
    if kind == "directory":
        path.mkdir()
    result = _invoke(["simulate", *TINY, "--checkpoint", str(path)])
    assert result.exit_code == 2, result.output
    what = "a directory, not a file" if kind == "directory" else "a device, not a regular file"
    assert _one_line(result.output) == f"error: --checkpoint {str(path)!r} is not accepted: it is {what}"


@pytest.mark.parametrize("checkpointed", [False, True])
def test_sigterm_during_the_final_write_leaves_no_temporary_file(tmp_path, monkeypatch, checkpointed):
    """Issue 20 item 7 (no id in the case list): SIGTERM during the final write left a 0-byte
    `.x.nc.*.tmp` beside the output. A real SIGTERM, delivered half-way through the write."""
    from stochpend.files import _files

    real = io.write_atomic

    def half_then_sigterm(path, data, **kwargs):
        def put(fd):
            view = memoryview(data).cast("B")
            _files.write_all(fd, view[: len(view) // 2])
            os.kill(os.getpid(), signal.SIGTERM)
            _files.write_all(fd, view[len(view) // 2:])
        return real(path, put, **kwargs)

    monkeypatch.setattr(io, "write_atomic", half_then_sigterm)
    extra = ["--checkpoint", str(tmp_path / "x.ckpt")] if checkpointed else []
    result = _invoke(["simulate", *TINY, "--quiet", *extra, "--out", str(tmp_path / "x.nc")])
    assert result.exit_code == 128 + signal.SIGTERM, result.output
    assert "Traceback" not in result.output
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == (["x.ckpt"] if checkpointed else []), left
    if checkpointed:
        assert "the last checkpoint is kept: continue with: stochpend resume" in result.output


def test_sigterm_during_the_bias_phase_says_so_and_keeps_the_checkpoint(tmp_path, monkeypatch):
    """F15: SIGTERM during the final bias estimate (outside the deferred-signal window) killed
    the run silently, exit 143 and no word. A real SIGTERM, sent as the bias phase starts."""
    from stochpend import bias

    real = bias.estimate

    def sigterm_then_estimate(*args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        return real(*args, **kwargs)

    monkeypatch.setattr(bias, "estimate", sigterm_then_estimate)
    ckpt = tmp_path / "b.ckpt"
    result = _invoke(["simulate", *TINY, "--quiet", "--checkpoint", str(ckpt), "--out", str(tmp_path / "b.nc")])
    assert result.exit_code == 128 + signal.SIGTERM, result.output
    assert _one_line(result.output) == ("interrupted by signal 15 (no new checkpoint); the last checkpoint is "
                                        f"kept: continue with: stochpend resume {ckpt}")
    monkeypatch.setattr(bias, "estimate", real)
    result = _invoke(["resume", str(ckpt), "--quiet"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "b.nc").is_file() and not ckpt.exists()


@pytest.mark.parametrize("case", ["T03", "D04", "K02", "K03"])
def test_values_beyond_the_floats_are_one_line(case):
    """T03, D04, K02, K03: ZeroDivisionError and OverflowError tracebacks from values each
    accepted alone (theory --D 1e308 --tau 1e-308, reduced --tau 1e-300, scaling --n 1e400)."""
    args, names = {
        "T03": (["theory", "--D", "1e308", "--tau", "1e-308"], "--D --tau"),
        "D04": (["reduced", "--tau", "1e-300", "--paths", "100", "--t-max", "10"], "--tau --paths --t-max"),
        "K02": (["scaling", "--n", "1e1000"], "--n"),
        "K03": (["scaling", "--n", "1e400"], "--n"),
    }[case]
    proc = subprocess.run(_cmd(*args), capture_output=True, text=True, env=_env(), timeout=120)
    assert proc.returncode == 2, proc.stderr
    line = _one_line(proc.stderr)
    if case in ("K02", "K03"):  # scaling states its range, [2, 1000], before any arithmetic
        assert line.startswith("error: --n 1000") and "is not accepted: an integer in [2, 1000]" in line, line
        assert len(line) < 200, line
        return
    assert line.startswith(f"error: the values of {names} are not accepted: a result lies beyond the "
                           "floating-point range"), line


def test_bfpe_that_cannot_fit_under_ulimit_is_refused_before_work(tmp_path):
    """B08: under `ulimit -v 3000000` bfpe --n-cells 1e6 --n-times 1000 (8 GB of laws) failed
    after 44 s with a MemoryError traceback."""
    cmd = " ".join(f"'{a}'" for a in _cmd("bfpe", "--n-cells", "1e6", "--n-times", "1000", "--t-max", "10",
                                          "--quiet", "--out", str(tmp_path / "b8.nc")))
    proc = subprocess.run(["sh", "-c", f"ulimit -v 3000000; {cmd}"], capture_output=True, text=True,
                          env=_env(), timeout=120)
    assert proc.returncode == 2, proc.stderr
    line = _one_line(proc.stderr)
    assert line.startswith("error: --n-times 1000 is not accepted: the solve keeps n_times x n_cells = 1000 x "
                           "1000000 laws, 7.6 GiB in all, more than the "), line
    assert list(tmp_path.iterdir()) == []


def test_resume_checks_the_work_before_any(tmp_path, handed_over):
    """S27: a checkpoint with t_max = 1e300 (configuration hash recomputed) was resumed with no
    work check, and ran until killed."""
    def edit(text: str) -> str:
        header = json.loads(text)
        header["config"]["t_max"] = 1e300
        header["config_sha256"] = ck.config_hash(ck.config_from_json(header["config"]))
        return json.dumps(header)

    path = _crafted_raw(handed_over, tmp_path / "c.ckpt", edit)
    result = _invoke_before_work(["resume", str(path), "--out", str(tmp_path / "o.nc")])
    assert result.exit_code == 2, result.output
    line = _one_line(result.output)
    assert line.startswith("error: t_max=1e+300 is not accepted: the run needs at least ") and \
        "--max-path-steps" in line, line


def test_a_long_reduced_run_says_its_estimate_before_it_starts():
    """D02: `reduced --paths 1e9` (about 25 min) started with no 'estimate:' line, unlike
    simulate. The line comes first; the run is then stopped."""
    proc = subprocess.Popen(_cmd("reduced", "--order", "first", "--paths", "1e9", "--t-max", "10", "--quiet"),
                            stderr=subprocess.PIPE, text=True, env=_env())
    try:
        first = proc.stderr.readline()
    finally:
        proc.kill()
        proc.communicate(timeout=60)
    assert first.startswith("estimate: at least 4e+10 path-steps (paths x output times), roughly "), first


# -- issue 36: checked before the work, printed commands that work, the hostile residue -----------
def test_an_unwritable_pseudo_filesystem_out_is_refused_before_any_work(tmp_path):
    """G4: --out /sys/x.nc (root may "write" there by its permission bits) ran the whole
    simulation, then lost it: 'cannot write ... Permission denied'."""
    if not Path("/sys").is_dir():
        pytest.skip("no /sys here")
    for command in (["simulate", *TINY, "--bias-paths", "0", "--quiet"], ["bfpe", "--t-max", "10"],
                    ["reduced", "--paths", "100", "--t-max", "1"]):
        result = _invoke([*command, "--out", "/sys/x.nc"])
        assert result.exit_code == 2, result.output
        line = _one_line(result.output)
        assert "a file cannot be created in the directory '/sys'" in line, line
    result = _invoke(["reproduce", "fig1", "--quick", "--out", "/sys/repro"])
    assert result.exit_code == 2, result.output
    assert "--out '/sys/repro' is not accepted" in _one_line(result.output)


def test_a_long_bfpe_solve_says_so_before_it_starts(tmp_path):
    """B01: 'bfpe --n-cells 1e7 --t-max 10' (accepted: about 6e9 cell-steps) printed nothing in
    40 s, with or without --quiet. Its estimate is the first line, before the solve allocates."""
    from stochpend.runs import resources

    if resources.available_memory() < 6 * 2**30:
        pytest.skip("the solve needs 4.8 GiB: refused here before any estimate")
    for quiet in ([], ["--quiet"]):
        line = _first_line(["bfpe", "--n-cells", "1e7", "--t-max", "10", *quiet, "--out", "b.nc"], tmp_path, 60)
        assert line.startswith("estimate: about 6.4e+09 cell-steps (n_cells x time steps = 10000000 x 640), "
                               "roughly "), line
    assert list(tmp_path.iterdir()) == []


def test_a_sweep_of_many_tiny_sets_says_what_it_will_cost(tmp_path):
    """NEW03: a grid of 99 999 sets of 2 paths (under the set and the size caps) passed the work
    check with its 2e5 path-steps and printed nothing in the hour it would take: each set's own
    cost (its tasks, statistics, bias estimate) was not counted. 20 000 sets: a minute at least."""
    values = ", ".join(f"{1 + i * 1e-5:.5f}" for i in range(20_000))
    (tmp_path / "g.toml").write_text(f"[base]\npaths = 2\nt_max = 0.05\nn_times = 1\n[grid]\nD = [{values}]\n")
    line = _first_line(["sweep", "g.toml", "--out", "g.nc"], tmp_path, 120)
    assert line.startswith("estimate: 20000 parameter sets, at least 4e+04 path-steps"), line
    assert "~3 ms a set" in line, line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.toml"]


def test_a_name_whose_temporary_name_is_too_long_is_refused_before_any_work(tmp_path):
    """NEW27, NEW30c: a valid 242-byte --out (or 244-byte --checkpoint) name was refused only
    when written: the temporary '.NAME.XXXXXXXX.tmp' is 14 bytes longer than NAME_MAX allows."""
    long_out, long_ckpt = "e" * 239 + ".nc", "k" * 239 + ".ckpt"
    for args, name in ((["--out", long_out], "--out"), (["--checkpoint", long_ckpt], "--checkpoint")):
        result = _invoke(["simulate", *TINY, "--bias-paths", "0", "--quiet", *args])
        assert result.exit_code == 2, result.output
        line = _one_line(result.output)
        assert line.startswith(f"error: {name} ") and "temporary name 14 bytes longer" in line, line
        assert "choose a name of at most 241 bytes" in line, line
    assert not list(Path.cwd().glob(".eee*")) and not list(Path.cwd().glob(".kkk*"))
    ok = tmp_path / ("e" * 238 + ".nc")  # 241 bytes: written
    result = _invoke(["simulate", *TINY, "--bias-paths", "0", "--quiet", "--out", str(ok)])
    assert result.exit_code == 0, result.output and ok.is_file()


def test_a_nul_in_text_a_result_would_store_is_refused_before_any_work(tmp_path):
    """NEW31a: a sweep description "fig\\u0000draft" ran the sweep, then 'VLEN strings do not
    support embedded NULLs' (exit 2 after the work, naming neither file nor key)."""
    toml = tmp_path / "nul.toml"
    toml.write_text('description = "fig\\u0000draft"\n[base]\npaths = 100\nt_max = 1.0\nn_times = 2\n'
                    '[grid]\nD = [1.0]\n')
    result = _invoke_before_work(["sweep", str(toml), "--quiet", "--out", str(tmp_path / "nul.nc")])
    assert result.exit_code == 2, result.output
    assert "nul.toml: description is not accepted: it holds a NUL character" in _one_line(result.output)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nul.toml"]


def test_a_nul_in_a_checkpoints_command_line_is_refused_before_any_work(tmp_path, handed_over):
    """NEW35: a checkpoint's command_line with a NUL did the whole work, then failed to write
    ('embedded NULLs') and advised a resume that failed the same way for ever."""
    crafted = _crafted(handed_over, tmp_path / "nul.ckpt", command_line="stochpend\u0000simulate", out=None)
    result = _invoke_before_work(["resume", str(crafted), "--out", str(tmp_path / "nul.nc"), "--quiet"])
    assert result.exit_code == 2, result.output
    assert "malformed header: command_line='stochpend\\x00simulate'" in _one_line(result.output)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nul.ckpt"]


def test_resume_advice_names_out_when_it_is_in_another_directory(tmp_path):
    """NEW41, NEW65: after Ctrl-C of a run whose --checkpoint and --out are in different
    directories, 'continue with: stochpend resume ckdir/i.ckpt' was refused (exit 2). The
    advice printed is run as printed."""
    import shlex

    (tmp_path / "ck dir").mkdir()
    (tmp_path / "outdir").mkdir()
    lock = ck.lock_path(tmp_path / "ck dir" / "i.ckpt")
    # The lock is taken before the run listens for Ctrl-C: a Ctrl-C in between ends the run at
    # once with "(no new checkpoint)" and no advice, which is honest (nothing to resume yet).
    # The CI's loaded machine hit that window once (c4e8664); then the signal goes again, later.
    for delay in (0.0, 2.0, 5.0):
        a = _start(["simulate", *LONG, "--checkpoint", "ck dir/i.ckpt", "--checkpoint-every", "1h",
                    "--out", "outdir/i.nc", "--quiet"], tmp_path)
        _wait_for(lock, a)
        time.sleep(delay)
        a.send_signal(signal.SIGINT)
        _, err = a.communicate(timeout=120)
        assert a.returncode == 130, err
        if "continue with: " in err.splitlines()[-1]:
            break
        assert "(no new checkpoint)" in err and not (tmp_path / "ck dir" / "i.ckpt").exists(), err
    advice = err.splitlines()[-1].split("continue with: ", 1)[1]
    assert advice == "stochpend resume 'ck dir/i.ckpt' --out outdir/i.nc", advice
    args = shlex.split(advice)
    assert args[0] == "stochpend"
    r = _run(*args[1:], "--quiet", cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "outdir" / "i.nc").is_file() and not (tmp_path / "ck dir" / "i.ckpt").exists()
    assert ck.resume_advice("a/b.ckpt", "a/c.nc") == "stochpend resume a/b.ckpt"  # same directory: no --out


def test_resume_advice_after_a_failed_write_names_out_in_another_directory(tmp_path, monkeypatch):
    """NEW40: --out's file system went read-only at the final write of a run whose --checkpoint is
    in another directory: 'the finished run is kept in ...: `stochpend resume res/mid.ckpt` writes
    it', and that command (the file system writable again) was refused, the checkpoint naming an
    out outside its own directory. The advice printed is run as printed."""
    import errno
    import shlex

    (tmp_path / "res").mkdir()
    (tmp_path / "outdir").mkdir()
    ckpt, out = tmp_path / "res" / "mid.ckpt", tmp_path / "outdir" / "mid.nc"
    real = io.write_atomic

    def read_only(path, data, **kwargs):
        if Path(path).parent == out.parent:
            raise OSError(errno.EROFS, os.strerror(errno.EROFS), str(path))
        return real(path, data, **kwargs)

    monkeypatch.setattr(io, "write_atomic", read_only)
    result = _invoke(["simulate", *TINY, "--bias-paths", "0", "--quiet", "--checkpoint", str(ckpt), "--out", str(out)])
    assert result.exit_code == 1, result.output
    line = _one_line(result.output)
    assert "Read-only file system" in line and f"the finished run is kept in {str(ckpt)!r}: `" in line, line
    advice = line.split("`")[1]
    assert advice == f"stochpend resume {ckpt} --out {out}", line
    monkeypatch.setattr(io, "write_atomic", real)
    result = _invoke([*shlex.split(advice)[1:], "--quiet"])
    assert result.exit_code == 0, result.output
    io.open_results(out)
    assert not ckpt.exists()


@pytest.mark.parametrize("kind", ["hardlink", "fifo", "device", "other-owner"])
def test_a_planted_lock_file_is_refused_without_touching_it(tmp_path, kind):
    """NEW06: a hard link to a user's file planted at .NAME-lock had the file's content replaced
    by 'pid N on host ...'; NEW07, NEW08: a FIFO or a (character) device there gave 'error:
    [Errno 22] Invalid argument'. The lock is created exclusively, and an existing one is used
    only when it is a regular file with one link, owned by this user."""
    ckpt = tmp_path / "k.ckpt"
    lock = ck.lock_path(ckpt)
    notes = tmp_path / "notes.txt"
    notes.write_text("my precious notes\n")
    if kind == "hardlink":
        os.link(notes, lock)
        why = "is a file with 2 links"
    elif kind == "fifo":
        os.mkfifo(lock)
        why = "is a FIFO (named pipe)"
    elif kind == "device":
        try:
            os.mknod(lock, stat.S_IFCHR | 0o666, os.makedev(1, 3))  # /dev/null's numbers
        except PermissionError:
            pytest.skip("creating a device node needs root")
        why = "is a device, not a regular file"
    else:
        if os.geteuid() != 0:
            pytest.skip("giving a file to another user needs root")
        lock.write_text("")
        os.chown(lock, 12345, 12345)
        why = "is owned by another user (uid 12345)"
    with pytest.raises(ValueError) as info:
        with ck.owned(ckpt):
            pass
    assert f"its lock file {str(lock)!r} {why}" in str(info.value), info.value
    assert "it was not touched" in str(info.value)
    assert notes.read_text() == "my precious notes\n"
    assert os.path.lexists(lock)
    result = _invoke(["simulate", *TINY, "--bias-paths", "0", "--quiet", "--checkpoint", str(ckpt)])
    assert result.exit_code == 2, result.output
    assert why in _one_line(result.output)
    assert notes.read_text() == "my precious notes\n"


def test_a_lock_left_by_a_killed_run_is_still_taken(tmp_path):
    """A lock file a killed run left (regular, one link, ours) is the ordinary case: taken."""
    ckpt = tmp_path / "k.ckpt"
    ck.lock_path(ckpt).write_text("pid 1 on host gone")
    with ck.owned(ckpt):
        assert "pid " in ck.lock_path(ckpt).read_text()
    assert not ck.lock_path(ckpt).exists()


def test_a_sparse_results_file_is_refused_before_it_is_allocated(tmp_path):
    """NEW24, NEW25: a 2 GiB sparse NetCDF (94 KB on disk) passed the declared-size check, which
    compared with st_size: 27.6 s and 4.9 GB to read it; 8 GiB gave a MemoryError traceback.
    The check alone is called here (on the old code it let the file through to the read)."""
    import h5py

    ds = __import__("stochpend").simulate(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1, bias_paths=0)
    path = tmp_path / "sparse.nc"
    ds.to_netcdf(path, engine="h5netcdf")
    with h5py.File(path, "a") as f:
        f.create_dataset("junk", shape=(2**28,), dtype="f8")[-1] = 1.0
    assert path.stat().st_size > 2**31 and path.stat().st_blocks * 512 < 2**24  # sparse
    with pytest.raises(ValueError, match="it declares 2.15e\\+09 bytes of data in a file of"):
        io._check_hdf5(path)


def test_text_from_a_file_is_shortened_for_the_terminal(tmp_path):
    """NC09, NEW32, NEW60: a 20 MB attribute printed 256 426 lines; it is cut, its length said."""
    ds = __import__("stochpend").simulate(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1, bias_paths=0)
    ds.attrs["seed"] = "x" * 200_000
    path = io.to_netcdf(ds, tmp_path / "long.nc")
    result = _invoke(["show", str(path)])
    assert result.exit_code == 0, result.output
    assert "(200000 characters in all, shortened)" in " ".join(result.output.split())
    assert len(result.output) < 20_000


def test_a_long_sweep_description_is_shortened_for_the_terminal(tmp_path):
    """NEW32: a 1 MB sweep description (the TOML under its cap) printed 11 773 lines of the
    table's title."""
    (tmp_path / "d.toml").write_text(SWEEP.replace('"tiny"', '"' + "y" * 200_000 + '"'))
    result = _invoke(["sweep", str(tmp_path / "d.toml"), "--out", str(tmp_path / "d.nc")])
    assert result.exit_code == 0, result.output
    assert "(200000 characters in all, shortened)" in " ".join(result.output.split())
    assert len(result.output) < 20_000


def test_a_long_command_line_in_a_checkpoint_is_shortened_for_the_terminal(tmp_path, handed_over):
    """NEW60: a crafted checkpoint's 1 MB command_line made resume print a 1 000 083-byte
    'resuming ...' line (escaped, not shortened)."""
    crafted = _crafted(handed_over, tmp_path / "long.ckpt", command_line="stochpend " + "z" * 200_000, out=None)
    result = _invoke(["resume", str(crafted), "--out", str(tmp_path / "long.nc")])
    assert result.exit_code == 0, result.output[:2000]
    resuming = " ".join(result.output.split("resuming ", 1)[1].split("% done)", 1)[0].split())
    assert "(200010 characters in all, shortened)" in resuming and len(resuming) < 2000, resuming[:2000]
    assert (tmp_path / "long.nc").is_file()


def test_a_checkpoint_directory_removed_after_saves_says_the_checkpoint_is_gone(tmp_path):
    """F09b: the directory of the checkpoint removed after checkpoints were written: 'no
    checkpoint was written before', which was false."""
    gone = tmp_path / "gone"
    gone.mkdir()
    config = SimulationConfig.build(**SMALL)
    cp = ck.FileCheckpointer(gone / "x.ckpt", None, config=config, chunk_paths=90)
    saved = []

    def maybe_save(state):
        if not saved:
            saved.append(cp.save(state))
            shutil.rmtree(gone)
            cp.save(state)

    cp.maybe_save = maybe_save  # type: ignore[method-assign]
    with pytest.raises(io.WriteError) as info:
        ck.run_checkpointed(config, checkpoint_path=gone / "x.ckpt", every_s=None, checkpointer=cp,
                            chunk_paths=90, break_lock=True)
    text = str(info.value)
    assert "the checkpoint written before is gone too (its directory" in text, text
    assert "no checkpoint was written before" not in text


def test_stdout_on_a_full_device_names_standard_output(tmp_path, handed_over):
    """NEW20: '>/dev/full' gave 'error: [Errno 28] No space left on device', naming nothing."""
    if not Path("/dev/full").exists():
        pytest.skip("no /dev/full here")
    ds = __import__("stochpend").simulate(noise="ou", paths=64, t_max=1.0, n_times=2, seed=1, bias_paths=0)
    path = io.to_netcdf(ds, tmp_path / "r.nc")
    with open("/dev/full", "w") as full:
        r = subprocess.run(_cmd("show", str(path)), stdout=full, stderr=subprocess.PIPE, text=True,
                           cwd=tmp_path, env=_env(), timeout=300)
    assert r.returncode == 1, r.stderr
    assert _one_line(r.stderr) == ("error: cannot write the results to standard output: No space left on "
                                   "device (files the command wrote before this are complete)")
    with open("/dev/full", "w") as full:  # the report's command: its result is written, then the table
        r = subprocess.run(_cmd("simulate", *TINY, "--bias-paths", "0", "--out", "n20.nc"), stdout=full,
                           stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=_env(), timeout=300)
    assert r.returncode == 1, r.stderr
    assert _one_line(r.stderr) == ("error: cannot write the results to standard output: No space left on "
                                   "device (files the command wrote before this are complete)")
    io.open_results(tmp_path / "n20.nc")


def test_numba_disable_jit_is_one_line(tmp_path):
    """NEW23: NUMBA_DISABLE_JIT=1 gave a 71-line traceback ('<intrinsic _take> is not usable in
    pure-python'); commands that compile nothing still run. A fresh process: Numba reads the
    variable once, when it is imported."""
    env = {**_env(), "NUMBA_DISABLE_JIT": "1"}
    r = subprocess.run(_cmd("simulate", "--paths", "2", "--t-max", "0.1", "--n-times", "1", "--bias-paths", "0"),
                       capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert r.returncode == 2, r.stderr
    assert _one_line(r.stderr) == ("error: NUMBA_DISABLE_JIT='1' is not accepted: stochpend's kernels "
                                   "run only compiled (the environment variable; unset it or set it to 0)")
    r = subprocess.run(_cmd("scaling"), capture_output=True, text=True, cwd=tmp_path, env=env, timeout=300)
    assert r.returncode == 0, r.stderr


def test_a_config_file_setting_one_option_twice_is_refused(tmp_path):
    """CFG5: t_max = 1.0 and t-max = 2.0 in one --config file were accepted; 2.0 silently won."""
    config = tmp_path / "c.toml"
    config.write_text("t_max = 1.0\nt-max = 2.0\n")
    result = _invoke(["simulate", "--config", str(config), "--paths", "10", "--bias-paths", "0"])
    assert result.exit_code == 2, result.output
    assert _one_line(result.output) == ("error: c.toml: t-max is not accepted: the file also sets t_max, "
                                        "the same option; keep one of them")


def test_the_checkpoint_read_guard_covers_its_measured_peak(tmp_path, handed_over, monkeypatch):
    """S28: reading a checkpoint peaked at 2.59 times the file (tracemalloc), the guard assumed 2."""
    import tracemalloc

    from stochpend.runs import resources

    path = tmp_path / "run.ckpt"
    path.write_bytes(handed_over)
    size = path.stat().st_size
    tracemalloc.start()
    try:
        ck.read(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    # Less memory than the read was just measured to take: refused before reading (the guard
    # asked for 2 times the file, and let it through).
    monkeypatch.setattr(resources, "available_memory", lambda: peak - 1)
    with pytest.raises(ValueError, match="and reading it needs"):
        ck.read(path)
    assert peak <= ck.READ_PEAK * size, (peak, size)
    monkeypatch.setattr(resources, "available_memory", lambda: int(2.5 * size))
    with pytest.raises(ValueError, match="reading it needs 3 times that"):
        ck.read(path)


def test_a_checkpoint_swapped_for_a_symlink_mid_run_is_a_failure_not_bad_input(tmp_path):
    """NEW12: the checkpoint replaced by a symlink to a victim mid-run: the victim was kept, but
    the run stopped with exit 2 ('is not accepted'), the code of input refused before any work.
    Now a WriteError (exit 1) that says what appeared and that the earlier checkpoint is gone."""
    victim = tmp_path / "victim.txt"
    victim.write_text("keep me\n")
    path = tmp_path / "x.ckpt"
    config = SimulationConfig.build(**SMALL)
    cp = ck.FileCheckpointer(path, None, config=config, chunk_paths=90)
    saved = []

    def maybe_save(state):
        if not saved:
            saved.append(cp.save(state))
            path.unlink()
            path.symlink_to(victim)
            cp.save(state)

    cp.maybe_save = maybe_save  # type: ignore[method-assign]
    with pytest.raises(io.WriteError) as info:
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, checkpointer=cp, chunk_paths=90)
    text = str(info.value)
    assert text.startswith(f"cannot write the checkpoint {str(path)!r}: it is a symbolic link (it appeared "
                           "while this run worked); it was not replaced; the checkpoint written before is gone "
                           "too: the run is lost"), text
    assert victim.read_text() == "keep me\n" and path.is_symlink()


def test_a_signal_just_after_the_result_was_written_says_so(tmp_path, monkeypatch):
    """M17: SIGTERM once x.nc was in place: exit 143 with 'continue with: stochpend resume
    x.ckpt', which then refused ('the file exists'). The run is done: its checkpoint is removed
    as on success, and the line says the result is complete."""
    real = io.write_atomic

    def write_then_sigterm(path, data, **kwargs):
        written = real(path, data, **kwargs)
        os.kill(os.getpid(), signal.SIGTERM)
        return written

    monkeypatch.setattr(io, "write_atomic", write_then_sigterm)
    out = tmp_path / "x.nc"
    result = _invoke(["simulate", *TINY, "--quiet", "--checkpoint", str(tmp_path / "x.ckpt"), "--out", str(out)])
    assert result.exit_code == 128 + signal.SIGTERM, result.output
    assert _one_line(result.output) == (f"interrupted by signal 15 after the result was written: {out} is "
                                        "complete (its checkpoint is removed)")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.nc"]
    io.open_results(out)
