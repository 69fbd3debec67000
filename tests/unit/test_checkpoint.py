"""Checkpoint and resume: exact continuation, refusal of damaged files, Ctrl-C, SIGKILL."""

from __future__ import annotations

import hashlib
import json
import os
import signal
import struct
import subprocess
import sys
import time

import numpy as np
import pytest
from typer.testing import CliRunner

from stochpend import cli, io
from stochpend.cli._scale import (
    parse_duration,
    resume_command,
    simulate_with_checkpoint,
    sweep_command,
)
from stochpend.model.settings import SimulationConfig
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run, simulate
from stochpend.text.progress import NoProgress
from tests._checkpoints import StopAfter

SMALL = {"noise": "ou", "D": 1.0, "tau": 1.0, "omega": 1.0, "paths": 300, "t_max": 20.0, "n_times": 6, "seed": 5}
CHUNK = 90  # paths per chunk: 30 batches of 3, so the run has 4 chunks


def _assert_identical(a, b):
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.variables:
        assert np.array_equal(a[name].values, b[name].values, equal_nan=a[name].dtype.kind == "f"), name


@pytest.fixture(scope="module")
def small():
    config = SimulationConfig.build(**SMALL)
    return config, run(config, chunk_paths=CHUNK)


def _interrupted(tmp_path, config, n, name="run.ckpt", out=None, chunk=CHUNK, **settings):
    path = tmp_path / name
    cp = StopAfter(path, None, config=config, n=n, out=out, chunk_paths=chunk)
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, checkpointer=cp, chunk_paths=chunk,
                            out=out, **settings)
    assert path.is_file()
    return path


@pytest.mark.parametrize("n", [1, 4, 9, 17, 25])
def test_interrupt_then_resume_is_exact(tmp_path, small, n):
    config, ref = small
    out = tmp_path / "result.nc"
    path = _interrupted(tmp_path, config, n, out=out)
    state = ck.read(path).state
    assert state.stop_batch == config.n_batches
    ds = ck.resume(path)
    _assert_identical(ref, ds)
    assert ds.attrs["path_steps"] == ref.attrs["path_steps"]
    assert ds.attrs["resumed"] == 1
    assert ds.attrs["kernel"] == ref.attrs["kernel"] and ds.attrs["precision"] == "float64"
    assert not path.exists(), "a finished run removes its checkpoint"
    _assert_identical(ref, io.open_results(out))


#: Attributes that time a run or name its checkpoint: the only ones a checkpointed run may
#: differ in from the same run by stochpend.runs.simulate.run.
_TIMING = {"wall_time_s", "simulation_wall_time_s", "compile_time_s", "path_steps_per_s", "bias_wall_time_s",
           "created", "checkpoint", "checkpoint_every_s", "resumed"}


def _assert_same_run(ref, ds):
    _assert_identical(ref, ds)
    for key in (set(ref.attrs) | set(ds.attrs)) - _TIMING:
        assert key in ref.attrs and key in ds.attrs, key
        assert np.array_equal(ref.attrs[key], ds.attrs[key], equal_nan=isinstance(ref.attrs[key], float)), key


def test_checkpointed_bias_paths_equals_simulate(tmp_path, small):
    """bias_paths is the run's, checkpointed or not, and a resume keeps it (saved in the file)."""
    config, _ = small
    ref = run(config, chunk_paths=CHUNK, bias_paths=100)
    ds = ck.run_checkpointed(config, checkpoint_path=tmp_path / "a.ckpt", every_s=None, chunk_paths=CHUNK,
                             bias_paths=100)
    assert ds.attrs["bias_paths"] == 100 != ck.bias.default_bias_paths(config.paths)
    _assert_same_run(ref, ds)
    path = _interrupted(tmp_path, config, 6, bias_paths=100)
    assert ck.read(path).bias_paths == 100
    _assert_same_run(ref, ck.resume(path))
    # none at all: 0 is recorded and kept as well
    path = _interrupted(tmp_path, config, 6, name="none.ckpt", bias_paths=0)
    resumed = ck.resume(path)
    assert "mean_E_bias" not in resumed
    _assert_same_run(run(config, chunk_paths=CHUNK, bias_paths=0), resumed)


AUTO = {"noise": "ou", "paths": 1000, "t_max": 10.0, "times": (5.0, 10.0), "seed": 3, "h_max": 0.4, "step_c": 0.8}


@pytest.fixture(scope="module")
def auto_reference():
    config = SimulationConfig.build(**AUTO)
    ref = run(config, chunk_paths=300, accuracy="auto", bias_paths=256)
    assert ref.attrs["accuracy_level"] >= 1  # the refined configuration is what runs and resumes
    return config, ref


def test_checkpointed_auto_run_interrupted_and_resumed_equals_the_auto_run(tmp_path, auto_reference, monkeypatch):
    config, ref = auto_reference
    path = _interrupted(tmp_path, config, 5, chunk=300, accuracy="auto", bias_paths=256)
    saved = ck.read(path)
    assert saved.choice is not None and saved.choice.level == ref.attrs["accuracy_level"]
    assert saved.config.h_max == ref.attrs["h_max"] and saved.bias_paths == 256

    def no_pilot(*args, **kwargs):
        raise AssertionError("the resumed run ran its pilot again")

    monkeypatch.setattr(ck.bias, "choose_level", no_pilot)
    monkeypatch.setattr(ck.bias, "estimate", no_pilot)
    ds = ck.resume(path)
    assert ds.attrs["resumed"] == 1 and not path.exists()
    _assert_same_run(ref, ds)


def test_auto_checkpoint_with_another_level_is_refused(tmp_path, auto_reference):
    config, _ = auto_reference
    path = _interrupted(tmp_path, config, 3, chunk=300, accuracy="auto", bias_paths=256)
    header, payload = _split(path.read_bytes())
    header["accuracy"]["level"] += 1
    _rewrite(path, header, payload)
    _refused(path, "malformed header: accuracy.level=")
    header["accuracy"]["level"] -= 1
    header["accuracy"]["pilot_batches"] = "32"
    _rewrite(path, header, payload)
    _refused(path, "malformed header: accuracy=")


def test_old_checkpoint_resumes_with_the_default_pairs(good, small):
    """A header without bias_paths and accuracy (written before they were recorded)."""
    config, ref = small
    header, payload = _split(good.read_bytes())
    del header["bias_paths"], header["accuracy"]
    _rewrite(good, header, payload)
    assert ck.read(good).bias_paths is None
    _assert_same_run(ref, ck.resume(good))


def test_resume_twice(tmp_path, small):
    config, ref = small
    path = _interrupted(tmp_path, config, 3)
    first = ck.read(path)
    position = (first.state.b0, first.state.j)
    cp = StopAfter(path, None, config=config, n=6, chunk_paths=CHUNK, resumed=1)
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, checkpointer=cp, chunk_paths=CHUNK,
                            _resume=first)
    second = ck.read(path)
    assert (second.state.b0, second.state.j) != position
    _assert_identical(ref, ck.resume(path))


def test_sigint_is_deferred_to_a_kernel_boundary(tmp_path, small):
    """A real SIGINT in the middle of a run: saved at the next boundary, then resumed exactly."""
    config, ref = small

    class SignalOnThird(ck.FileCheckpointer):
        calls = 0

        def maybe_save(self, state):
            self.calls += 1
            if self.calls == 3:
                os.kill(os.getpid(), signal.SIGINT)  # handled before the next bytecode
                assert self.stop_requested
            super().maybe_save(state)

    path = tmp_path / "run.ckpt"
    cp = SignalOnThird(path, 3600.0, config=config, chunk_paths=CHUNK)
    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(ck.CheckpointInterrupt) as info:
        ck.run_checkpointed(config, checkpoint_path=path, every_s=3600.0, checkpointer=cp, chunk_paths=CHUNK)
    assert signal.getsignal(signal.SIGINT) is before
    assert info.value.path == path and cp.saves == 1
    _assert_identical(ref, ck.resume(path))


def test_ignored_sigint_stays_ignored(tmp_path, small):
    """A run started with SIGINT ignored (a background job) is not stopped by it."""
    config, ref = small

    class SignalOnce(ck.FileCheckpointer):
        def maybe_save(self, state):
            if self.saves == 0:
                os.kill(os.getpid(), signal.SIGINT)
            self.saves += 1
            super().maybe_save(state)

    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        cp = SignalOnce(tmp_path / "run.ckpt", None, config=config, chunk_paths=CHUNK)
        ds = ck.run_checkpointed(config, checkpoint_path=cp.path, every_s=None, checkpointer=cp,
                                 chunk_paths=CHUNK)
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
    _assert_identical(ref, ds)


def test_periodic_saves(tmp_path, small):
    config, ref = small
    path = tmp_path / "run.ckpt"
    cp = ck.FileCheckpointer(path, 0.0, config=config, chunk_paths=CHUNK)
    ds = ck.run_checkpointed(config, checkpoint_path=path, every_s=0.0, checkpointer=cp, chunk_paths=CHUNK)
    assert cp.saves > 5 and not path.exists()
    _assert_identical(ref, ds)
    assert not list(tmp_path.iterdir()), "no temporary files left behind"


# -- damaged or foreign checkpoints ----------------------------------------------------------
@pytest.fixture
def good(tmp_path, small):
    config, _ = small
    return _interrupted(tmp_path, config, 4)


def _split(data: bytes):
    n = len(ck.MAGIC)
    (head_len,) = struct.unpack_from("<Q", data, n)
    start = n + 8
    return json.loads(data[start:start + head_len]), data[start + head_len:-32]


def _rewrite(path, header, payload):
    head = json.dumps(header).encode()
    body = ck.MAGIC + struct.pack("<Q", len(head)) + head + payload
    path.write_bytes(body + hashlib.sha256(body).digest())


def _refused(path, needle, *, read=True):
    """Refused in one line by ``read`` (and so by ``resume``); ``read=False``: by ``resume``, which
    may find it only as it replays a target run's rounds."""
    with pytest.raises(ValueError) as info:
        (ck.read if read else ck.resume)(path)
    message = str(info.value)
    assert message.startswith(f"checkpoint={str(path)!r} is not accepted: ") and needle in message, message
    assert "\n" not in message
    with pytest.raises(ValueError, match="is not accepted"):
        ck.resume(path)


@pytest.mark.parametrize("keep", [0, 5, 16, 100, 0.5, -1])
def test_truncated_is_refused(good, keep):
    data = good.read_bytes()
    cut = int(len(data) * keep) if isinstance(keep, float) else (len(data) + keep if keep < 0 else keep)
    good.write_bytes(data[:cut])
    _refused(good, "truncated" if cut >= 5 or cut == 0 else "not a stochpend checkpoint")


@pytest.mark.parametrize("where", [20, 0.3, 0.7, -1])
def test_corrupted_is_refused(good, where):
    data = bytearray(good.read_bytes())
    i = int(len(data) * where) if isinstance(where, float) else (len(data) + where if where < 0 else where)
    data[i] ^= 0x01
    good.write_bytes(bytes(data))
    _refused(good, "checksum mismatch: the file is truncated or corrupted")


def test_not_a_checkpoint(tmp_path):
    p = tmp_path / "x.ckpt"
    p.write_bytes(b"PK\x03\x04" + b"\x00" * 200)
    _refused(p, "not a stochpend checkpoint")
    _refused(tmp_path / "missing.ckpt", "no such file")


def test_other_version_is_refused(good):
    header, payload = _split(good.read_bytes())
    header["stochpend_version"] = "0.0.1"
    _rewrite(good, header, payload)
    _refused(good, "written by stochpend 0.0.1, this is stochpend")


def test_backend_and_precision_are_recorded_and_checked(good, monkeypatch):
    header, payload = _split(good.read_bytes())
    assert (header["backend"], header["precision"]) == ("cpu", "float64")
    header["backend"] = "tpu"
    _rewrite(good, header, payload)
    _refused(good, "unknown backend 'tpu'")


def test_gpu_checkpoint_without_a_usable_gpu_is_one_line(good, monkeypatch):
    """A GPU run resumes on the GPU; where none is usable, resume says so in one line."""
    from stochpend.engine import cuda as gpu

    monkeypatch.setattr(gpu, "availability", lambda: (False, "the CUDA driver reports no GPU"))
    header, payload = _split(good.read_bytes())
    header["backend"] = "cuda"
    _rewrite(good, header, payload)
    assert ck.read(good).state.backend == "cuda"
    with pytest.raises(ValueError) as info:
        ck.resume(good)
    message = str(info.value)
    assert message.startswith(f"checkpoint={str(good)!r} is not accepted: it ran on backend='cuda'")
    assert "the CUDA driver reports no GPU" in message and "\n" not in message


def test_other_build_is_refused(good):
    header, payload = _split(good.read_bytes())
    header["stochpend_build"] = header["stochpend_version"] + " (code 000000000000)"
    _rewrite(good, header, payload)
    _refused(good, "(code 000000000000), this is stochpend")
    _refused(good, "the code that determines the numbers differs")


def test_config_hash_mismatch_is_refused(good):
    header, payload = _split(good.read_bytes())
    header["config"]["D"] = 2.0
    _rewrite(good, header, payload)
    _refused(good, "configuration hash mismatch")


def test_invalid_config_is_refused(good):
    header, payload = _split(good.read_bytes())
    header["config"]["tau"] = -1.0
    _rewrite(good, header, payload)
    _refused(good, "its configuration no longer validates (tau=-1.0 is not accepted")


def test_inconsistent_arrays_are_refused(good):
    header, payload = _split(good.read_bytes())
    header["arrays"][0]["dtype"] = "|O"
    _rewrite(good, header, payload)
    _refused(good, "array 'x' has dtype |O")
    header["arrays"][0]["dtype"] = "<f8"
    header["run"]["j"] = 99
    _rewrite(good, header, payload)
    _refused(good, "inconsistent run position")


def test_unrewritten_file_still_reads(good):
    header, payload = _split(good.read_bytes())
    _rewrite(good, header, payload)  # same content, re-serialized: still valid
    assert ck.read(good).config.seed == SMALL["seed"]


# -- the command-line pieces -----------------------------------------------------------------
@pytest.mark.parametrize(
    ("text", "seconds"),
    [("30s", 30), ("5m", 300), ("1h", 3600), ("1h30m", 5400), ("0.2s", 0.2), ("90", 90), ("250ms", 0.25),
     ("2 min", 120), ("1d", 86400), (".5s", 0.5)],
)
def test_parse_duration(text, seconds):
    assert parse_duration(text) == pytest.approx(seconds)


@pytest.mark.parametrize("text", ["", "0s", "5x", "m", "-1s", "1h-5m", "nan", "5 m s", "1e3s"])
def test_parse_duration_refuses(text):
    with pytest.raises(ValueError, match=r"checkpoint_every=.* is not accepted: a duration > 0"):
        parse_duration(text)


def test_simulate_with_checkpoint_refusals(tmp_path, small):
    config, _ = small
    existing = tmp_path / "run.ckpt"
    existing.write_bytes(b"x")
    kw = {"every_s": 1.0, "overwrite": False, "progress": NoProgress()}
    with pytest.raises(ValueError, match="the file exists; continue that run with `stochpend resume"):
        simulate_with_checkpoint(config, checkpoint_path=existing, out=None, **kw)
    with pytest.raises(ValueError, match="it is the same file as --out"):
        simulate_with_checkpoint(config, checkpoint_path=tmp_path / "a.nc", out=tmp_path / "a.nc", **kw)
    with pytest.raises(ValueError, match="does not exist"):
        simulate_with_checkpoint(config, checkpoint_path=tmp_path / "no" / "a.ckpt", out=None, **kw)


def test_simulate_with_checkpoint_matches_simulate(tmp_path, small):
    config, ref = small
    out = tmp_path / "r.nc"
    ds = simulate_with_checkpoint(config, checkpoint_path=tmp_path / "r.ckpt", every_s=0.05, out=out,
                                  overwrite=False, progress=NoProgress(), command_line="stochpend simulate x")
    _assert_identical(ref, ds)
    _assert_identical(ref, io.open_results(out))
    assert io.open_results(out).attrs["command_line"] == "stochpend simulate x"
    assert not (tmp_path / "r.ckpt").exists()


@pytest.fixture
def app():
    names = {c.name for c in cli.app.registered_commands}
    if "sweep" not in names:
        cli.app.command("sweep")(sweep_command)
    if "resume" not in names:
        cli.app.command("resume")(resume_command)
    return cli.app


def test_cli_resume(tmp_path, small, app):
    config, ref = small
    out = tmp_path / "orig.nc"
    path = _interrupted(tmp_path, config, 5, out=out)
    result = CliRunner().invoke(app, ["resume", str(path)])
    assert result.exit_code == 0, result.output
    assert "resuming" in result.output and "wrote" in result.output
    _assert_identical(ref, io.open_results(out))
    # Damaged: exit code 2, one line, nothing written.
    path = _interrupted(tmp_path, config, 5, name="again.ckpt", out=tmp_path / "again.nc")
    path.write_bytes(path.read_bytes()[:-10])
    result = CliRunner().invoke(app, ["resume", str(path)])
    assert result.exit_code == 2 and "checksum mismatch" in result.output
    assert not (tmp_path / "again.nc").exists()


def test_cli_resume_refuses_existing_out(tmp_path, small, app):
    config, _ = small
    out = tmp_path / "o.nc"
    path = _interrupted(tmp_path, config, 2, out=out)
    out.write_text("someone else's file")
    result = CliRunner().invoke(app, ["resume", str(path)])
    assert result.exit_code == 2 and "the file exists" in result.output
    result = CliRunner().invoke(app, ["resume", str(path), "--out", str(tmp_path / "elsewhere.nc"), "-q"])
    assert result.exit_code == 0, result.output
    assert (tmp_path / "elsewhere.nc").is_file()


# -- end to end: a real process killed, then `resume` ----------------------------------------
BIG = ["--noise", "ou", "--D", "1", "--tau", "1", "--omega", "1", "--paths", "10000", "--t-max", "200",
       "--n-times", "30", "--seed", "7"]
BIG_KW = {"noise": "ou", "D": 1.0, "tau": 1.0, "omega": 1.0, "paths": 10000, "t_max": 200.0, "n_times": 30,
          "seed": 7}


SIMULATE = ["stochpend", "simulate"]
RESUME = ["stochpend", "resume"]


def _start(tmp_path, ckpt, out):
    # One thread: a run of several seconds however many cores, so that the signal lands
    # mid-run (the numbers do not depend on the thread count).
    cmd = [sys.executable, "-m", *SIMULATE, *BIG, "--threads", "1", "--checkpoint", str(ckpt),
           "--checkpoint-every", "0.2s", "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=tmp_path)
    deadline = time.monotonic() + 120
    while not ckpt.exists():
        if proc.poll() is not None:
            raise AssertionError(f"the run ended before a checkpoint: {proc.communicate()}")
        if time.monotonic() > deadline:
            proc.kill()
            raise AssertionError("no checkpoint within 120 s")
        time.sleep(0.05)
    assert proc.poll() is None, "the run finished before it could be interrupted: make it longer"
    return proc


def _resume_cli(ckpt, tmp_path):
    r = subprocess.run([sys.executable, "-m", *RESUME, str(ckpt), "--quiet"],
                       capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr


@pytest.fixture(scope="module")
def big_reference():
    return simulate(**BIG_KW)


def test_sigkill_then_resume_is_exact(tmp_path, big_reference):
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start(tmp_path, ckpt, out)
    proc.send_signal(signal.SIGKILL)
    proc.communicate(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert ckpt.exists() and not out.exists()
    saved = ck.read(ckpt)
    assert saved.state.path_steps > 0 and saved.out == out
    _resume_cli(ckpt, tmp_path)
    assert not ckpt.exists()
    result = io.open_results(out)
    _assert_identical(big_reference, result)
    assert result.attrs["path_steps"] == big_reference.attrs["path_steps"]


@pytest.mark.parametrize(("signum", "code"), [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_or_sigterm_writes_checkpoint(tmp_path, signum, code):
    """The signal is acted on at the next kernel boundary: a valid checkpoint, then exit 128+N.

    (That resuming it is exact is what the tests above check.)"""
    ckpt, out = tmp_path / "run.ckpt", tmp_path / "run.nc"
    proc = _start(tmp_path, ckpt, out)
    before = ckpt.stat().st_mtime_ns
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == code, err
    assert f"state saved to {ckpt}; continue with: stochpend resume {ckpt}" in err.decode()
    assert ckpt.stat().st_mtime_ns >= before and not out.exists()
    saved = ck.read(ckpt)
    assert 0 < saved.state.path_steps and saved.out == out and saved.every_s == pytest.approx(0.2)


# -- a target run's checkpoint (issue 35: "a checkpointed target-error run resumes bit for bit") ---
#: The damped pendulum started in its Boltzmann law (tests/unit/test_multilevel.py's cheap case):
#: a pilot of 3 rounds, then 2 more, the whole in a fraction of a second once compiled.
TARGET_RUN = dict(noise="white", D=0.0, omega=1.0, t_max=2.0, times=(1.0, 2.0), h_max=0.5, seed=3)
TARGET_OWN = dict(gamma=0.5, additive_D=0.4, initial_temperature=0.4)
TARGET_ARGS = ["simulate", "--noise", "white", "--D", "0", "--t-max", "2", "--times", "1,2", "--h-max", "0.5",
               "--seed", "3", "-p", "gamma=0.5", "-p", "additive_D=0.4", "-p", "initial_temperature=0.4",
               "--target-error", "0.05"]


@pytest.fixture(scope="module")
def target_reference():
    import warnings

    from stochpend.runs import multilevel

    config = SimulationConfig.build(**TARGET_RUN, noise_params=TARGET_OWN)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = simulate(**TARGET_RUN, **TARGET_OWN, target_error=0.05)
    return config, multilevel.check_target(config, 0.05), ref


def _assert_same_target_result(ref, ds):
    assert set(ds.data_vars) == set(ref.data_vars)
    for name, var in ref.data_vars.items():
        assert ds[name].dtype == var.dtype and np.array_equal(ds[name].values, var.values, equal_nan=True), name
    for key in ("target_level_seeds", "target_levels", "target_certified", "path_steps", "target_route_seeds"):
        assert ds.attrs[key] == ref.attrs[key], key


class _StopAtRound(ck.TargetCheckpointer):
    """Asks to stop once the journal holds ``at`` rounds (as a Ctrl-C during the next would)."""

    at = 1

    def round_done(self, journal):
        if len(journal.rounds) == self.at:
            self.request_stop()
        super().round_done(journal)


def _target_interrupted(tmp_path, config, target, at, out=None, name="t.ckpt"):
    path = tmp_path / name
    saver = type("Stop", (_StopAtRound,), {"at": at})(path, None, config=config, target=target, out=out)
    with pytest.raises(ck.CheckpointInterrupt):
        ck.run_target_checkpointed(config, target, checkpoint_path=path, every_s=None, out=out, checkpointer=saver)
    assert path.is_file() and (out is None or not out.exists())
    return path


@pytest.mark.parametrize("at", [1, 4])
def test_a_target_run_interrupted_at_a_round_boundary_resumes_bit_for_bit(tmp_path, target_reference, at):
    config, target, ref = target_reference
    path = _target_interrupted(tmp_path, config, target, at, out=tmp_path / "t.nc")
    saved = ck.read(path)
    assert isinstance(saved, ck.TargetCheckpoint) and len(saved.journal.rounds) == at
    ds = ck.resume(path)
    assert not path.exists() and ds.attrs["resumed"] == 1
    _assert_same_target_result(ref, ds)
    _assert_same_target_result(ref, io.open_results(tmp_path / "t.nc"))


def test_a_target_on_the_displacement_interrupted_at_a_round_resumes_bit_for_bit(tmp_path):
    """A target on a running sum's statistics (every coupled member tracking its own
    displacement): interrupted after its second round, resumed, the uninterrupted run's numbers
    to the bit."""
    import warnings

    from stochpend.runs import multilevel

    own = dict(TARGET_OWN, torque=0.3)
    kw = dict(TARGET_RUN, observables=("displacement",))
    stats = ("mean_displacement", "diffusion_displacement")
    config = SimulationConfig.build(**kw, noise_params=own)
    target = multilevel.check_target(config, 0.05, target_statistics=stats)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = simulate(**kw, **own, target_error=0.05, target_statistics=stats)
    assert np.all(np.abs(ref["mean_displacement_level_mean"].values[1:]) > 0)  # the levels carry it
    path = _target_interrupted(tmp_path, config, target, 2)
    ds = ck.resume(path)
    assert ds.attrs["resumed"] == 1
    _assert_same_target_result(ref, ds)


def test_a_target_run_interrupted_in_its_late_time_route_resumes_bit_for_bit(tmp_path):
    """The OU pendulum's t = 100, where the levels decorrelate and two independent ensembles
    certify the time (tests/unit/test_multilevel.py): stopped after the route's first ensemble,
    the resumed run replays the levels' rounds and that ensemble and runs the rest."""
    import warnings

    from stochpend.runs import multilevel

    run_ = dict(noise="ou", t_max=100.0, times=(1.0, 100.0), seed=2)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ref = simulate(**run_, target_error=0.05, target_statistics=["mean_E"], progress=False)
    assert ref["mean_E_route"].values.tolist() == [0, 1]
    config = SimulationConfig.build(**run_)
    target = multilevel.check_target(config, 0.05, 0.95, ["mean_E"])

    class AfterTheFirstEnsemble(ck.TargetCheckpointer):
        def round_done(self, journal):
            if len(journal.ensembles) == 1:
                self.request_stop()
            super().round_done(journal)

    path = tmp_path / "late.ckpt"
    with pytest.raises(ck.CheckpointInterrupt):
        ck.run_target_checkpointed(config, target, checkpoint_path=path, every_s=None,
                                   checkpointer=AfterTheFirstEnsemble(path, None, config=config, target=target))
    assert len(ck.read(path).journal.ensembles) == 1
    _assert_same_target_result(ref, ck.resume(path))


def test_ctrl_c_in_a_checkpointed_target_run_saves_it_and_resume_finishes_it_bit_for_bit(
        tmp_path, target_reference, app, monkeypatch):
    """A real SIGINT during the first round boundary's save: deferred (deferred_signals), saved,
    exit 130; `stochpend resume` writes the uninterrupted run's numbers."""
    _, _, ref = target_reference
    monkeypatch.chdir(tmp_path)
    done = ck.TargetCheckpointer.round_done

    def signalled(self, journal):
        if len(journal.rounds) == 1:
            os.kill(os.getpid(), signal.SIGINT)
        done(self, journal)

    monkeypatch.setattr(ck.TargetCheckpointer, "round_done", signalled)
    result = CliRunner().invoke(app, [*TARGET_ARGS, "--checkpoint", "t.ckpt", "--out", "t.nc"])
    assert result.exit_code == 130, result.output
    assert "state saved to" in result.output and "stochpend resume t.ckpt" in result.output
    assert (tmp_path / "t.ckpt").is_file() and not (tmp_path / "t.nc").exists()
    monkeypatch.setattr(ck.TargetCheckpointer, "round_done", done)
    result = CliRunner().invoke(app, ["resume", "t.ckpt"])
    assert result.exit_code == 0, result.output
    assert "resuming" in result.output and "1 rounds done" in result.output and "mean_E2 " in result.stdout
    assert not (tmp_path / "t.ckpt").exists()
    ds = io.open_results(tmp_path / "t.nc")
    _assert_same_target_result(ref, ds)
    assert ds.attrs["command_line"].startswith("stochpend") and ds.attrs["resumed"] == 1


def test_an_uninterrupted_checkpointed_target_run_is_the_target_run(tmp_path, target_reference, app, monkeypatch):
    _, _, ref = target_reference
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(app, [*TARGET_ARGS, "--checkpoint", "t.ckpt", "--checkpoint-every", "0.001s",
                                      "--out", "t.nc"])
    assert result.exit_code == 0, result.output
    assert not (tmp_path / "t.ckpt").exists()
    _assert_same_target_result(ref, io.open_results(tmp_path / "t.nc"))


def _crafted(path, edit):
    header, payload = _split(path.read_bytes())
    edit(header)
    _rewrite(path, header, payload)


@pytest.mark.parametrize(("edit", "needle"), [
    (lambda h: h["target"].update(error=0.0), "its target no longer validates (target_error=0.0 is not accepted"),
    (lambda h: h["target"].update(times=[3.0]), "its target no longer validates (target_times=[3.0]"),
    (lambda h: h["target"]["rounds"][0].update(seed=12345), "its round 0 (level 0, seed 12345, 256 samples"),
    (lambda h: h["target"]["rounds"][0].update(level=1), "its round 0 (level 1,"),
    (lambda h: h["target"]["rounds"][0].update(batches=0), "malformed header: target.rounds[0]"),
    (lambda h: h["target"]["rounds"][0].update(stop=True), "malformed header: target.rounds[0]"),
    (lambda h: h["target"].pop("ensembles"), "malformed header: target"),
    (lambda h: h.update(kind="other"), "unknown kind 'other'"),
    (lambda h: h["arrays"][0].update(shape=[2, 3]), "array 'target_n' has dtype <i8 and shape (2, 3), expected"),
])
def test_a_damaged_or_crafted_target_checkpoint_is_refused_in_one_line(tmp_path, target_reference, edit, needle):
    config, target, _ = target_reference
    path = _target_interrupted(tmp_path, config, target, 2, out=tmp_path / "t.nc")
    _crafted(path, edit)
    _refused(path, needle, read=False)
    assert not (tmp_path / "t.nc").exists()


def test_a_target_checkpoints_samples_that_no_round_has_are_refused(tmp_path, target_reference):
    config, target, _ = target_reference
    path = _target_interrupted(tmp_path, config, target, 1)
    data = bytearray(path.read_bytes())
    header, payload = _split(bytes(data))
    counts = np.frombuffer(payload[:16], dtype="<i8").copy()
    counts[1] = 7  # 256 samples at time 0, 7 at time 1: not what one round runs
    _rewrite(path, header, counts.tobytes() + payload[16:])
    _refused(path, "array 'target_n' row 0 is not a round's samples to time index 1")


def test_a_damaged_target_checkpoint_is_refused_by_resume_exit_2(tmp_path, target_reference, app):
    config, target, _ = target_reference
    path = _target_interrupted(tmp_path, config, target, 1, out=tmp_path / "t.nc")
    path.write_bytes(path.read_bytes()[:-10])
    result = CliRunner().invoke(app, ["resume", str(path)])
    assert result.exit_code == 2 and "checksum mismatch" in result.output, result.output
    assert len(result.output.strip().splitlines()) == 1 and not (tmp_path / "t.nc").exists()


def test_the_journal_replays_the_independent_routes_ensembles_and_refuses_another():
    from stochpend.runs import multilevel

    made = []

    def run():
        made.append(1)
        return multilevel.Ensemble(7, 0.25, 100, 1, np.zeros((1, 2)), np.zeros((1, 2)), 500, 0)

    journal = multilevel.Journal(source="checkpoint='x'")
    first = journal.ensemble(7, 0.25, 100, 1, run)
    again = multilevel.Journal(ensembles=list(journal.ensembles), source="checkpoint='x'")
    assert again.ensemble(7, 0.25, 100, 1, run) is first and len(made) == 1
    with pytest.raises(ValueError, match=r"checkpoint='x' is not accepted: its ensemble 0 \(seed 7, h = 0.25"):
        multilevel.Journal(ensembles=list(journal.ensembles), source="checkpoint='x'").ensemble(7, 0.125, 100, 1, run)
