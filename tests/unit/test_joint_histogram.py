"""The joint (x, Omega) histogram (issue 23): its counts add up to the finite paths, its Omega
marginal to <Omega^2>; the same counts from the lane driver, the one-path driver, any thread
count and chunking, a checkpoint resumed, a sweep and the CUDA backend (in the simulator); a
run without it is the run it was; bad input is one line naming the parameter."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from stochpend import cli, io
from stochpend.engine import cpu, runner
from stochpend.model import settings
from stochpend.model.settings import SimulationConfig
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run
from tests._checkpoints import StopAfter

#: The damped pendulum with additive white noise (no parametric noise): it relaxes to
#: Boltzmann at T = D_a / (2 gamma) = 0.4 (tests/statistical/test_family_dynamics.py).
DAMPED = dict(noise="white", D=0.0, omega=1.0, paths=600, t_max=4.0, times=(1.0, 4.0), seed=11,
              gamma=0.5, additive_D=0.4, joint_bins=(12, 10), n_batches=20)
#: The paper's pendulum (OU parametric noise), default Omega range; and a non-periodic oscillator.
PAPER = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=300, t_max=6.0, n_times=3, seed=5,
             joint_bins=(7, 9), n_batches=30)
HARMONIC = dict(noise="white", D=0.5, omega=1.0, potential="harmonic", paths=300, t_max=6.0, n_times=3,
                seed=6, joint_bins=(6, 5), joint_x_range=(-1.5, 1.5), joint_Omega_max=1.2, n_batches=30)

JOINT_VARS = ("joint_hist", "joint_hist_outside", "joint_density", "joint_density_stderr", "x_bin_edges",
              "Omega_bin_edges")


def _config(kwargs):
    kw = dict(kwargs)
    own = {k: kw.pop(k) for k in ("gamma", "additive_D") if k in kw}
    return SimulationConfig.build(**kw, noise_params=own)


def _same_joint(a, b):
    for name in JOINT_VARS:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)


@pytest.fixture(scope="module")
def damped():
    config = _config(DAMPED)
    return config, run(config, bias_paths=0)


def test_counts_add_up_to_the_finite_paths_at_every_time(damped):
    config, ds = damped
    assert ds.joint_hist.dims == ("time", "x_bin", "Omega_bin")
    assert ds.joint_hist.shape == (2, 12, 10)
    total = ds.joint_hist.values.sum(axis=(1, 2)) + ds.joint_hist_outside.values
    np.testing.assert_array_equal(total, ds.n_finite_paths.values)
    # the density integrates to the fraction inside the grid
    area = np.diff(ds.x_bin_edges.values, axis=1)[:, :, None] * np.diff(ds.Omega_bin_edges.values, axis=1)[:, None, :]
    inside = (ds.joint_density.values * area).sum(axis=(1, 2))
    np.testing.assert_allclose(inside, ds.joint_hist.values.sum(axis=(1, 2)) / ds.n_finite_paths.values,
                               rtol=1e-12)
    # the periodic angle over [-pi, pi); the Omega range covers 8 thermal standard deviations
    np.testing.assert_allclose(ds.x_bin_edges.values[:, [0, -1]], [[-np.pi, np.pi]] * 2, rtol=0, atol=0)
    assert ds.Omega_bin_edges.values[0, -1] >= 8.0 * np.sqrt(0.4)


def test_the_omega_marginal_matches_mean_omega2():
    """Fine Omega bins: <Omega^2> from the marginal (bin centres, Sheppard's w^2/12) agrees
    with mean_Omega2 within its standard error and the binning's bound."""
    kw = dict(DAMPED, joint_bins=(4, 200), joint_Omega_max=4.0, paths=2000)
    ds = run(_config(kw), bias_paths=0)
    edges = ds.Omega_bin_edges.values[-1]
    w = edges[1] - edges[0]
    centres = 0.5 * (edges[1:] + edges[:-1])
    marginal = ds.joint_hist.values[-1].sum(axis=0)
    assert int(ds.joint_hist_outside[-1]) == 0
    m2 = float((marginal * (centres**2 + w * w / 12.0)).sum() / marginal.sum())
    want, se = float(ds.mean_Omega2[-1]), float(ds.mean_Omega2_stderr[-1])
    # the bins move each path's Omega^2 by at most |Omega| w; averaged, far less
    assert abs(m2 - want) < 4 * se + 0.02 * w, (m2, want, se, w)


def test_the_error_is_the_multinomial_one_in_size():
    """Independent paths: the batch-means error of each cell's probability is close to the
    multinomial sqrt(p (1 - p) / N) (50 batches: about 10% scatter per cell, less in the median)."""
    ds = run(_config(dict(DAMPED, paths=4000, joint_bins=(6, 6), joint_Omega_max=1.5, n_batches=50)), bias_paths=0)
    n = float(ds.n_finite_paths[-1])
    area = np.diff(ds.x_bin_edges.values[-1])[:, None] * np.diff(ds.Omega_bin_edges.values[-1])[None, :]
    p = ds.joint_hist.values[-1] / n
    ok = ds.joint_hist.values[-1] >= 20
    ratio = ds.joint_density_stderr.values[-1][ok] * area[ok] / np.sqrt(p[ok] * (1 - p[ok]) / n)
    assert ok.sum() >= 20 and 0.9 < float(np.median(ratio)) < 1.1, (ok.sum(), np.median(ratio))
    assert np.all(ds.joint_density_stderr.values[-1][ds.joint_hist.values[-1] == 0] == 0)


def test_the_lane_driver_one_path_driver_threads_and_chunks_give_the_same_counts(damped, monkeypatch):
    config, ref = damped
    assert cpu.advance_kernel(cpu.spec_for(config)) is not cpu.path_kernel(cpu.spec_for(config))  # lanes
    _same_joint(ref, run(config, bias_paths=0, threads=1, chunk_paths=90))
    monkeypatch.setattr(cpu, "advance_kernel", cpu.path_kernel)
    _same_joint(ref, run(config, bias_paths=0, chunk_paths=150))


def test_without_it_the_run_is_the_run_it_was(damped):
    config, ref = damped
    plain = run(_config({k: v for k, v in DAMPED.items() if k != "joint_bins"}), bias_paths=0)
    assert not set(JOINT_VARS) & set(plain.data_vars)
    for name in plain.data_vars:
        np.testing.assert_array_equal(plain[name].values, ref[name].values, err_msg=str(name))
    assert "joint_bins" not in ck.config_to_json(plain_config := _config({k: v for k, v in DAMPED.items()
                                                                          if k != "joint_bins"}))
    assert settings.hist_columns(plain_config) == plain_config.hist_bins + 2


@pytest.mark.parametrize("n", [2, 5])
def test_a_checkpoint_resumed_gives_the_straight_run(tmp_path, n):
    config = _config(PAPER)
    ref = run(config, bias_paths=0, chunk_paths=90)
    path = tmp_path / "run.ckpt"
    cp = StopAfter(path, None, config=config, n=n, chunk_paths=90)
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, checkpointer=cp, chunk_paths=90,
                            bias_paths=0)
    assert ck.read(path).config.joint_bins == (7, 9)
    ds = ck.resume(path)
    _same_joint(ref, ds)
    np.testing.assert_array_equal(ds.E_hist.values, ref.E_hist.values)


def test_netcdf_round_trip_and_sweep(tmp_path):
    config = _config(HARMONIC)
    ds = run(config, bias_paths=0)
    out = tmp_path / "h.nc"
    io.to_netcdf(ds, out)
    _same_joint(ds, io.open_results(out))
    # non-periodic: x as is, on the given range
    np.testing.assert_array_equal(ds.x_bin_edges.values[:, [0, -1]], [[-1.5, 1.5]] * 3)
    from stochpend.sweep import sweep

    base = {k: list(v) if isinstance(v, tuple) else v for k, v in HARMONIC.items() if k != "D"}
    swept = sweep({"base": base, "grid": {"D": [0.5, 0.8]}}, bias_paths=0)
    assert swept.joint_hist.dims == ("D", "time", "x_bin", "Omega_bin")
    np.testing.assert_array_equal(swept.joint_hist.sel(D=0.5).values, ds.joint_hist.values)
    with pytest.raises(ValueError, match=r"^.*joint_bins is not accepted: it differs between sets"):
        sweep({"base": {k: v for k, v in base.items() if k != "joint_bins"},
               "case": [{"D": 0.5, "joint_bins": [6, 5]}, {"D": 0.8, "joint_bins": [5, 5]}]}, bias_paths=0)


def test_show_prints_the_grid_and_the_marginal_check(tmp_path, damped):
    _, ds = damped
    out = tmp_path / "d.nc"
    io.to_netcdf(ds, out)
    result = CliRunner().invoke(cli.app, ["show", str(out)])
    assert result.exit_code == 0, result.output
    lines = [line for line in result.output.splitlines() if "joint" in line or "Omega marginal" in line
             or "finite paths" in line]
    assert any("12 x 10 bins" in line for line in lines), result.output
    assert any(": equal" in line for line in lines), result.output
    assert any("Omega marginal" in line for line in lines), result.output
    assert all(len(line) <= 80 for line in lines)


@pytest.mark.parametrize("kwargs, name", [
    (dict(joint_bins=(0, 5)), "joint_bins"),
    (dict(joint_bins=(5,)), "joint_bins"),
    (dict(joint_bins=(5, 501)), "joint_bins"),
    (dict(joint_bins=(5, 2.5)), "joint_bins"),
    (dict(joint_bins="5,5"), "joint_bins"),
    (dict(joint_bins=(5, 5), joint_Omega_max=-1.0), "joint_Omega_max"),
    (dict(joint_bins=(5, 5), joint_Omega_max=float("nan")), "joint_Omega_max"),
    (dict(joint_bins=(5, 5), joint_Omega_max=[1.0, 2.0]), "joint_Omega_max"),
    (dict(joint_bins=(5, 5), joint_x_range=(-1.0, 1.0)), "joint_x_range"),  # periodic
    (dict(joint_bins=(5, 5), potential="harmonic", joint_x_range=(1.0, -1.0)), "joint_x_range"),
    (dict(joint_bins=(5, 5), potential="harmonic", joint_x_range=(0.0, float("inf"))), "joint_x_range"),
    (dict(joint_bins=(5, 5), potential="harmonic", omega=0.0), "joint_x_range"),
    (dict(joint_Omega_max=1.0), "joint_Omega_max"),
])
def test_bad_input_is_one_line_naming_the_parameter(kwargs, name):
    with pytest.raises(ValueError) as info:
        SimulationConfig.build(paths=10, t_max=1.0, n_times=3, **kwargs)
    message = str(info.value)
    assert message.startswith(f"{name}=") and "is not accepted" in message and "\n" not in message, message


@pytest.mark.parametrize("args, option", [
    (["--joint-bins", "0,5"], "--joint-bins"),
    (["--joint-bins", "5"], "--joint-bins"),
    (["--joint-bins", "a,5"], "--joint-bins"),
    (["--joint-bins", "5,5", "--joint-Omega-max", "-2"], "--joint-Omega-max"),
    (["--joint-bins", "5,5", "--potential", "harmonic", "--joint-x-range", "3,1"], "--joint-x-range"),
])
def test_cli_refuses_bad_input_in_one_line_with_exit_code_2(args, option):
    result = CliRunner().invoke(cli.app, ["simulate", "--paths", "10", "--t-max", "1", "--quiet", *args])
    assert result.exit_code == 2, result.output
    text = result.output.strip()
    assert "Traceback" not in text and len(text.splitlines()) == 1, text
    assert option in text and "is not accepted" in text, text


def test_cli_simulate_writes_it(tmp_path):
    out = tmp_path / "c.nc"
    result = CliRunner().invoke(cli.app, ["simulate", "--paths", "200", "--t-max", "2", "--n-times", "2",
                                          "--bias-paths", "0", "--joint-bins", "6,4", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert "6 x 4 bins" in result.output
    ds = io.open_results(out)
    assert ds.joint_hist.shape == (2, 6, 4)
    np.testing.assert_array_equal(ds.joint_hist.values.sum(axis=(1, 2)) + ds.joint_hist_outside.values,
                                  ds.n_finite_paths.values)


# -- the CUDA backend, in the simulator (a process of its own) ---------------------------------
CUDA_CASES = {
    "pendulum": dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=48, t_max=1.0, times=[0.5, 1.0], seed=9,
                     joint_bins=[5, 4], n_batches=4),
    "harmonic": dict(noise="white", D=0.5, omega=1.0, potential="harmonic", paths=48, t_max=1.0,
                     times=[0.5, 1.0], seed=10, joint_bins=[4, 6], joint_x_range=[-1.0, 1.0],
                     joint_Omega_max=0.8, n_batches=4),
}


def test_cuda_simulator_counts_equal_the_cpu(tmp_path):
    pytest.importorskip("numba.cuda")
    spec = tmp_path / "cases.json"
    spec.write_text(json.dumps(CUDA_CASES))
    out = tmp_path / "out.npz"
    script = Path(__file__).with_name("_joint_cudasim.py")
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    done = subprocess.run([sys.executable, str(script), str(spec), str(out)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    with np.load(out) as data:
        simulated = {k: data[k] for k in data.files}
    for name, kwargs in CUDA_CASES.items():
        config = SimulationConfig.build(**kwargs)
        acc, _ = runner.run_batches(config, 0, config.n_batches, chunk_paths=kwargs["paths"] // 2)
        assert acc.hist.shape[1] == settings.hist_columns(config) > config.hist_bins + 2
        np.testing.assert_array_equal(simulated[f"{name}/hist"], acc.hist, err_msg=name)
        np.testing.assert_allclose(simulated[f"{name}/sums"], acc.sums, rtol=1e-12, atol=0.0, err_msg=name)


def test_a_configuration_file_sets_it(tmp_path):
    toml = tmp_path / "run.toml"
    toml.write_text("paths = 100\nt_max = 1.0\nn_times = 2\nbias_paths = 0\njoint_bins = [5, 3]\n"
                    "joint_Omega_max = 2.0\n", encoding="utf-8")
    out = tmp_path / "t.nc"
    result = CliRunner().invoke(cli.app, ["simulate", "--config", str(toml), "--quiet", "--out", str(out)])
    assert result.exit_code == 0, result.output
    ds = io.open_results(out)
    assert ds.joint_hist.shape == (2, 5, 3)
    np.testing.assert_array_equal(ds.Omega_bin_edges.values[:, [0, -1]], [[-2.0, 2.0]] * 2)


def test_the_error_is_the_delete_one_batch_jackknife_for_equal_batches():
    """From Σc_b, Σc_b² and Σc_b n_b alone: for batches of equal size the batch-means error
    of p = C/N is the delete-one-batch jackknife's exactly (and close to it otherwise)."""
    from stochpend.model.power_sums import EnsembleSums

    rng = np.random.default_rng(4)
    shape, n_e = (2, 3), 4
    cells = (shape[0] + 2) * (shape[1] + 2)
    for n_b in (np.full(12, 50), rng.integers(40, 60, size=12)):
        counts = np.array([rng.multinomial(n, np.full(cells, 1.0 / cells)) for n in n_b])  # (B, cells)
        acc = EnsembleSums.empty(len(n_b), 1, n_e - 2, (), joint_cells=cells)
        acc.sums[:, 0, 0] = n_b
        acc.filled[:] = True
        row = np.empty(3 * cells, dtype=np.int64)
        cpu.joint_sums(counts, n_b.astype(np.float64), row)
        acc.hist[0, n_e:] = row
        _, se = acc.joint(n_e, shape)
        loo = (counts.sum(axis=0) - counts) / (n_b.sum() - n_b)[:, None]
        b = len(n_b)
        jack = np.sqrt((b - 1) / b * ((loo - loo.mean(axis=0)) ** 2).sum(axis=0))
        rtol = 1e-12 if np.all(n_b == n_b[0]) else 0.05
        np.testing.assert_allclose(se[0].ravel(), jack, rtol=rtol)
