"""stochpend.runs.resources: memory and work estimated, and refused, before any work."""

from __future__ import annotations

import math

import pytest

import stochpend
from stochpend.model.settings import SimulationConfig
from stochpend.runs import resources


def _config(**kwargs):
    return SimulationConfig.build(**kwargs)


def test_chunk_defaults_match_the_backends():
    from stochpend.engine import cpu, cuda

    assert resources.CPU_CHUNK_PATHS == cpu.DEFAULT_CHUNK_PATHS
    assert resources.STATE_BYTES_PER_PATH == {"float64": 57, "float32": 45}
    assert resources.STATE_BYTES_PER_PATH["float32"] == cuda._bytes_per_path("float32")
    assert resources.STATE_BYTES_PER_PATH["float64"] == cuda._bytes_per_path("float64")
    assert resources.CUDA_CHUNK_PATHS == cuda.DEFAULT_CHUNK_PATHS


def test_memory_counts_one_chunk_of_state_and_the_per_time_arrays():
    c = _config(paths=10_000, n_times=40, hist_bins=100, n_batches=100)
    est = resources.estimate(c)
    n_cols = 102
    expected = (10_000 * 57  # state: the whole ensemble fits in one chunk
                + 2 * 100 * 40 * 9 * 8 + 100 * 40 * 9 * 8  # per-batch sums (+ Dataset) + the chunk's
                + 2 * 40 * n_cols * 8 + 40 * n_cols * 8 + 100 * n_cols * 8  # histograms
                + 2 * 40 * 101 * 8)  # edges (+ Dataset)
    assert est.memory_bytes == expected
    assert est.min_path_steps == pytest.approx(10_000 * 1000 / 0.05)
    assert est.seconds > 0 and est.chunk_paths == 10_000


def test_the_estimate_holds_the_chunks_the_runner_holds():
    """The runner's chunks are whole batches, as many as fit in chunk_paths and at least one:
    with batches of 10**7 paths (10**9 paths, 100 batches) one batch is a chunk on the CPU,
    six on a GPU (2**26 paths)."""
    c = _config(paths=10**9)
    est = resources.estimate(c)
    assert est.chunk_paths == c.batch_size == 10**7
    assert 10**7 * 57 < est.memory_bytes < 10**7 * 57 + 2**20
    small = resources.estimate(c, chunk_paths=1000)
    assert small.chunk_paths == 10**7  # never less than a batch
    gpu = resources.estimate(c, backend="cuda", precision="float32")
    assert gpu.chunk_paths == 6 * 10**7 and gpu.device_bytes == 6 * 10**7 * 45
    assert gpu.memory_bytes < est.memory_bytes
    huge = resources.estimate(_config(paths=10**15))
    assert huge.chunk_paths == 10**13 and huge.min_path_steps == pytest.approx(2e19)


def test_work_limit_refuses_in_one_line_and_can_be_raised():
    c = _config(paths=10**15)
    with pytest.raises(ValueError) as info:
        resources.check(c)
    msg = str(info.value)
    assert msg.startswith("paths=1000000000000000 is not accepted: the run needs at least 2e+19 path-steps")
    assert "max_path_steps" in msg and "\n" not in msg
    c = _config(paths=100, t_max=1e300)
    with pytest.raises(ValueError, match=r"^t_max=1e\+300 is not accepted"):
        resources.check(c)
    c = _config(paths=10, t_max=1.0, h_max=1e-14)
    with pytest.raises(ValueError, match=r"^h_max=1e-14 is not accepted"):
        resources.check(c)
    assert resources.check(c, max_path_steps=math.inf).min_path_steps == pytest.approx(1e15)
    for bad in (0, -1.0, math.nan, "many", True):
        with pytest.raises(ValueError, match=r"^max_path_steps="):
            resources.check(c, max_path_steps=bad)


def test_memory_check_names_the_parameter(monkeypatch):
    monkeypatch.setattr(resources, "_memory_bound", lambda: (2**30, "this machine has"))
    with pytest.raises(ValueError) as info:
        resources.check(_config(hist_bins=10**9))
    msg = str(info.value)
    assert msg.startswith("hist_bins=1000000000 is not accepted: the run needs ")
    assert "TiB of memory" in msg and "1.0 GiB available" in msg and "\n" not in msg
    with pytest.raises(ValueError, match=r"^n_times=1000000 is not accepted: the run needs"):
        resources.check(_config(n_times=10**6, n_batches=1000, paths=10**6, t_max=1.0))
    with pytest.raises(ValueError, match=r"^chunk_paths=100000000 is not accepted"):
        resources.check(_config(paths=10**9, t_max=1e-3), chunk_paths=10**8)


def test_formats():
    assert resources.format_bytes(1536) == "1.5 KiB"
    assert resources.format_bytes(80 * 2**40) == "80.0 TiB"
    assert resources.format_bytes(10**400) == "more than 1e308 B"
    assert resources.format_seconds(5) == "5 s"
    assert resources.format_seconds(3 * 3600) == "3 h"
    assert resources.format_seconds(math.inf) == "forever"


def test_api_refuses_before_any_work():
    with pytest.raises(ValueError, match=r"^paths=1000000000000000 is not accepted"):
        stochpend.simulate(paths=10**15)
    with pytest.raises(ValueError, match=r"^max_path_steps=0 is not accepted"):
        stochpend.simulate(paths=10, t_max=1.0, max_path_steps=0)
    with pytest.raises(ValueError, match=r"^paths=100 is not accepted"):
        stochpend.simulate(paths=100, t_max=1.0, n_times=1, max_path_steps=10)


class _Started(Exception):
    pass


def _start_then_stop(config, *, progress, **kwargs):
    progress.start(1.0, "simulating")
    raise _Started


@pytest.mark.parametrize("args,long_run,compiling", [
    (["--paths", "1e6", "--t-max", "1000"], True, 0.0),  # 2e10 path-steps: minutes
    (["--paths", "10", "--t-max", "1"], False, 0.0),
    # kernels not in Numba's cache: a short run is mostly compiling, and says so
    (["--paths", "10", "--t-max", "1"], True, 12.0),
])
def test_cli_announces_long_runs_even_when_quiet(args, long_run, compiling):
    from unittest import mock

    from typer.testing import CliRunner

    from stochpend.cli import app

    with (mock.patch("stochpend.runs.lifecycle.execute", _start_then_stop),
          mock.patch("stochpend.runs.resources.compile_seconds", lambda *a, **k: compiling)):
        result = CliRunner().invoke(app, ["simulate", "--quiet", *args])
    assert isinstance(result.exception, _Started), result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    if long_run:
        assert len(lines) == 1 and lines[0].startswith("estimate: at least "), result.output
        assert "peak memory" in lines[0]
        assert ("2e+10 path-steps" in lines[0]) == (not compiling)
        assert ("plus ~12 s compiling kernels (first use, cached after)" in lines[0]) == bool(compiling)
    else:
        assert lines == [], result.output


def test_quiet_long_run_prints_a_heartbeat_every_minute(capsys):
    """A long run without a progress bar (--quiet, or a batch job's log) says it is alive once
    a minute: done fraction, elapsed and remaining time; a short run, or one with a bar, never."""
    from stochpend.cli import RichProgress

    now = [1000.0]
    beat = RichProgress(enabled=False, announce="estimate: long", clock=lambda: now[0])
    beat.start(200.0, "simulating")
    for done, at in [(10.0, 30.0), (50.0, 61.0), (60.0, 90.0), (100.0, 122.0), (200.0, 300.0)]:
        now[0] = 1000.0 + at
        beat.update(done)
    beat.finish()
    lines = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert lines == ["estimate: long",
                     "progress: simulating 25.0 % after 61 s, about 3.0 min left",
                     "progress: simulating 50.0 % after 2.0 min, about 2.0 min left",
                     "progress: simulating 100.0 % after 5.0 min, about 0 s left"]
    for enabled, announce in [(False, None), (True, "estimate: long")]:
        other = RichProgress(enabled=enabled, announce=announce, clock=lambda: now[0])
        assert other.heartbeat is None  # a short run, or a bar that shows the progress
    # a resumed checkpointed run is long by nature: it beats without an estimate line
    assert RichProgress(enabled=False, long_run=True).heartbeat == 60.0
    assert RichProgress(enabled=True, long_run=True).heartbeat is None


def test_a_cgroup_memory_limit_bounds_the_available_memory(tmp_path):
    """A Slurm job or a container kills a process at its group's limit whatever the machine
    has: the headroom is the smallest limit - usage + reclaimable cache over the group and its
    ancestors (v2), or the v1 memory group's; no limit, no number."""
    from stochpend.runs.resources import cgroup_headroom

    root, proc = tmp_path / "cg", tmp_path / "cgroup"
    job = root / "slurm" / "job_7"
    job.mkdir(parents=True)
    (root / "slurm" / "memory.max").write_text("max\n")
    (root / "slurm" / "memory.current").write_text("900\n")
    (job / "memory.max").write_text(f"{4 << 30}\n")
    (job / "memory.current").write_text(f"{3 << 30}\n")
    (job / "memory.stat").write_text(f"anon 5\ninactive_file {1 << 29}\nactive_file 7\n")
    proc.write_text("0::/slurm/job_7\n")
    assert cgroup_headroom(str(root), str(proc)) == (1 << 30) + (1 << 29)
    (root / "slurm" / "memory.max").write_text(f"{(1 << 30) + 1000}\n")  # a tighter parent
    assert cgroup_headroom(str(root), str(proc)) == (1 << 30) + 100
    (job / "memory.max").write_text("max\n")
    (root / "slurm" / "memory.max").write_text("max\n")
    assert cgroup_headroom(str(root), str(proc)) is None
    # cgroup v1, inside a container (the group's path is not under the mount)
    v1 = root / "memory"
    v1.mkdir()
    (v1 / "memory.limit_in_bytes").write_text(f"{2 << 30}\n")
    (v1 / "memory.usage_in_bytes").write_text(f"{1 << 30}\n")
    (v1 / "memory.stat").write_text("cache 3\ntotal_inactive_file 1000\n")
    proc.write_text("4:memory:/process_api/abc\n0::/\n")
    assert cgroup_headroom(str(root), str(proc)) == (1 << 30) + 1000
    (v1 / "memory.limit_in_bytes").write_text("9223372036854771712\n")  # v1's "no limit"
    assert cgroup_headroom(str(root), str(proc)) is None
    assert cgroup_headroom(str(root), str(tmp_path / "missing")) is None


def test_the_memory_refusal_names_the_cgroup_limit(monkeypatch):
    from stochpend.runs import resources

    monkeypatch.setattr(resources, "cgroup_headroom", lambda: 1 << 20)
    with pytest.raises(ValueError, match=r"^hist_bins=100000 is not accepted: .* and this process's memory "
                                         r"limit \(cgroup\) leaves 1(\.0)? MiB available; use fewer"):
        stochpend.simulate(paths=10, t_max=1.0, hist_bins=100_000)
