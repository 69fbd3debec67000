"""Soak: a long checkpointed run keeps its memory flat, and every checkpoint it writes is valid.

A run of many small chunks (100 paths each) saves a checkpoint every 2 s for
``STOCHPEND_SOAK_SECONDS`` (default 600) seconds, then is stopped with SIGTERM. Meanwhile the
test samples the process's resident memory (VmRSS) every 2 s and reads every checkpoint the
moment it appears (checksum, configuration, position moving forward, finished batches never
changing). At the end three checkpoints (early, middle, the SIGTERM one) are resumed for two
chunks each, and the batches they finish must equal the same batches run alone, bit for bit.

The RSS curve (seconds, KiB) is printed and written to ``rss.tsv`` in the test's temporary
folder, and also to ``$STOCHPEND_SOAK_DIR`` when that is set. Run with
``pytest -m slow tests/soak -s``.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import stochpend
from stochpend.engine.runner import run_batches
from stochpend.runs import checkpoint as ck
from tests.soak._soak_run import CHUNK_PATHS, EVERY_S, config_for

HELPER = Path(__file__).with_name("_soak_run.py")
DURATION_S = float(os.environ.get("STOCHPEND_SOAK_SECONDS", "600"))
#: RSS sampling interval (seconds).
SAMPLE_S = 2.0
#: Allowed growth of the RSS maximum from the first half (after warm-up) to the second half:
#: a few MiB of allocator noise. A leak of one checkpoint's arrays per save (the finished
#: batches' sums: ~3 MB for the default duration) exceeds it at the first save.
RSS_GROWTH_LIMIT_KIB = 4 * 1024
#: Allowed slope of the RSS over the second half (a least-squares line): 1 KiB/s is 3.5 MiB
#: an hour, a slow leak a 10-minute soak could otherwise hide under the limit above.
RSS_SLOPE_LIMIT_KIB_PER_S = 1.0


def memory_trend(samples: list[tuple[float, int]], duration_s: float) -> tuple[int, int, float]:
    """``(growth, first_max, slope)``: the largest RSS (KiB) of the second half of the run
    minus the largest of the first half after the warm-up (the first fifth, at most 60 s: the
    JIT loads its kernels, the first chunk and the first checkpoint allocate), that maximum,
    and the slope (KiB/s) of a straight line through the second half."""
    warmup = min(60.0, duration_s / 5)
    first = [rss for t, rss in samples if warmup <= t < duration_s / 2]
    last = [(t, rss) for t, rss in samples if t >= duration_s / 2]
    if len(first) < 2 or len(last) < 2:
        raise ValueError(f"too few RSS samples ({len(samples)}) over {duration_s} s")
    t, rss = np.array(last, dtype=float).T
    slope = float(np.polyfit(t, rss, 1)[0])
    return int(max(rss)) - max(first), max(first), slope


def test_memory_trend_tells_flat_from_leaking():
    """The criteria themselves: allocator noise passes; a slow leak (2 KiB/s) and a jump of
    8 MiB in the second half each fail."""
    rng = np.random.default_rng(1)
    t = np.arange(0.0, 600.0, 2.0)
    flat = [(float(s), int(250_000 + (40_000 if s < 20 else 0) + rng.integers(0, 1500))) for s in t]
    growth, first_max, slope = memory_trend(flat, 600.0)
    assert growth < RSS_GROWTH_LIMIT_KIB and abs(slope) < RSS_SLOPE_LIMIT_KIB_PER_S and first_max > 250_000
    leaking = [(s, rss + int(2 * s)) for s, rss in flat]
    assert memory_trend(leaking, 600.0)[2] > RSS_SLOPE_LIMIT_KIB_PER_S
    jump = [(s, rss + (8192 if s > 500 else 0)) for s, rss in flat]
    assert memory_trend(jump, 600.0)[0] > RSS_GROWTH_LIMIT_KIB


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise AssertionError(f"no VmRSS for process {pid}")


class _Stop(Exception):
    pass


class _StopAt:
    """Lets a resumed run go until chunk ``b_stop`` starts, then stops it."""

    def __init__(self, b_stop: int) -> None:
        self.b_stop = b_stop
        self.state = None

    def maybe_save(self, state) -> None:
        if state.b0 >= self.b_stop:
            self.state = state
            raise _Stop


def _check_resumes(path: Path, config) -> int:
    """Resume ``path`` for two chunks: the batches it finishes equal those batches run alone."""
    saved = ck.read(path)
    st = saved.state
    b0 = st.b0
    b_stop = min(b0 + 2, config.n_batches)
    hist_before = st.acc.hist.copy()
    stopper = _StopAt(b_stop)
    try:
        run_batches(config, st.first_batch, st.stop_batch, chunk_paths=CHUNK_PATHS, checkpointer=stopper,
                    resume=st)
    except _Stop:
        pass
    resumed = stopper.state.acc if stopper.state is not None else st.acc
    alone, _ = run_batches(config, b0, b_stop)
    assert np.array_equal(resumed.sums[b0:b_stop], alone.sums[b0:b_stop]), path
    assert np.array_equal(resumed.hist - hist_before, alone.hist), path
    assert resumed.filled[:b_stop].all()
    return b0


@pytest.mark.slow
def test_soak(tmp_path):
    config = config_for(DURATION_S)
    ckpt, out = tmp_path / "soak.ckpt", tmp_path / "soak.nc"
    src = Path(stochpend.__file__).resolve().parents[1]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(src), *filter(None, [os.environ.get("PYTHONPATH")])])}
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    proc = subprocess.Popen([sys.executable, str(HELPER), str(ckpt), str(out), str(DURATION_S)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    samples: list[tuple[float, int]] = []
    seen: list[tuple[float, int, int]] = []  # (elapsed_s, b0, j) of every checkpoint read
    kept: dict[str, Path] = {}
    last_id = None
    previous = None
    started = time.monotonic()
    next_sample = 0.0
    try:
        while (now := time.monotonic() - started) < DURATION_S:
            assert proc.poll() is None, f"the soak run ended after {now:.0f} s: {proc.communicate()}"
            if now >= next_sample:
                samples.append((round(now, 1), _rss_kib(proc.pid)))
                next_sample += SAMPLE_S
            try:
                stat = ckpt.stat()
            except FileNotFoundError:
                stat = None
            if stat is not None and (stat.st_ino, stat.st_mtime_ns) != last_id:
                last_id = (stat.st_ino, stat.st_mtime_ns)
                saved = ck.read(ckpt)  # checksum, version, configuration, array table
                previous = _check_sequence(saved, previous)
                seen.append((saved.elapsed_s, saved.state.b0, saved.state.j))
                label = "early" if not kept else "middle" if now >= DURATION_S / 2 else None
                if label and label not in kept:
                    kept[label] = tmp_path / f"{label}.ckpt"
                    shutil.copyfile(ckpt, kept[label])
            time.sleep(0.2)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 143, err
    final = ck.read(ckpt)  # the SIGTERM checkpoint
    _check_sequence(final, previous)
    seen.append((final.elapsed_s, final.state.b0, final.state.j))
    kept["final"] = ckpt

    curve = "\n".join(f"{t:.1f}\t{rss}" for t, rss in samples)
    (tmp_path / "rss.tsv").write_text("seconds\trss_kib\n" + curve + "\n")
    if os.environ.get("STOCHPEND_SOAK_DIR"):
        shutil.copyfile(tmp_path / "rss.tsv", Path(os.environ["STOCHPEND_SOAK_DIR"]) / "rss.tsv")
    growth, first_max, slope = memory_trend(samples, DURATION_S)
    gaps = np.diff([s[0] for s in seen[:-1]])
    print(f"\nsoak: {DURATION_S:.0f} s, {len(seen)} checkpoints (gaps {gaps.min():.2f}-{gaps.max():.2f} s), "
          f"{final.state.b0} of {config.n_batches} chunks done, RSS growth {growth} KiB over a first-half "
          f"maximum of {first_max} KiB, second-half slope {slope:.3f} KiB/s\nseconds\trss_kib\n{curve}")

    assert len(seen) >= 0.8 * DURATION_S / EVERY_S, f"only {len(seen)} checkpoints in {DURATION_S} s"
    assert gaps.min() >= EVERY_S - 0.05, "a checkpoint came before its interval"
    assert final.state.b0 >= 20, "too few chunks for a soak"
    assert growth <= RSS_GROWTH_LIMIT_KIB, f"RSS grew by {growth} KiB (limit {RSS_GROWTH_LIMIT_KIB})"
    assert slope <= RSS_SLOPE_LIMIT_KIB_PER_S, f"RSS grows by {slope:.3f} KiB/s in the second half"
    resumed_at = {label: _check_resumes(path, config) for label, path in kept.items()}
    assert resumed_at["early"] < resumed_at["middle"] < resumed_at["final"], resumed_at


def _check_sequence(saved: ck.Checkpoint, previous: ck.Checkpoint | None) -> ck.Checkpoint:
    """Each checkpoint is further on than the one before, its finished batches are exactly
    those before its chunk, and a batch once finished never changes."""
    st = saved.state
    assert st.first_batch == 0 and st.acc.filled[:st.b0].all() and not st.acc.filled[st.b0:].any()
    assert st.b1 == st.b0 + 1  # one batch a chunk
    if previous is not None:
        p = previous.state
        assert (st.b0, st.j) >= (p.b0, p.j) and st.path_steps >= p.path_steps
        assert saved.elapsed_s > previous.elapsed_s
        assert np.array_equal(st.acc.sums[:p.b0], p.acc.sums[:p.b0])
        assert np.all(st.acc.hist >= p.acc.hist)
    return saved

