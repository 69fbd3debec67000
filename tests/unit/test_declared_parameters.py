"""A noise with parameters of its own runs everywhere with no file of stochpend changed
(issue 22, item 2): tests/unit/_two_ou.py, the sum of two OU processes with correlation times
tau1, tau2 and a weight, declares them, and

* the Python API takes them as keywords and its ensemble has the law it was built with: the
  stationary variance of xi (a user observable) within |z| < 4, and at weight = 1 the built-in
  OU noise's energy statistics within |z| < 4;
* the command line takes them as ``--param`` with ``--plugin tests.unit._two_ou`` and gives the
  API's numbers bit for bit; ``show`` prints them;
* a checkpointed run resumes exactly, and a resume in a process that was not given the plugin
  is refused in one line (a checkpoint names its noise, it never loads it);
* a sweep over them on a two-process Dask LocalCluster gives each set's numbers bit for bit;
* the CUDA backend (Numba's simulator) agrees with the CPU.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import stochpend
from stochpend import io, plugins
from stochpend.model.settings import SimulationConfig
from stochpend.observables import Observable, register, unregister
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run
from tests._checkpoints import StopAfter
from tests.unit import _two_ou

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = "tests.unit._two_ou"
OWN = dict(tau1=0.5, tau2=5.0, weight=0.3)
SMALL = dict(noise="two-ou", D=1.0, omega=1.0, paths=400, t_max=5.0, n_times=3, seed=4, **OWN)


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")]),
            **extra}


def _cli(*args: str, cwd: Path, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stochpend", *args], cwd=cwd, env=_env(**env), capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def reference():
    return stochpend.simulate(**SMALL, bias_paths=0)


def test_its_ensemble_has_the_law_it_declares():
    register(Observable("xi2", lambda x, Omega, xi, t: xi * xi))
    try:
        ds = stochpend.simulate(noise="two-ou", D=2.0, omega=1.0, paths=20_000, t_max=10.0, n_times=3, seed=8,
                                bias_paths=0, observables=("xi2",), **OWN)
    finally:
        unregister("xi2")
    z = (ds.mean_xi2.values - _two_ou.variance(2.0, **OWN)) / ds.mean_xi2_stderr.values
    assert np.all(np.abs(z) < 4), z
    assert ds.attrs["noise_tau1"] == 0.5 and ds.attrs["noise_parameters"] == "tau1=0.5, tau2=5, weight=0.3"


def test_at_weight_one_it_is_the_ou_noise_in_law():
    common = dict(D=1.0, omega=1.0, paths=20_000, t_max=20.0, n_times=4, bias_paths=0)
    two = stochpend.simulate(noise="two-ou", tau1=1.0, weight=1.0, seed=1, **common)
    one = stochpend.simulate(noise="ou", tau=1.0, seed=2, **common)
    for name in ("mean_E", "mean_E2", "mean_Omega2"):
        z = (two[name].values - one[name].values) / np.hypot(two[f"{name}_stderr"].values, one[f"{name}_stderr"].values)
        assert np.all(np.abs(z) < 4), (name, z)


def test_its_parameters_change_the_numbers_and_are_validated(reference):
    other = stochpend.simulate(**{**SMALL, "weight": 0.9}, bias_paths=0)
    assert not np.array_equal(other.mean_E.values, reference.mean_E.values)
    with pytest.raises(ValueError, match=r"^weight=1.5 is not accepted: a finite number in \[0, 1\]"):
        stochpend.simulate(**{**SMALL, "weight": 1.5})
    with pytest.raises(ValueError, match="tau=2 is not accepted|tau3=1 is not accepted"):
        stochpend.simulate(**{**SMALL, "tau3": 1})


def test_the_command_line_gives_the_api_s_numbers(reference, tmp_path):
    done = _cli("simulate", "--plugin", PLUGIN, "--noise", "two-ou", "--param", "tau1=0.5", "--param", "tau2=5",
                "--param", "weight=0.3", "--paths", "400", "--t-max", "5", "--n-times", "3", "--seed", "4",
                "--bias-paths", "0", "--out", "x.nc", "-q", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    ds = io.open_results(tmp_path / "x.nc")
    for name in ("mean_E", "mean_E_stderr", "mean_E4", "E_hist"):
        assert np.array_equal(ds[name].values, reference[name].values), name
    shown = _cli("show", "x.nc", cwd=tmp_path, COLUMNS="200")
    assert shown.returncode == 0 and "tau1=0.5, tau2=5, weight=0.3" in shown.stdout, shown.stdout
    listed = _cli("list", "--plugin", PLUGIN, cwd=tmp_path, COLUMNS="300")
    assert "two-ou" in listed.stdout and "--param weight=" in listed.stdout, listed.stdout


def test_a_checkpointed_run_resumes_exactly_and_only_with_the_plugin(tmp_path):
    config = SimulationConfig.build(noise="two-ou", D=1.0, omega=1.0, paths=300, t_max=5.0, n_times=3, seed=5,
                                    noise_params=OWN)
    ref = run(config, chunk_paths=90, bias_paths=0)

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90, bias_paths=0,
                            checkpointer=StopAfter(path, None, config=config, n=4, chunk_paths=90, out=tmp_path / "r.nc"),
                            out=tmp_path / "r.nc")
    refused = _cli("resume", str(path), cwd=tmp_path)
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    assert "two-ou" in refused.stderr and path.is_file()
    done = _cli("resume", "--plugin", PLUGIN, str(path), "-q", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    ds = io.open_results(tmp_path / "r.nc")
    assert ds.attrs["noise_weight"] == 0.3
    for name in ("mean_E", "mean_E2_stderr", "nonfinite_paths"):
        assert np.array_equal(ds[name].values, ref[name].values), name


def test_a_sweep_over_its_parameters_on_dask_workers(tmp_path):
    pytest.importorskip("distributed")
    plugins.load(PLUGIN)  # what the command line's --plugin does: the workers load it too
    spec = {"base": {"noise": "two-ou", "D": 1.0, "omega": 1.0, "paths": 200, "t_max": 4.0, "n_times": 2,
                     "seed": 6, "tau2": 5.0},
            "grid": {"tau1": [0.5, 2.0], "weight": [0.2, 0.8]}}
    ds = stochpend.sweep.sweep(spec, scheduler="local", workers=2, bias_paths=0)
    for tau1 in (0.5, 2.0):
        for weight in (0.2, 0.8):
            alone = stochpend.simulate(noise="two-ou", D=1.0, omega=1.0, paths=200, t_max=4.0, n_times=2, seed=6,
                                       tau1=tau1, tau2=5.0, weight=weight, bias_paths=0)
            got = ds.sel(tau1=tau1, weight=weight)
            assert np.array_equal(got.mean_E.values, alone.mean_E.values), (tau1, weight)


_CUDASIM = """
import json
import stochpend
import tests.unit._two_ou
ds = stochpend.simulate(noise="two-ou", D=1.0, omega=1.0, paths=48, t_max=1.0, times=[0.5, 1.0], seed=3,
                        n_batches=4, backend="cuda", bias_paths=0, tau1=0.5, tau2=5.0, weight=0.3)
print(json.dumps({"mean_E": ds.mean_E.values.tolist(), "backend": ds.attrs["backend"]}))
"""


@pytest.mark.gpu
def test_the_cuda_backend_agrees_with_the_cpu():
    done = subprocess.run([sys.executable, "-c", _CUDASIM], cwd=ROOT, env=_env(NUMBA_ENABLE_CUDASIM="1"),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    gpu = json.loads(done.stdout.strip().splitlines()[-1])
    cpu = stochpend.simulate(noise="two-ou", D=1.0, omega=1.0, paths=48, t_max=1.0, times=[0.5, 1.0], seed=3,
                             n_batches=4, bias_paths=0, **OWN)
    assert gpu["backend"] == "cuda"
    np.testing.assert_allclose(gpu["mean_E"], cpu.mean_E.values, rtol=1e-9, atol=0)
