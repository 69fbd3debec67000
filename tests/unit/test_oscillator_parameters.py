"""An oscillator with a parameter of its own runs everywhere (issue 22, item 2, "a noise or
oscillator states its own parameters"): tests/unit/_tilted_well.py, the double well tilted by
``a`` (U = x^4/4 - x^2/2 + a x), declares ``a``, and

* the Python API takes it as a keyword; at a = 0 the run is the untilted double well's bit for
  bit, and without noise (D = 0, from rest at x0) the energy it conserves is the tilted one,
  omega**2 U(x0; a), to the integrator's tolerance;
* it is validated in one line, and a name both the noise and the oscillator declare is refused;
* the command line takes it as ``--param a=...`` with ``--plugin tests.unit._tilted_well`` and
  gives the API's numbers bit for bit; ``show`` and ``list`` print it;
* a checkpointed run resumes exactly (the checkpoint stores ``osc_params``);
* a sweep file takes it as a key;
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
from stochpend import io, models
from stochpend.engine import integrator
from stochpend.model.parameters import Parameter, split
from stochpend.model.settings import SimulationConfig
from stochpend.models import Model
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run
from tests._checkpoints import StopAfter
from tests.unit import _tilted_well
from tests.unit._user_models import DOUBLE_WELL, register_all

ROOT = Path(__file__).resolve().parents[2]
PLUGIN = "tests.unit._tilted_well"
SMALL = dict(potential="tilted-well", noise="ou", D=0.5, tau=1.0, omega=1.0, paths=300, t_max=5.0, n_times=3,
             seed=4, a=0.2)


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(ROOT), os.environ.get("PYTHONPATH", "")]),
            **extra}


def _cli(*args: str, cwd: Path, **env: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "stochpend", *args], cwd=cwd, env=_env(**env), capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def reference():
    models.register(_tilted_well.TILTED_WELL)  # (another test may have unregistered it)
    return stochpend.simulate(**SMALL, bias_paths=0)


def test_the_record_carries_the_declared_parameter():
    config = SimulationConfig.build(**{k: v for k, v in SMALL.items() if k != "a"}, noise_params={"a": 0.2})
    assert config.osc_params == (("a", 0.2),) and config.noise_params == ()
    assert integrator.step_record(config)[1] == (0.2,)
    assert SimulationConfig.build(potential="tilted-well").osc_params == (("a", 0.0),)  # the default
    power = SimulationConfig.build(potential="power", power_n=3)
    assert integrator.step_record(power)[1] == (3.0,) and power.osc_params == ()
    assert integrator.step_record(SimulationConfig.build())[1] == (0.0,)  # the pendulum: none
    attrs = config.to_attrs()
    assert attrs["potential_parameters"] == "a=0.2" and attrs["potential_a"] == 0.2
    assert "osc_params" not in attrs and "potential_parameters" not in SimulationConfig.build().to_attrs()
    assert "osc_params" not in ck.config_to_json(SimulationConfig.build())  # old hashes do not move
    assert ck.config_from_json(ck.config_to_json(config)) == config


def test_at_zero_tilt_it_is_the_double_well_bit_for_bit(reference):
    register_all()
    common = {k: v for k, v in SMALL.items() if k not in ("potential", "a")}
    tilted = stochpend.simulate(**common, potential="tilted-well", a=0.0, bias_paths=0)
    plain = stochpend.simulate(**common, potential="double-well", bias_paths=0)
    for name in ("mean_E", "mean_E_stderr", "mean_E2", "E_hist", "E_bin_edges"):
        assert np.array_equal(tilted[name].values, plain[name].values), name
    assert not np.array_equal(reference.mean_E.values, plain.mean_E.values)  # a = 0.2 is another run


@pytest.mark.parametrize("a", [0.0, 0.2, -0.5])
def test_without_noise_it_conserves_the_tilted_energy(a):
    """D = 0, from rest at x0 = 1.3: Stormer-Verlet keeps E = omega**2 U(x0; a) to O(h**2)
    (here 1e-4 of the barrier scale), which the untilted energy misses by |a x0| >= 0.26."""
    x0, omega = 1.3, 1.0
    E0 = omega**2 * _tilted_well.potential(x0, a)
    ds = stochpend.simulate(potential="tilted-well", noise="white", D=0.0, theta0=x0, Omega0=0.0, omega=omega,
                            paths=2, t_max=100.0, n_times=5, seed=1, n_batches=2, h_max=0.01, step_c=0.0,
                            a=a, bias_paths=0)
    assert np.all(np.abs(ds.mean_E.values - E0) < 1e-4), (ds.mean_E.values, E0)
    if a:
        assert np.all(np.abs(ds.mean_E.values - DOUBLE_WELL.potential(x0)) > 0.2)
    # The histogram's lower edge is the tilted well's bottom, min over x of U(x; a).
    grid = np.linspace(-10.0, 10.0, 20001)
    assert ds.E_bin_edges.values[0, 0] == pytest.approx(min(_tilted_well.potential(float(x), a) for x in grid))


def test_it_is_validated_and_a_name_declared_twice_is_refused(reference):
    with pytest.raises(ValueError, match=r"^a=1.5 is not accepted: a finite number in \[-1, 1\]"):
        stochpend.simulate(**{**SMALL, "a": 1.5})
    with pytest.raises(ValueError, match=r"^b=1 is not accepted: not a parameter of noise 'ou' \(its own parameters: "
                                         r"none\) nor of potential 'tilted-well' \(its own parameters: a\)$"):
        stochpend.simulate(**{**SMALL, "b": 1})
    with pytest.raises(ValueError, match=r"^Parameter name 'power_n' is not accepted"):
        Parameter("power_n", 1.0, "a run's own setting")
    # A model whose parameter a registered noise declares is refused when registered ...
    from tests.unit import _two_ou  # registers noise 'two-ou' (tau1, tau2, weight)

    clash = Model(name="clash", potential=lambda x, weight: weight * x * x, force=lambda x, weight: 2 * weight * x,
                  parameters=(Parameter("weight", 1.0, "a weight"),))
    with pytest.raises(ValueError, match=r"^model='clash' is not accepted: its parameter 'weight' is also a "
                                         r"parameter of noise 'two-ou'"):
        models.register(clash)
    # ... and, should the pieces meet anyway, so is the pair.
    with pytest.raises(ValueError, match=r"^noise='two-ou' with potential='clash' is not accepted: both declare "
                                         r"the parameter 'weight'"):
        split(_two_ou.TWO_OU, clash, {})


def test_its_functions_take_the_parameter_in_python_too():
    m = _tilted_well.TILTED_WELL
    assert m.defaults == (0.0,)
    assert m.oscillator.functions.potential(1.0, (0.2,)) == pytest.approx(-0.25 + 0.2)
    assert m.oscillator.functions.force(1.0, (0.2,)) == pytest.approx(0.2)
    assert m.energy_floor((0.0,)) == pytest.approx(-0.25)
    with pytest.raises(ValueError, match=r"^potential is not accepted: calling it with x=0.5, a=0 raised"):
        Model(name="bad", potential=lambda x: x, force=lambda x, a: a, parameters=(Parameter("a", 0.0, "a"),))


def test_the_command_line_gives_the_api_s_numbers(reference, tmp_path):
    done = _cli("simulate", "--plugin", PLUGIN, "--potential", "tilted-well", "--noise", "ou", "--D", "0.5",
                "--tau", "1", "--param", "a=0.2", "--paths", "300", "--t-max", "5", "--n-times", "3", "--seed", "4",
                "--bias-paths", "0", "--out", "x.nc", "-q", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    ds = io.open_results(tmp_path / "x.nc")
    for name in ("mean_E", "mean_E_stderr", "mean_E4", "E_hist"):
        assert np.array_equal(ds[name].values, reference[name].values), name
    assert ds.attrs["potential_a"] == 0.2
    shown = _cli("show", "x.nc", cwd=tmp_path, COLUMNS="200")
    assert shown.returncode == 0 and "a=0.2" in shown.stdout, shown.stdout
    listed = _cli("list", "--plugin", PLUGIN, cwd=tmp_path, COLUMNS="300")
    assert "tilted-well" in listed.stdout and "--param a=" in listed.stdout, listed.stdout


def test_a_checkpointed_run_resumes_exactly(tmp_path):
    models.register(_tilted_well.TILTED_WELL)
    config = SimulationConfig.build(potential="tilted-well", noise="ou", D=0.5, tau=1.0, paths=300, t_max=5.0,
                                    n_times=3, seed=5, noise_params={"a": -0.3})
    ref = run(config, chunk_paths=90, bias_paths=0)

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90, bias_paths=0,
                            checkpointer=StopAfter(path, None, config=config, n=4, chunk_paths=90, out=tmp_path / "r.nc"),
                            out=tmp_path / "r.nc")
    done = _cli("resume", "--plugin", PLUGIN, str(path), "-q", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    ds = io.open_results(tmp_path / "r.nc")
    assert ds.attrs["potential_a"] == -0.3
    for name in ("mean_E", "mean_E2_stderr", "nonfinite_paths"):
        assert np.array_equal(ds[name].values, ref[name].values), name


def test_a_sweep_file_takes_it_as_a_key():
    models.register(_tilted_well.TILTED_WELL)
    spec = {"base": {"potential": "tilted-well", "noise": "ou", "D": 0.5, "tau": 1.0, "paths": 200, "t_max": 4.0,
                     "n_times": 2, "seed": 6},
            "grid": {"a": [-0.2, 0.3]}}
    ds = stochpend.sweep.sweep(spec, scheduler="sync", bias_paths=0)
    for a in (-0.2, 0.3):
        alone = stochpend.simulate(potential="tilted-well", noise="ou", D=0.5, tau=1.0, paths=200, t_max=4.0,
                                   n_times=2, seed=6, a=a, bias_paths=0)
        assert np.array_equal(ds.sel(a=a).mean_E.values, alone.mean_E.values), a


_CUDASIM = """
import json
import stochpend
import tests.unit._tilted_well
ds = stochpend.simulate(potential="tilted-well", noise="ou", D=0.5, tau=1.0, paths=48, t_max=1.0, times=[0.5, 1.0],
                        seed=3, n_batches=4, backend="cuda", bias_paths=0, a=0.2)
print(json.dumps({"mean_E": ds.mean_E.values.tolist(), "backend": ds.attrs["backend"]}))
"""


@pytest.mark.gpu
def test_the_cuda_backend_agrees_with_the_cpu():
    done = subprocess.run([sys.executable, "-c", _CUDASIM], cwd=ROOT, env=_env(NUMBA_ENABLE_CUDASIM="1"),
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    gpu = json.loads(done.stdout.strip().splitlines()[-1])
    models.register(_tilted_well.TILTED_WELL)
    cpu = stochpend.simulate(potential="tilted-well", noise="ou", D=0.5, tau=1.0, paths=48, t_max=1.0,
                             times=[0.5, 1.0], seed=3, n_batches=4, bias_paths=0, a=0.2)
    assert gpu["backend"] == "cuda"
    np.testing.assert_allclose(gpu["mean_E"], cpu.mean_E.values, rtol=1e-9, atol=0)
