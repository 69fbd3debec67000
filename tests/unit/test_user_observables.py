"""Observables users write (issue 22, item 3): a function of one path's state (x, Omega, xi, t)
whose ensemble mean a run reports with its standard error and bias estimate.

The strongest check is an observable that spells a built-in one: ``Omega * Omega`` must give
``mean_Omega2`` to the last bit (value, error, bias), since it is the same arithmetic summed in
the same order -- on the CPU here and in Numba's CUDA simulator in a subprocess. The others
check what only a user observable sees: the noise's value xi (the OU law's moments within
|z| < 4) and the time t (the output time, to rounding), exclusion of a path whose value is not
finite, checkpoints and resume, and one-line refusals.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import stochpend
from stochpend.model.settings import SimulationConfig
from stochpend.observables import Observable, register, unregister
from stochpend.runs import checkpoint as ck
from stochpend.runs.simulate import run
from tests._checkpoints import StopAfter

RUN = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=2000, t_max=10.0, n_times=4, seed=11)


@pytest.fixture(autouse=True)
def observables():
    register(Observable("Omega2_user", lambda x, Omega, xi, t: Omega * Omega))
    register(Observable("xi", lambda x, Omega, xi, t: xi, label="⟨ξ⟩"))
    register(Observable("xi2", lambda x, Omega, xi, t: xi * xi))
    register(Observable("t", lambda x, Omega, xi, t: t))
    yield
    for name in ("Omega2_user", "xi", "xi2", "t", "inf_right", "cos_x"):
        unregister(name)


def test_a_user_observable_that_spells_omega2_is_bit_identical_to_the_built_in_one():
    ds = stochpend.simulate(**RUN, bias_paths=128, observables=("Omega2_user",))
    for suffix in ("", "_stderr", "_bias", "_bias_stderr", "_bias_verdict"):
        a, b = ds[f"mean_Omega2_user{suffix}"].values, ds[f"mean_Omega2{suffix}"].values
        assert np.array_equal(a, b), suffix
    assert ds.attrs["observables"] == "Omega2_user"
    assert "Omega * Omega" in ds.attrs["observable_Omega2_user_source"]
    # The table's statistics do not move when a run adds observables; their verdicts may, since
    # the family of simultaneous intervals now holds the observable's entries too.
    plain = stochpend.simulate(**RUN, bias_paths=128)
    for name in plain.data_vars:
        if not name.endswith("_bias_verdict"):
            assert np.array_equal(plain[name].values, ds[name].values, equal_nan=True), name
    assert ds.attrs["bias_tests"] == plain.attrs["bias_tests"] + np.count_nonzero(np.isfinite(ds.mean_Omega2_user_bias))


def test_the_noise_value_and_the_time_reach_the_observable():
    ds = stochpend.simulate(**RUN, bias_paths=0, observables=("xi", "xi2", "t"))
    # OU from its stationary law: <xi> = 0, <xi^2> = D/(2 tau) at every time.
    z_mean = ds.mean_xi.values / ds.mean_xi_stderr.values
    z_var = (ds.mean_xi2.values - RUN["D"] / (2 * RUN["tau"])) / ds.mean_xi2_stderr.values
    assert np.all(np.abs(z_mean) < 4) and np.all(np.abs(z_var) < 4), (z_mean, z_var)
    assert ds.mean_xi.attrs["long_name"] == "⟨ξ⟩"
    # Every path lands on the output time (the mean of equal numbers, to rounding).
    assert np.allclose(ds.mean_t.values, ds.time.values, rtol=1e-13, atol=0)


def test_a_path_whose_observable_is_not_finite_is_excluded_and_counted():
    register(Observable("inf_right", lambda x, Omega, xi, t: math.inf if x > 2.5 else 1.0))
    ds = stochpend.simulate(**RUN, bias_paths=0, observables=("inf_right",))
    lost = ds.nonfinite_paths.values
    assert lost[0] > 0 and np.all(np.diff(lost) >= 0)  # excluded from then on
    assert np.all(ds.n_finite_paths.values + lost == RUN["paths"])
    assert np.all(ds.mean_inf_right.values == 1.0)  # never averaged in


def test_checkpointed_auto_run_with_an_observable_resumes_its_bias(tmp_path):
    """The pilot saved with an auto run's checkpoint holds the observable's bias too."""
    config = SimulationConfig.build(noise="ou", paths=1000, t_max=10.0, times=(5.0, 10.0), seed=3, h_max=0.4,
                                    step_c=0.8, observables=("xi2",))
    ref = run(config, chunk_paths=300, accuracy="auto", bias_paths=256)
    assert ref.attrs["accuracy_level"] >= 1 and "mean_xi2_bias" in ref

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=300, accuracy="auto",
                            bias_paths=256, checkpointer=StopAfter(path, None, config=config, n=3, chunk_paths=300))
    done = ck.resume(path)
    assert set(done.data_vars) == set(ref.data_vars)
    for name in ref.data_vars:
        assert np.array_equal(done[name].values, ref[name].values, equal_nan=True), name


def test_checkpointed_run_with_an_observable_resumes_exactly(tmp_path):
    config = SimulationConfig.build(**{**RUN, "paths": 300}, observables=("xi2",))
    ref = run(config, chunk_paths=90, bias_paths=0)

    path = tmp_path / "run.ckpt"
    with pytest.raises(KeyboardInterrupt):
        ck.run_checkpointed(config, checkpoint_path=path, every_s=None, chunk_paths=90,
                            checkpointer=StopAfter(path, None, config=config, n=5, chunk_paths=90))
    # A process that has not registered the observable refuses in one line, naming it.
    unregister("xi2")
    with pytest.raises(ValueError, match="'xi2' is not a registered observable"):
        ck.resume(path)
    register(Observable("xi2", lambda x, Omega, xi, t: xi * xi))
    done = ck.resume(path)
    for name in ("mean_xi2", "mean_xi2_stderr", "mean_E", "nonfinite_paths"):
        assert np.array_equal(done[name].values, ref[name].values), name


@pytest.mark.parametrize("kwargs, message", [
    (dict(observables=("nope",)), "observables=('nope',) is not accepted: 'nope' is not a registered observable"),
    (dict(observables=("xi", "xi")), "a name appears twice"),
    (dict(observables=3), "observables=3 is not accepted"),
])
def test_a_run_asking_for_an_unknown_observable_is_refused_in_one_line(kwargs, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")) as info:
        stochpend.simulate(**RUN, **kwargs)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("name, value, message", [
    ("E2", lambda x, Omega, xi, t: 1.0, "mean_E2 is a built-in statistic"),
    ("2x", lambda x, Omega, xi, t: 1.0, "a letter, then letters, digits or _"),
    ("bad", lambda x, Omega: 1.0, "raised TypeError"),
    ("nan", lambda x, Omega, xi, t: math.nan, "it returned nan"),
])
def test_an_observable_that_cannot_work_is_refused_where_it_is_declared(name, value, message):
    with pytest.raises(ValueError, match=message):
        Observable(name, value)


_CUDASIM = """
import json, sys
import numpy as np
import stochpend
from stochpend.observables import Observable, register
register(Observable("Omega2_user", lambda x, Omega, xi, t: Omega * Omega))
register(Observable("t", lambda x, Omega, xi, t: t))
ds = stochpend.simulate(noise="white", D=1.0, omega=1.0, paths=48, t_max=1.0, times=[0.5, 1.0], seed=3,
                        n_batches=4, backend="cuda", bias_paths=0, observables=("Omega2_user", "t"))
print(json.dumps({"same": bool(np.array_equal(ds.mean_Omega2_user.values, ds.mean_Omega2.values)
                               and np.array_equal(ds.mean_Omega2_user_stderr.values, ds.mean_Omega2_stderr.values)),
                  "t": ds.mean_t.values.tolist(), "time": ds.time.values.tolist(),
                  "backend": ds.attrs["backend"]}))
"""


@pytest.mark.gpu
def test_user_observables_in_the_cuda_simulator():
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1",
           "PYTHONPATH": os.pathsep.join([str(Path(stochpend.__file__).resolve().parents[1]),
                                          os.environ.get("PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-c", _CUDASIM], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    r = json.loads(done.stdout.strip().splitlines()[-1])
    assert r["backend"] == "cuda" and r["same"]
    assert np.allclose(r["t"], r["time"], rtol=1e-13, atol=0)
