"""Nothing lost, nothing hangs, nothing crashes: the fault table, on every backend.

Each fault hits a real ``stochpend`` process (the command line, as a user runs it):

* kill -9, SIGTERM and Ctrl-C (SIGINT) in the middle of ``simulate --checkpoint F --out O``,
  then ``resume F``: the result equals an uninterrupted run bit for bit, on the CPU's
  SIMD lane driver (adaptive step, the default), its SIMD lock-step driver (fixed step) and the CUDA
  backend (in Numba's CUDA simulator);
* a crash in the middle of writing ``--out`` or a checkpoint: nothing partial at either path,
  and the run resumes exactly;
* two processes finishing on the same ``--out`` at the same instant: one complete file, and a
  one-line refusal (or, with ``--overwrite``, a complete overwrite);
* a full disk (ENOSPC), injected and, where user namespaces allow, on a real 600 KiB tmpfs:
  one line, exit code 1, the last good checkpoint intact and resumable;
* a Dask worker killed mid-sweep (CPU workers, and CUDA workers in the simulator): the same
  bits, Dask reruns the lost task.

Runs are small (seconds); the CPU ones use one thread so that a signal lands mid-run.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import xarray as xr
from typer.testing import CliRunner

import stochpend
from stochpend import cli, io
from stochpend.engine import cpu, integrator
from stochpend.model.settings import SimulationConfig
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run

HERE = Path(__file__).parent
HOOKS = HERE / "_fault_hooks.py"
DASK = HERE / "_fault_dask.py"
SRC = Path(stochpend.__file__).resolve().parents[1]


def _times(step: float, n: int) -> list[float]:
    return [round(step * (i + 1), 10) for i in range(n)]


#: backend name -> (SimulationConfig.build kwargs, extra CLI options, environment). Each run
#: lasts a few seconds after its first checkpoint, with a kernel boundary every few tenths.
BACKENDS = {
    # the default driver: adaptive steps on the SIMD lanes (each lane its own step; issue 13)
    "cpu-adaptive": (dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=4000, t_max=200.0,
                          times=_times(20.0, 10), seed=7), [], {}),
    # fixed step, OU pendulum, float64: the SIMD lock-step driver (asserted below)
    "cpu-lockstep": (dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=10000, t_max=600.0,
                          times=_times(60.0, 10), seed=7, step_c=0.0), [], {}),
    # the CUDA kernels in Numba's simulator (~1e3 path-steps/s: four paths)
    "cuda-sim": (dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=4, t_max=4.0,
                      times=_times(0.5, 8), seed=7, h_max=0.1),
                 ["--backend", "cuda"], {"NUMBA_ENABLE_CUDASIM": "1"}),
}


def _cli_args(kwargs: dict) -> list[str]:
    names = {"D": "--D", "tau": "--tau", "omega": "--omega", "paths": "--paths", "t_max": "--t-max",
             "seed": "--seed", "step_c": "--step-c", "h_max": "--h-max"}
    args = ["--noise", kwargs["noise"], "--times", ",".join(f"{t:g}" for t in kwargs["times"])]
    for key, flag in names.items():
        if key in kwargs:
            args += [flag, f"{kwargs[key]:g}" if isinstance(kwargs[key], float) else str(kwargs[key])]
    return args


def _env(extra: dict[str, str]) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    env["PYTHONPATH"] = os.pathsep.join([str(SRC), *filter(None, [env.get("PYTHONPATH")])])
    env.update(extra)
    return env


def _simulate_cmd(backend: str, ckpt: Path, out: Path, *, hook: list[str] | None = None,
                  config: dict | None = None, every: str = "0.1s",
                  extra: list[str] | None = None) -> tuple[list[str], dict]:
    kwargs, options, env = BACKENDS[backend]
    threads = [] if backend == "cuda-sim" else ["--threads", "1"]
    args = ["simulate", *_cli_args(config or kwargs), *options, *threads, "--checkpoint", str(ckpt),
            "--checkpoint-every", every, "--out", str(out), "--quiet", *(extra or [])]
    return [sys.executable, str(HOOKS), *(hook or ["none"]), "--", *args], _env(env)


def _start(backend: str, ckpt: Path, out: Path, **kw) -> subprocess.Popen:
    cmd, env = _simulate_cmd(backend, ckpt, out, **kw)
    return subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            cwd=ckpt.parent, env=env)


def _wait_for_checkpoint(proc: subprocess.Popen, ckpt: Path, timeout: float = 120) -> None:
    deadline = time.monotonic() + timeout
    while not ckpt.exists():
        if proc.poll() is not None:
            raise AssertionError(f"the run ended before its first checkpoint: {proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError(f"no checkpoint within {timeout} s")
        time.sleep(0.02)
    assert proc.poll() is None, "the run finished before it could be interrupted: make it longer"


def _resume(ckpt: Path, backend: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(HOOKS), "none", "--", "resume", str(ckpt), "--quiet", *args],
                          capture_output=True, text=True, cwd=ckpt.parent, timeout=300,
                          env=_env(BACKENDS[backend][2]))


def _fraction_done(saved: ck.Checkpoint) -> float:
    st, c = saved.state, saved.config
    return (st.done_work + float(np.sum(st.t))) / (c.paths * c.t_max)


def _assert_identical(ref: xr.Dataset, ds: xr.Dataset) -> None:
    """Every variable and coordinate, bit for bit (NaN where NaN), and the work done."""
    assert sorted(ref.variables) == sorted(ds.variables)
    for name in ref.variables:
        assert np.array_equal(ref[name].values, ds[name].values, equal_nan=ref[name].dtype.kind == "f"), name
    assert int(ds.attrs["path_steps"]) == int(ref.attrs["path_steps"])


def _one_line(text: str) -> str:
    # The start's "estimate:" line is not part of the error: a cold start prints it when this
    # machine's compile calibration (stochpend.numerics._calibration) expects over 10 s of compiling.
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("estimate: ")]
    assert len(lines) == 1, text
    assert "Traceback" not in text
    return lines[0]


@pytest.fixture(scope="module")
def references(tmp_path_factory):
    """The uninterrupted runs: in process on the CPU (all threads: the thread count must not
    matter), and the uninterrupted command on the CUDA simulator (a subprocess, started now)."""
    folder = tmp_path_factory.mktemp("reference")
    cuda_ckpt, cuda_out = folder / "ref.ckpt", folder / "ref.nc"
    proc = _start("cuda-sim", cuda_ckpt, cuda_out)
    refs = {name: run(SimulationConfig.build(**BACKENDS[name][0])) for name in ("cpu-adaptive", "cpu-lockstep")}
    _, err = proc.communicate(timeout=600)
    assert proc.returncode == 0, err
    refs["cuda-sim"] = io.open_results(cuda_out)
    assert refs["cuda-sim"].attrs["backend"] == "cuda"
    return refs


def test_the_backends_are_the_drivers_named():
    adaptive = cpu.spec_for(SimulationConfig.build(**BACKENDS["cpu-adaptive"][0]))
    lockstep = cpu.spec_for(SimulationConfig.build(**BACKENDS["cpu-lockstep"][0]))
    assert adaptive.adaptive and adaptive.fast_math and integrator.lanes_supported(adaptive)
    assert not lockstep.adaptive and lockstep.fast_math  # what selects the lock-step kernel


# -- signals mid-run, then resume ---------------------------------------------------------------
SIGNALS = {"kill-9": (signal.SIGKILL, -signal.SIGKILL), "sigterm": (signal.SIGTERM, 143),
           "sigint": (signal.SIGINT, 130)}


@pytest.mark.parametrize("fault", list(SIGNALS))
@pytest.mark.parametrize("backend", list(BACKENDS))
def test_signal_mid_run_then_resume_is_exact(tmp_path, references, backend, fault):
    if backend == "cuda-sim":
        pytest.importorskip("numba.cuda")
    signum, code = SIGNALS[fault]
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start(backend, ckpt, out)
    _wait_for_checkpoint(proc, ckpt)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == code, err
    assert "Traceback" not in err
    if signum != signal.SIGKILL:  # saved at the next kernel boundary, then a clean exit
        last = err.splitlines()[-1]
        assert last == f"interrupted: state saved to {ckpt}; continue with: stochpend resume {ckpt}", err
    assert not out.exists(), "an interrupted run wrote its result"
    # A run killed by SIGKILL cannot remove its lock file; the kernel released the lock itself,
    # and the resume below takes it over.
    lock = [ck.lock_path(ckpt).name] if signum == signal.SIGKILL else []
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(["run.ckpt", *lock]), \
        "a temporary file was left behind"
    saved = ck.read(ckpt)
    assert saved.state.backend == ("cuda" if backend == "cuda-sim" else "cpu")
    assert 0 < _fraction_done(saved) < 1, "the fault did not land mid-run"
    r = _resume(ckpt, backend)
    assert r.returncode == 0, r.stderr
    assert not ckpt.exists() and out.is_file()
    ds = io.open_results(out)
    _assert_identical(references[backend], ds)
    assert ds.attrs["resumed"] == 1


@pytest.mark.parametrize("gap_s", [0.0, 0.3])
def test_a_second_ctrl_c_still_saves_and_exits_130(tmp_path, references, gap_s):
    """I3: Ctrl-C, then Ctrl-C again 0.3 s later (an impatient user): the state is saved once,
    and the exit is 130 with the one line, never death by the signal or Click's 'Aborted!'."""
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start("cpu-adaptive", ckpt, out)
    _wait_for_checkpoint(proc, ckpt)
    proc.send_signal(signal.SIGINT)
    time.sleep(gap_s)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "Aborted" not in err
    assert err.splitlines()[-1].startswith("interrupted"), err
    r = _resume(ckpt, "cpu-adaptive")
    assert r.returncode == 0, r.stderr
    _assert_identical(references["cpu-adaptive"], io.open_results(out))


def test_a_ctrl_c_python_drops_still_saves_and_exits_130(tmp_path, references):
    """A Ctrl-C that lands in a weakref callback (the import system's module-lock callback, in a
    fresh-clone CI run at eced1d9) has its KeyboardInterrupt printed and dropped by Python; the
    run went on to its end and exited 0. Made to happen here just as the run starts listening
    for signals: the run saves at its first boundary, exits 130 advising the resume, and the
    resume gives the uninterrupted run's bits."""
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start("cpu-adaptive", ckpt, out, hook=["drop-sigint"], every="1h")
    _, err = proc.communicate(timeout=300)
    assert "Exception ignored" in err and "KeyboardInterrupt" in err, err  # the drop happened
    assert proc.returncode == 130, err
    assert "continue with: " in err.splitlines()[-1], err
    assert ckpt.is_file() and not out.exists()
    assert _fraction_done(ck.read(ckpt)) < 1
    r = _resume(ckpt, "cpu-adaptive")
    assert r.returncode == 0, r.stderr
    _assert_identical(references["cpu-adaptive"], io.open_results(out))


# -- crashes inside a write (the same code on every backend: io and checkpoint) -------------------
#: A run of a fraction of a second: these faults strike in the writes, not mid-run.
SMALL = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=20.0, times=_times(2.0, 10), seed=5)


@pytest.fixture(scope="module")
def small_reference():
    return run(SimulationConfig.build(**SMALL))


def test_kill_inside_the_final_write_leaves_nothing_at_out(tmp_path, small_reference):
    """SIGKILL with half the result written: --out does not exist; the run, saved at its last
    kernel boundary, resumes without recomputing and writes the exact result."""
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start("cpu-adaptive", ckpt, out, config=SMALL, every="1h", hook=["kill-in-out-write"])
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == -signal.SIGKILL, err
    assert not out.exists()
    partial = [p for p in tmp_path.iterdir() if p.name.startswith(".run.nc.")]
    assert len(partial) == 1, "the hook did not cut a write short"  # left by the kill, not at --out
    saved = ck.read(ckpt)
    assert _fraction_done(saved) == 1.0, "the finished run was not saved before the write"
    r = _resume(ckpt, "cpu-adaptive")
    assert r.returncode == 0, r.stderr
    _assert_identical(small_reference, io.open_results(out))


def test_kill_inside_a_checkpoint_write_keeps_the_previous_one(tmp_path, small_reference):
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start("cpu-adaptive", ckpt, out, config=SMALL, every="0.001s",
                  hook=["kill-in-checkpoint-write", "3"])
    _, err = proc.communicate(timeout=300)
    assert proc.returncode == -signal.SIGKILL, err
    assert len([p for p in tmp_path.iterdir() if p.name.startswith(".run.ckpt.")]) == 1  # the cut one
    saved = ck.read(ckpt)  # the second checkpoint, whole (its checksum is verified)
    assert 0 < _fraction_done(saved) < 1
    r = _resume(ckpt, "cpu-adaptive")
    assert r.returncode == 0, r.stderr
    _assert_identical(small_reference, io.open_results(out))


# -- two processes, one --out -------------------------------------------------------------------
@pytest.fixture(scope="module")
def seed_references():
    return {seed: run(SimulationConfig.build(**{**SMALL, "seed": seed})) for seed in (11, 12)}


@pytest.mark.parametrize("overwrite", [False, True])
def test_two_runs_finishing_on_one_out(tmp_path, seed_references, overwrite):
    """Both runs pass the up-front check, compute, and put their result in place at the same
    instant (a barrier after each has written its temporary file)."""
    barrier = tmp_path / "barrier"
    barrier.mkdir()
    out = tmp_path / "run.nc"
    extra = ["--overwrite"] if overwrite else []
    procs = {seed: _start("cpu-adaptive", tmp_path / f"run{seed}.ckpt", out, config={**SMALL, "seed": seed},
                          extra=extra, hook=["barrier", str(barrier)]) for seed in (11, 12)}
    results = {seed: (p.communicate(timeout=300), p.returncode) for seed, p in procs.items()}
    assert len(list(barrier.iterdir())) == 2, results  # both reached the write
    codes = sorted(code for _, code in results.values())
    ds = io.open_results(out)  # one complete, valid file
    winners = [seed for seed, ref in seed_references.items() if ds.attrs["seed"] == seed]
    assert len(winners) == 1
    _assert_identical(seed_references[winners[0]], ds)
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".run.nc.")]
    if overwrite:
        assert codes == [0, 0], results
        return
    assert codes == [0, 2], results
    loser = next(seed for seed, (_, code) in results.items() if code == 2)
    assert loser != winners[0]
    line = _one_line(results[loser][0][1])
    ckpt = tmp_path / f"run{loser}.ckpt"
    assert line == (f"error: --out {str(out)!r} is not accepted: the file exists (another process wrote it "
                    f"while this one ran; pass --overwrite to replace it); the finished run is kept in "
                    f"{str(ckpt)!r}: `stochpend resume {ckpt}` writes it (add --out FILE to write it "
                    "elsewhere)"), line
    elsewhere = tmp_path / "elsewhere.nc"
    r = _resume(ckpt, "cpu-adaptive", "--out", str(elsewhere))
    assert r.returncode == 0, r.stderr
    _assert_identical(seed_references[loser], io.open_results(elsewhere))


# -- a full disk --------------------------------------------------------------------------------
def _no_space(*_args, **_kwargs):
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def _full_disk_after(monkeypatch, budget: int) -> None:
    """Every file written through stochpend.files._files gets ``budget`` more bytes, then ENOSPC
    (the bytes before it really reach the temporary file)."""
    from stochpend.files import _files

    real, left = _files.write_all, [budget]

    def write_all(fd, data):
        view = memoryview(data).cast("B")
        if len(view) > left[0]:
            real(fd, view[: left[0]])
            left[0] = 0
            _no_space()
        left[0] -= len(view)
        real(fd, view)

    monkeypatch.setattr(_files, "write_all", write_all)


def _small_cli(tmp_path) -> tuple[list[str], Path, Path]:
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    args = ["simulate", *_cli_args(SMALL), "--checkpoint", str(ckpt), "--checkpoint-every", "0.001s",
            "--out", str(out), "--quiet"]
    return args, ckpt, out


def test_full_disk_during_a_checkpoint_write(tmp_path, monkeypatch, small_reference):
    """The third checkpoint write runs out of space half-way: one line, exit code 1, the
    second checkpoint intact (byte for byte) and resumable to the exact result."""
    args, ckpt, out = _small_cli(tmp_path)
    calls, before = [0], {}
    real_write = ck.write

    def write(path, c):
        calls[0] += 1
        if calls[0] == 3:
            before["bytes"] = Path(path).read_bytes()
            with monkeypatch.context() as m:
                _full_disk_after(m, 4096)
                return real_write(path, c)
        return real_write(path, c)

    monkeypatch.setattr(ck, "write", write)
    result = CliRunner().invoke(cli.app, args)
    assert result.exit_code == 1, result.output
    assert not isinstance(result.exception, OSError)
    line = _one_line(result.output)
    assert line == (f"error: cannot write the checkpoint {str(ckpt)!r}: No space left on device; the "
                    f"previous checkpoint is kept: continue with `stochpend resume {ckpt}` once the cause "
                    "is fixed"), line
    assert calls[0] == 3 and ckpt.read_bytes() == before["bytes"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.ckpt"]  # no partial file, no result
    monkeypatch.setattr(ck, "write", real_write)
    assert 0 < _fraction_done(ck.read(ckpt)) < 1
    result = CliRunner().invoke(cli.app, ["resume", str(ckpt), "--quiet"])
    assert result.exit_code == 0, result.output
    _assert_identical(small_reference, io.open_results(out))


def test_full_disk_at_the_first_checkpoint_says_none_was_kept(tmp_path, monkeypatch):
    args, ckpt, out = _small_cli(tmp_path)
    monkeypatch.setattr(os, "fsync", _no_space)
    result = CliRunner().invoke(cli.app, args)
    assert result.exit_code == 1
    line = _one_line(result.output)
    assert line == (f"error: cannot write the checkpoint {str(ckpt)!r}: No space left on device; no "
                    "checkpoint was written before"), line
    assert list(tmp_path.iterdir()) == []


def test_full_disk_during_the_final_write(tmp_path, monkeypatch, small_reference):
    """--out cannot be written: one line, exit code 1, nothing at --out, the finished run kept."""
    args, ckpt, out = _small_cli(tmp_path)
    real = io.write_atomic

    def half_then_full(path, data, **kwargs):
        with monkeypatch.context() as m:
            _full_disk_after(m, len(memoryview(data).cast("B")) // 2)
            return real(path, data, **kwargs)

    monkeypatch.setattr(io, "write_atomic", half_then_full)
    result = CliRunner().invoke(cli.app, args)
    assert result.exit_code == 1, result.output
    line = _one_line(result.output)
    assert line == (f"error: cannot write out={str(out)!r}: No space left on device; nothing was written "
                    f"there; the finished run is kept in {str(ckpt)!r}: `stochpend resume {ckpt}` writes it "
                    "(add --out FILE to write it elsewhere)"), line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.ckpt"]
    assert _fraction_done(ck.read(ckpt)) == 1.0
    monkeypatch.setattr(io, "write_atomic", real)
    result = CliRunner().invoke(cli.app, ["resume", str(ckpt), "--quiet"])
    assert result.exit_code == 0, result.output
    _assert_identical(small_reference, io.open_results(out))


def test_full_disk_without_a_checkpoint(tmp_path, monkeypatch):
    out = tmp_path / "run.nc"
    _full_disk_after(monkeypatch, 1000)
    result = CliRunner().invoke(cli.app, ["simulate", "--paths", "20", "--t-max", "1", "--n-times", "2",
                                          "--bias-paths", "0", "--out", str(out), "--quiet"])
    assert result.exit_code == 1
    assert _one_line(result.output) == (f"error: cannot write out={str(out)!r}: No space left on device; "
                                        "nothing was written there")
    assert list(tmp_path.iterdir()) == []


def _user_namespaces() -> bool:
    if shutil.which("unshare") is None:
        return False
    r = subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "true"], capture_output=True)
    return r.returncode == 0


@pytest.mark.skipif(not _user_namespaces(), reason="needs unprivileged user namespaces to mount a tmpfs")
def test_real_full_disk_on_a_tiny_tmpfs(tmp_path, references):
    """A 600 KiB tmpfs holds one checkpoint (~390 KB) but not a second beside it: the second
    write fails with a real ENOSPC. Then the tmpfs is enlarged and the run resumed."""
    disk, saved = tmp_path / "disk", tmp_path / "saved"
    disk.mkdir()
    saved.mkdir()
    cmd, env = _simulate_cmd("cpu-adaptive", disk / "run.ckpt", disk / "run.nc")
    resume = [sys.executable, str(HOOKS), "none", "--", "resume", str(disk / "run.ckpt"), "--quiet"]
    script = "\n".join([
        f"mount -t tmpfs -o size=600k tmpfs {disk}",
        f"cd {disk}",
        " ".join(f"'{a}'" for a in cmd) + f" 2> {saved}/err1; echo $? > {saved}/rc1",
        f"ls -A {disk} > {saved}/listing",
        f"cp {disk}/run.ckpt {saved}/ 2>/dev/null",
        f"mount -o remount,size=20m {disk}",
        " ".join(f"'{a}'" for a in resume) + f" 2> {saved}/err2; echo $? > {saved}/rc2",
        f"cp {disk}/run.nc {saved}/ 2>/dev/null",
        "true",
    ])
    subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", script], env=env,
                   timeout=600, check=True)
    err1 = (saved / "err1").read_text()
    assert (saved / "rc1").read_text().strip() == "1", err1
    ckpt = disk / "run.ckpt"
    assert _one_line(err1) == (f"error: cannot write the checkpoint {str(ckpt)!r}: No space left on device; "
                               f"the previous checkpoint is kept: continue with `stochpend resume {ckpt}` once "
                               "the cause is fixed")
    assert (saved / "listing").read_text().split() == ["run.ckpt"]  # no partial file, no result
    assert 0 < _fraction_done(ck.read(saved / "run.ckpt")) < 1
    assert (saved / "rc2").read_text().strip() == "0", (saved / "err2").read_text()
    _assert_identical(references["cpu-adaptive"], io.open_results(saved / "run.nc"))


# -- a Dask worker lost mid-sweep ---------------------------------------------------------------
@pytest.mark.dask
# The CUDA-simulator variant passed with a warm kernel cache (8 min 43 s suite) but ran past its
# helper's 240 s watchdog in a fresh clone's cold cache on 2026-11-25, leaving a Dask worker
# holding the pipes: moved to the slow suite until that is understood (closing note).
@pytest.mark.parametrize("backend", ["cpu", pytest.param("cuda", marks=pytest.mark.slow)])
def test_worker_killed_mid_sweep_changes_nothing(tmp_path, backend):
    pytest.importorskip("distributed", reason="the `dask` extra is not installed")
    report_path = tmp_path / "report.json"
    env = _env({"NUMBA_ENABLE_CUDASIM": "1"} if backend == "cuda" else {})
    r = subprocess.run([sys.executable, str(DASK), backend, str(report_path)], capture_output=True,
                       text=True, timeout=400, env=env, cwd=tmp_path)
    assert r.returncode == 0, r.stderr[-6000:]  # after 240 s the helper dumps its stacks and exits
    report = json.loads(report_path.read_text())
    assert report["backend"] == backend
    assert report["killed"], "no worker was killed"
    assert report["victim"] in report["workers_before"] and report["victim"] not in report["workers_after"]
    assert len(report["workers_after"]) == 2  # the nanny restarted it
    assert report["tasks_started"] > report["n_tasks"], "the lost task was not run again"
    assert report["same_variables"] and report["different"] == [], report
