"""The CUDA backend against the CPU kernels, in Numba's CUDA simulator.

The simulator needs NUMBA_ENABLE_CUDASIM=1 before Numba is imported, while this process runs
the real CPU Numba, so the CUDA side runs once per session in a subprocess
(``_cudasim_check.py``) and its results are compared here with the CPU computed in-process.
The simulator executes the kernels as Python with the same shared scalar functions, so in
float64 the sums agree with the CPU to the last bit (asserted to 1e-12 relative) and the
histograms exactly. Ensembles are tiny: the simulator runs about 1e4 path-steps a second.
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

from stochpend import rng
from stochpend._backends import cpu
from stochpend._backends import cuda as gpu
from stochpend.params import SimulationConfig
from stochpend.simulate import cpu_kernels, run_batches
from tests.unit._user_models import register_all

register_all()

pytestmark = pytest.mark.gpu

HELPER = Path(__file__).with_name("_cudasim_check.py")

_COMMON = dict(t_max=2.0, times=[0.5, 1.0, 2.0], seed=7, paths=48, n_batches=4, hist_bins=8)

#: Each case: the configuration, the batches and chunking of the simulated run (the CPU
#: reference uses the default chunking: results must not depend on it).
CASES = [
    # OU, omega = 1, adaptive steps, two chunks.
    dict(name="ou_omega1", config=dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1,
                                       step_c=0.25, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6),
    # OU, omega = 0, overflow bin in use, fixed initial noise.
    dict(name="ou_omega0", config=dict(noise="ou", D=2.0, tau=0.5, omega=0.0, h_max=0.1,
                                       step_c=0.25, xi0=0.3, hist_E_max=0.2, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=12, check_paths=6),
    # White noise, omega = 1, fixed initial angle, a subset of the batches.
    dict(name="white_omega1", config=dict(noise="white", D=1.0, omega=1.0, h_max=0.1,
                                          step_c=0.25, theta0=1.0, Omega0=0.3, **_COMMON),
         first_batch=1, stop_batch=3, chunk_paths=1000, check_paths=6),
    # White noise, omega = 0, step budget of 2 steps a launch (several launches a segment).
    dict(name="white_omega0", config=dict(noise="white", D=0.5, omega=0.0, h_max=0.1,
                                          step_c=0.25, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=48, check_paths=6, launch=[1, 2]),
    # Unstable explicit steps (h = 5 in the well U = x**2/2 of the power-law code): the state
    # overflows to inf/nan during the segment, and the path is frozen as non-finite. (The
    # power n = 1 keeps x**n exact: Python's pow and Numba's repeated products differ in the
    # last bit for n > 2, which the exploding dynamics would amplify.)
    dict(name="blowup", config=dict(noise="white", D=1.0, omega=1.0, h_max=5.0, step_c=0.0,
                                    potential="power", power_n=1, coupling="position",
                                    **{**_COMMON, "t_max": 1500.0, "times": [500.0, 1500.0],
                                       "seed": 3}),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6),
    # A finite state whose moments overflow (E**4): escaped paths, frozen as non-finite.
    dict(name="escape", config=dict(noise="white", D=0.5, omega=1.0, h_max=0.5, step_c=0.0,
                                    potential="harmonic", Omega0=1e77, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6),
    # float32 against float64 with fixed steps: both take the same steps (the clock is float64
    # in both) and the same draws, so they differ by float32 rounding only.
    dict(name="f32_ou", config=dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1,
                                    step_c=0.0, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6, float32=True),
    dict(name="f32_white", config=dict(noise="white", D=1.0, omega=0.0, h_max=0.125,
                                       step_c=0.0, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=48, check_paths=6, float32=True),
]
CASES += [
    # The dichotomous noise: steps cut at the flips, a flip draw on the step that ends on one.
    dict(name="dichotomous", config=dict(noise="dichotomous", D=1.0, tau=0.3, omega=1.0,
                                         h_max=0.1, step_c=0.25, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6),
    # The harmonic noise: exact 3x3 update, two draws a step; underdamped W.
    dict(name="harmonic_noise", config=dict(noise="harmonic", D=1.0, tau=1.0, omega_noise=1.5,
                                            omega=1.0, h_max=0.1, step_c=0.25, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=48, check_paths=6),
    # A user-defined model (tests/unit/_user_models.py) with position coupling and OU noise.
    dict(name="user_model", config=dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1,
                                        step_c=0.25, potential="double-well",
                                        coupling="position", **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6),
]
CASE_NAMES = [case["name"] for case in CASES]
F64_CASES = CASE_NAMES  # every case checks float64 against the CPU
F32_CASES = [case["name"] for case in CASES if case.get("float32")]

#: float32 tolerance on the simulator (about 20 steps): sums relative to their scale
#: (observed ~1e-6), histogram counts moved across bin edges per output time (observed 0).
F32_SUMS_RTOL = 1e-4
F32_HIST_MOVES = 2


@pytest.fixture(scope="module")
def simulated(tmp_path_factory, cpu_results):
    """Run every case once in the CUDA simulator (a subprocess); returns the saved arrays.

    The CPU references are computed (and the CPU kernels compiled) while the subprocess runs.
    """
    folder = tmp_path_factory.mktemp("cudasim")
    spec = folder / "spec.json"
    out = folder / "out.npz"
    spec.write_text(json.dumps(CASES))
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    with subprocess.Popen(
        [sys.executable, str(HELPER), str(spec), str(out)],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    ) as child:
        try:
            for name in CASE_NAMES:
                cpu_results(name)
            stdout, stderr = child.communicate(timeout=600)
        finally:
            if child.poll() is None:
                child.kill()
    if child.returncode != 0:
        pytest.fail(f"CUDA simulator run failed:\n{stdout}\n{stderr[-5000:]}")
    with np.load(out) as data:
        return {key: data[key] for key in data.files}


def _case(name: str) -> dict:
    return next(case for case in CASES if case["name"] == name)


def _config(name: str) -> SimulationConfig:
    return SimulationConfig.build(**_case(name)["config"])


def _cpu_states(config: SimulationConfig, n: int) -> dict[str, np.ndarray]:
    """Paths 0..n-1 through every output time with the CPU kernels (as in run_batches)."""
    init_paths, advance_paths, _ = cpu_kernels(config)
    x, Omega, xi, t = (np.empty(n) for _ in range(4))
    k = np.empty(n, dtype=np.uint64)
    status = np.empty(n, dtype=np.uint8)
    t_comp = np.empty(n)
    xi_aux = np.empty(n)
    key0, key1 = rng.seed_to_key(config.seed)
    init_paths(x, Omega, xi, t, k, status, key0, key1, 0,
                   0.0 if config.theta0 is None else config.theta0, config.theta0 is None,
                   config.Omega0, 0.0 if config.xi0 is None else config.xi0, config.xi0 is None,
                   config.D, config.tau_or_zero, config.noise_code, t_comp, xi_aux,
                   config.omega_noise_or_zero)
    pot = config.potential_code
    cpl = config.coupling_code
    for t_target in config.times:
        while advance_paths(x, Omega, xi, t, k, status, t_target, 1000, config.noise_code,
                                config.D, config.tau_or_zero, config.omega**2, config.h_max,
                                config.step_c, pot, config.power_n, cpl, key0, key1, 0, t_comp, xi_aux,
                                config.omega_noise_or_zero)[1]:
            pass
    return dict(x=x, Omega=Omega, xi=xi, t=t, k=k, status=status)


def _check_cpu_kernels_are_current() -> None:
    """The CPU kernels must compute what the shared functions' current source says.

    Numba's on-disk cache (``cache=True``) is invalidated by edits to cpu.py only, not to the
    rng/physics/schemes functions it inlines, so after such an edit the CPU kernels may run old
    code. Compare one initial condition and one OU step with the Python functions.
    """
    from stochpend import schemes

    config = SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=1, t_max=0.1,
                                    times=[0.1], seed=5, h_max=0.1, step_c=0.0, n_batches=2)
    state = _cpu_states(config, 1)
    key0, key1 = rng.seed_to_key(config.seed)
    u, _ = rng.draw_uniforms(key0, key1, np.uint64(0), np.uint64(rng.N_INIT_THETA))
    z, _ = rng.draw_normals(key0, key1, np.uint64(0), np.uint64(rng.N_INIT_XI))
    x0, xi0 = 2.0 * math.pi * u - math.pi, math.sqrt(1.0 / 2.0) * z
    z1, z2 = rng.draw_normals(key0, key1, np.uint64(0), np.uint64(rng.N_FIRST_STEP))
    a, s_xi, m_I, c_I, s_I = schemes.ou_step_coefficients(0.1, 1.0, 1.0)
    x1, Omega1 = schemes.verlet_step(x0, 0.0, 0.1, 1.0, m_I * xi0 + c_I * z1 + s_I * z2, 0, 2, 0)
    expected = (x1, Omega1, a * xi0 + s_xi * z1)
    found = (state["x"][0], state["Omega"][0], state["xi"][0])
    if found != expected:
        pytest.fail(
            f"the CPU kernels do not compute what rng/schemes say (state {found} != {expected}): "
            "most likely a stale Numba cache, which cache=True keys on cpu.py alone; delete "
            "src/stochpend/_backends/__pycache__/*.nbi and *.nbc (or set NUMBA_CACHE_DIR) and rerun"
        )


@pytest.fixture(scope="module")
def cpu_results():
    _check_cpu_kernels_are_current()
    cache: dict[str, tuple] = {}

    def get(name: str):
        if name not in cache:
            case = _case(name)
            config = _config(name)
            sums, steps = run_batches(config, case["first_batch"], case["stop_batch"])
            cache[name] = (sums, steps, _cpu_states(config, case["check_paths"]))
        return cache[name]

    return get


# -- float64: the simulator equals the CPU ----------------------------------------------------
@pytest.mark.parametrize("name", F64_CASES)
def test_sums_and_histogram_equal_cpu(simulated, cpu_results, name):
    cpu_sums, cpu_steps, _ = cpu_results(name)
    sums = simulated[f"{name}/sums"]
    assert sums.shape == cpu_sums.sums.shape
    np.testing.assert_array_equal(simulated[f"{name}/filled"], cpu_sums.filled)
    np.testing.assert_allclose(sums, cpu_sums.sums, rtol=1e-12, atol=0.0)
    np.testing.assert_array_equal(simulated[f"{name}/hist"], cpu_sums.hist)
    assert int(simulated[f"{name}/path_steps"]) == cpu_steps


@pytest.mark.parametrize("name", F64_CASES)
def test_final_states_equal_cpu_path_by_path(simulated, cpu_results, name):
    _, _, states = cpu_results(name)
    for key in ("x", "Omega", "xi"):
        np.testing.assert_allclose(simulated[f"{name}/state_{key}"], states[key], rtol=1e-12,
                                   atol=1e-300, err_msg=key)
    for key in ("t", "k", "status"):
        np.testing.assert_array_equal(simulated[f"{name}/state_{key}"], states[key], err_msg=key)


def test_cases_exercise_what_they_claim(simulated, cpu_results):
    """Guards the test data: blow-ups, overflow bin, relaunches and chunks really happen."""
    blowup, _, blowup_states = cpu_results("blowup")
    assert blowup.sums[..., cpu.S_NONFINITE].sum() > 0
    assert not np.all(np.isfinite(blowup_states["x"]))  # went non-finite while stepping
    escape, _, _ = cpu_results("escape")
    assert np.all(escape.sums[..., cpu.S_NONFINITE].sum(axis=0) == _COMMON["paths"])
    overflow, _, _ = cpu_results("ou_omega0")
    assert overflow.hist[:, -1].sum() > 0
    # Several launches a segment report progress more often than once per output time.
    updates = simulated["white_omega0/progress_updates"]
    assert updates.size > len(_COMMON["times"])
    assert np.all(np.diff(updates) >= 0)
    subset = simulated["white_omega1/filled"]
    assert subset.tolist() == [False, True, True, False]


@pytest.mark.parametrize("name", CASE_NAMES)
def test_progress_reports_all_work(simulated, name):
    case = _case(name)
    config = _config(name)
    bs = config.batch_size
    paths = min(case["stop_batch"] * bs, config.paths) - case["first_batch"] * bs
    total = float(simulated[f"{name}/progress_total"])
    assert total == pytest.approx(paths * config.t_max)
    updates = simulated[f"{name}/progress_updates"]
    assert updates[-1] <= total * (1 + 1e-12)
    assert bool(simulated[f"{name}/progress_finished"])


# -- float32 -----------------------------------------------------------------------------------
@pytest.mark.parametrize("name", F32_CASES)
def test_float32_agrees_with_float64(simulated, name):
    s64, s32 = simulated[f"{name}/sums"], simulated[f"{name}/sums32"]
    scale = np.max(np.abs(s64), axis=0, keepdims=True)  # per time and column
    assert np.all(np.abs(s32 - s64) <= F32_SUMS_RTOL * scale)
    moves = np.abs(simulated[f"{name}/hist32"] - simulated[f"{name}/hist"]).sum(axis=1)
    assert np.all(moves <= 2 * F32_HIST_MOVES)
    assert int(simulated[f"{name}/path_steps32"]) == int(simulated[f"{name}/path_steps"])
    assert simulated[f"{name}/state32_x"].dtype == np.float32
    for key in ("Omega", "xi"):
        np.testing.assert_allclose(simulated[f"{name}/state32_{key}"], simulated[f"{name}/state_{key}"],
                                   rtol=0, atol=1e-4, err_msg=key)


def test_float32_variants_compute_in_float32():
    """The float32 variants are derived from the shared source and type as float32 in Numba."""
    import numba

    f32 = gpu._float32_variants()
    verlet_step, step_size = f32.verlet_step, f32.step_size
    ou_step_coefficients, draw_normals = f32.ou_step_coefficients, f32.draw_normals
    f = np.float32

    @numba.njit
    def step(x, Om, h, omega2, noise, xi, D, tau, key0, key1):
        x1, Om1 = verlet_step(x, Om, h, omega2, noise, 0, 2, 0)
        hh = step_size(Om1, xi, x1, h, f(0.25), omega2, 0, 2, 0)
        a, s_xi, m_I, c_I, s_I = ou_step_coefficients(hh, D, tau)
        z1, z2 = draw_normals(key0, key1, np.uint64(3), np.uint64(5))
        return x1, Om1, hh, a, s_xi, m_I, c_I, s_I, z1, z2

    key0, key1 = rng.seed_to_key(11)
    args = (f(3.1), f(2.5), f(0.05), f(1.0), f(0.01), f(0.4), f(1.0), f(1.0), key0, key1)
    out = step(*args)
    signature = step.nopython_signatures[0].return_type
    assert all(str(t) == "float32" for t in signature.types), signature
    from stochpend import schemes

    x1, Om1 = schemes.verlet_step(3.1, 2.5, 0.05, 1.0, 0.01, 0, 2, 0)
    hh = schemes.step_size(Om1, 0.4, x1, 0.05, 0.25, 1.0, 0, 2, 0)
    ref = (x1, Om1, hh, *schemes.ou_step_coefficients(hh, 1.0, 1.0),
           *rng.draw_normals(key0, key1, np.uint64(3), np.uint64(5)))
    np.testing.assert_allclose(np.array(out, dtype=np.float64), ref, rtol=2e-6)


# -- pieces that need no simulator -------------------------------------------------------------
def test_hist_column_is_searchsorted():
    rs = np.random.default_rng(0)
    edges = np.sort(rs.normal(size=(3, 9)), axis=1)
    for j in range(3):
        for E in np.concatenate([rs.normal(scale=2, size=200), edges[j]]):
            if E < edges[j, 0]:
                expected = 0
            elif E >= edges[j, -1]:
                expected = edges.shape[1]
            else:
                expected = int(np.searchsorted(edges[j], E, side="right"))
            assert gpu.hist_column(edges, j, E) == expected


def test_availability_without_gpu_is_a_clean_no():
    ok, reason = gpu.availability()
    assert isinstance(ok, bool) and isinstance(reason, str) and reason
    assert "\n" not in reason
    if not ok:  # this machine: no driver, no GPU
        config = _config("ou_omega1")
        with pytest.raises(RuntimeError, match="backend='cuda' is not usable here") as info:
            gpu.run_batches(config, 0, config.n_batches)
        assert "\n" not in str(info.value)


def test_availability_reasons(monkeypatch):
    monkeypatch.setattr(gpu, "_simulator_enabled", lambda: False)

    def no_driver() -> int:
        raise OSError("libcuda.so:\n cannot open shared object file")

    monkeypatch.setattr(gpu, "_device_count", no_driver)
    ok, reason = gpu.availability()
    assert not ok and "no usable CUDA driver" in reason and "\n" not in reason
    monkeypatch.setattr(gpu, "_device_count", lambda: 0)
    assert gpu.availability() == (False, "the CUDA driver reports no GPU")
    monkeypatch.setattr(gpu, "cuda", None)
    ok, reason = gpu.availability()
    assert not ok and "numba.cuda cannot be imported" in reason


def test_bad_arguments_are_refused_first():
    config = _config("ou_omega1")
    with pytest.raises(ValueError, match="precision='float16' is not accepted"):
        gpu.run_batches(config, 0, 1, precision="float16")


def test_simulator_reports_itself(simulated):
    assert bool(simulated["availability_ok"])
    assert "simulator" in str(simulated["availability_reason"])


def test_simulated_cases_are_small(simulated):
    """Keep this file fast: each simulated case should take a few seconds at most."""
    seconds = {name: float(simulated[f"{name}/seconds"]) for name in CASE_NAMES}
    assert math.fsum(seconds.values()) < 120, seconds
