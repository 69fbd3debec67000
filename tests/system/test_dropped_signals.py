"""A Ctrl-C whose exception Python drops still stops the command.

Python raises a signal's exception in whatever code runs when it lands; in a weakref callback
or ``__del__`` that exception is printed ("Exception ignored in ...") and discarded. A fresh-clone
CI run at eced1d9 hit it: the Ctrl-C landed in the import system's module-lock callback, the run
went on to its end and exited 0. Here the same drop is made on purpose (a SIGINT raised inside a
weakref callback, in this process, under ``CliRunner``) at the three places a command can be:
before a run's first kernel boundary, before a checkpointed run listens for signals, and after
the last boundary. Each test first checks that the exception really was dropped.
"""

from __future__ import annotations

import shlex
import signal
import sys
import weakref

import pytest
from typer.testing import CliRunner

from stochpend import cli
from stochpend.engine import runner
from stochpend.files import _files, io
from stochpend.runs import checkpoint

TINY = ["simulate", "--paths", "200", "--t-max", "2", "--n-times", "2", "--seed", "3", "--threads", "1",
        "--bias-paths", "0", "--quiet"]


class _Box:
    pass


def _drop_a_sigint() -> None:
    """Deliver SIGINT while a weakref callback runs, where Python drops its exception."""
    box = _Box()
    ref = weakref.ref(box, lambda _: signal.raise_signal(signal.SIGINT))
    del box
    assert ref() is None


@pytest.fixture
def dropped(monkeypatch):
    """The exceptions Python dropped (``sys.unraisablehook``), in order."""
    seen: list[type[BaseException]] = []
    monkeypatch.setattr(sys, "unraisablehook", lambda u: seen.append(type(u.exc_value)))
    return seen


def test_a_dropped_signal_is_kept_until_taken_back(dropped):
    with _files.signals_interrupt():
        _drop_a_sigint()
        assert dropped == [KeyboardInterrupt]
        with pytest.raises(KeyboardInterrupt):
            _files.raise_pending()
        _files.raise_pending()  # taken back once
        assert _files.take_pending() is None
    _drop_a_sigint()  # outside a command: Python's own handler, nothing recorded
    assert dropped == [KeyboardInterrupt, KeyboardInterrupt]
    assert _files.take_pending() is None


def test_a_run_stops_at_its_first_boundary(tmp_path, monkeypatch, dropped):
    real = runner.run_batches

    def dropping(*args, **kwargs):
        _drop_a_sigint()
        return real(*args, **kwargs)

    monkeypatch.setattr(runner, "run_batches", dropping)
    out = tmp_path / "r.nc"
    result = CliRunner().invoke(cli.app, [*TINY, "--out", str(out)])
    assert dropped == [KeyboardInterrupt]
    assert result.exit_code == 130, result.output
    assert "interrupted" in result.output and not out.exists()


def test_a_checkpointed_run_saves_and_says_how_to_continue(tmp_path, monkeypatch, dropped):
    real = checkpoint.FileCheckpointer.signals

    def dropping(self):
        _drop_a_sigint()  # before the run's handlers are in place
        return real(self)

    monkeypatch.setattr(checkpoint.FileCheckpointer, "signals", dropping)
    ckpt, out = tmp_path / "r.ckpt", tmp_path / "r.nc"
    result = CliRunner().invoke(cli.app, [*TINY, "--checkpoint", str(ckpt), "--out", str(out)])
    assert dropped == [KeyboardInterrupt]
    assert result.exit_code == 130, result.output
    assert "continue with: " in result.output and ckpt.is_file() and not out.exists(), result.output
    monkeypatch.setattr(checkpoint.FileCheckpointer, "signals", real)
    advice = shlex.split(result.output.strip().splitlines()[-1].split("continue with: ", 1)[1])
    assert advice[:2] == ["stochpend", "resume"], advice  # run as printed
    result = CliRunner().invoke(cli.app, [*advice[1:], "--quiet"])
    assert result.exit_code == 0, result.output
    assert out.is_file() and not ckpt.exists()


def test_after_the_last_boundary_the_exit_status_says_so(tmp_path, monkeypatch, dropped):
    real = io.to_netcdf

    def dropping(*args, **kwargs):
        value = real(*args, **kwargs)
        _drop_a_sigint()
        return value

    monkeypatch.setattr(io, "to_netcdf", dropping)
    out = tmp_path / "r.nc"
    result = CliRunner().invoke(cli.app, [*TINY, "--out", str(out)])
    assert dropped == [KeyboardInterrupt]
    assert result.exit_code == 130, result.output
    assert "as the command finished: what it printed and wrote is complete" in result.output
    assert out.is_file()


def test_a_signal_ignored_on_the_way_out_stays_ignored():
    """A command exiting after a signal ignores further ones (cli._common._stop_listening); the
    context's exit put SIGTERM's default back over that, so a SIGTERM in the last instant
    killed the process by the signal instead of its exit 128 + n."""
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with _files.signals_interrupt():
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        assert signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        assert signal.getsignal(signal.SIGINT) is before[signal.SIGINT]  # untouched: restored
    finally:
        for s, h in before.items():
            signal.signal(s, h)


def test_outside_a_command_nothing_is_recorded():
    """A Python caller's second Ctrl-C of a checkpointed run raises as Python does
    (checkpoint.deferred_signals records it only inside a command): nothing may be left to stop
    that caller's next run at its first boundary."""
    _files.record_signal(signal.SIGINT)
    _files.raise_pending()  # nothing recorded, nothing raised
    assert _files.take_pending() is None
