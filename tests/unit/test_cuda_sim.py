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
import sys
from pathlib import Path

import numpy as np
import pytest

from stochpend.engine import cpu, integrator, runner
from stochpend.engine import cuda as gpu
from stochpend.engine.runner import run_batches
from stochpend.model.settings import SimulationConfig
from stochpend.noises import ou
from stochpend.numerics import rng
from stochpend.numerics.mathlib import LIBM
from stochpend.observables import S_COUNT, S_NONFINITE, Observable, column
from tests import _background
from tests._kernels import Paths
from tests.unit import _phase_noise
from tests.unit._user_models import register_all

register_all()
_phase_noise.register()

S_E1, S_E2 = column("E"), column("E2")

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
CASES += [
    # A noise defined in a test file (tests/unit/_phase_noise.py), registered at run time.
    dict(name="phase_drive", config=dict(noise="phase-drive", D=1.0, tau=0.5, omega_noise=3.0,
                                         omega=1.0, h_max=0.1, step_c=0.25, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6, float32=True),
    # float32 for every noise and for a user model: the pieces built for numpy.float32 by the
    # same factories. Fixed steps, so float32 takes float64's steps (the clock is float64).
    dict(name="f32_dichotomous", config=dict(noise="dichotomous", D=1.0, tau=0.3, omega=1.0,
                                             h_max=0.1, step_c=0.0, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6, float32=True),
    dict(name="f32_harmonic_noise", config=dict(noise="harmonic", D=1.0, tau=1.0, omega_noise=1.5,
                                                omega=1.0, h_max=0.1, step_c=0.0, **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=48, check_paths=6, float32=True),
    dict(name="f32_user_model", config=dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1,
                                            step_c=0.0, potential="double-well",
                                            coupling="position", **_COMMON),
         first_batch=0, stop_batch=4, chunk_paths=24, check_paths=6, float32=True),
]
#: Paths of each precision in the float32-vs-float64 two-sample test.
PAIR_PATHS = 1000

#: Runs through the runner's other features on the GPU (not compared with the CPU).
EXTRAS = [
    # Interrupted at the 5th checkpoint opportunity (in the second of two chunks), then resumed.
    dict(name="ckpt_ou", kind="checkpoint", stop_after=5, chunk_paths=24,
         config=dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1, step_c=0.25, **_COMMON)),
    dict(name="ckpt_dichotomous_f32", kind="checkpoint", stop_after=9, chunk_paths=12,
         precision="float32",
         config=dict(noise="dichotomous", D=1.0, tau=0.3, omega=1.0, h_max=0.1, step_c=0.25,
                     **_COMMON)),
    dict(name="sweep", kind="sweep",
         spec={"base": dict(noise="ou", tau=1.0, omega=1.0, h_max=0.1, step_c=0.25, **_COMMON),
               "case": [{"D": 1.0}, {"D": 0.5, "seed": 8}]}),
]
EXTRAS += [
    # Philox words and both normal pairs in a kernel, against the CPU (test_rng_in_kernel_...).
    dict(name="rng", kind="rng", n=512, seed=2**40 + 12345),
    # float32 against float64 as two independent ensembles (seeds differ): mean E in standard
    # errors. A fixed start (theta0 = 1, Omega0 = 0): the spread of E comes from the noise alone.
    dict(name="precision_pair", kind="precision_pair", seeds=[31, 32],
         config=dict(noise="ou", D=2.0, tau=1.0, omega=1.0, h_max=0.05, step_c=0.0, theta0=1.0,
                     Omega0=0.0, t_max=2.0, times=[0.5, 1.0, 2.0], paths=PAIR_PATHS,
                     n_batches=10, hist_bins=4)),
    # The bias estimate's pairs on the GPU, in two chunks of 16 (test_gpu_bias_pairs_equal_cpu).
    dict(name="bias_pairs", kind="bias", pairs=32, chunk_pairs=16,
         config=dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1, step_c=0.25, **_COMMON)),
]
CASE_NAMES = [case["name"] for case in CASES]
F64_CASES = CASE_NAMES  # every case checks float64 against the CPU
F32_CASES = [case["name"] for case in CASES if case.get("float32")]

#: float32 tolerance on the simulator (about 20 steps): sums relative to their scale
#: (observed ~1e-6), histogram counts moved across bin edges per output time (observed 0).
F32_SUMS_RTOL = 1e-4
F32_HIST_MOVES = 2


def background_run(folder: Path) -> _background.Command:
    """Every case in the CUDA simulator (a subprocess, about 100 s), started with the session
    (tests/_background.py)."""
    spec = folder / "spec.json"
    spec.write_text(json.dumps(CASES + EXTRAS))
    return _background.Command([sys.executable, str(HELPER), str(spec), str(folder / "out.npz")],
                               env={**os.environ, "NUMBA_ENABLE_CUDASIM": "1"})


@pytest.fixture(scope="module")
def simulated(cpu_results):
    """Run every case once in the CUDA simulator (a subprocess); returns the saved arrays.

    The CPU references are computed (and the CPU kernels compiled) while the subprocess runs.
    """
    run = _background.start(__name__, background_run)
    for name in CASE_NAMES:
        cpu_results(name)
    done = run.wait(timeout=600)
    if done.returncode != 0:
        pytest.fail(f"CUDA simulator run failed:\n{done.stdout}\n{done.stderr[-5000:]}")
    with np.load(run.folder / "out.npz") as data:
        return {key: data[key] for key in data.files}


def _case(name: str) -> dict:
    return next(case for case in CASES if case["name"] == name)


def _config(name: str) -> SimulationConfig:
    return SimulationConfig.build(**_case(name)["config"])


def _cpu_states(config: SimulationConfig, n: int) -> dict[str, np.ndarray]:
    """Paths 0..n-1 through every output time with the CPU kernels (as in run_batches)."""
    kern = cpu.kernels(cpu.spec_for(config))
    p = Paths(n).init(kern, config.seed, theta0=config.theta0, Omega0=config.Omega0, xi0=config.xi0,
                      D=config.D, tau=config.tau_or_zero, W=config.omega_noise_or_zero)
    for t_target in config.times:
        while p.advance(kern, t_target, 1000, config.seed, D=config.D, tau=config.tau_or_zero,
                        W=config.omega_noise_or_zero, omega2=config.omega**2, n=config.power_n,
                        h_max=config.h_max, step_c=config.step_c)[1]:
            pass
    return dict(x=p.x, Omega=p.Omega, xi=p.xi, t=p.t, k=p.k, status=p.status)


def _check_cpu_kernels_are_current() -> None:
    """The CPU kernels must compute what the shared functions' current source says.

    Numba's on-disk cache (``cache=True``) is invalidated by edits to cpu.py only, not to the
    integrator, noise and rng functions it inlines, so after such an edit the CPU kernels may
    run old code (``_jitcache`` guards against it). Compare one initial condition and one OU
    step with the Python functions.
    """
    config = SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=1, t_max=0.1,
                                    times=[0.1], seed=5, h_max=0.1, step_c=0.0, n_batches=2)
    state = _cpu_states(config, 1)
    key0, key1 = rng.seed_to_key(config.seed)
    u, _ = rng.draw_uniforms(key0, key1, np.uint64(0), np.uint64(rng.N_INIT_THETA))
    z, _ = rng.draw_normals(key0, key1, np.uint64(0), np.uint64(rng.N_INIT_XI))
    x0, xi0 = 2.0 * math.pi * u - math.pi, math.sqrt(1.0 / 2.0) * z
    z1, z2 = rng.draw_normals(key0, key1, np.uint64(0), np.uint64(rng.N_FIRST_STEP))
    a, s_xi, m_I, c_I, s_I = ou.step_coefficients(0.1, (1.0, 1.0))
    verlet = integrator.build(integrator.spec("ou", adaptive=False)).verlet
    x1, Omega1 = verlet(x0, 0.0, 0.1, 1.0, m_I * xi0 + c_I * z1 + s_I * z2, (2.0,))
    expected = (x1, Omega1, a * xi0 + s_xi * z1)
    found = (state["x"][0], state["Omega"][0], state["xi"][0])
    if found != expected:
        pytest.fail(
            f"the CPU kernels do not compute what rng/integrator say (state {found} != {expected}): "
            "most likely a stale Numba cache, which cache=True keys on cpu.py alone; delete "
            "src/stochpend/engine/__pycache__/*.nbi and *.nbc (or set NUMBA_CACHE_DIR) and rerun"
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
    assert blowup.sums[..., S_NONFINITE].sum() > 0
    assert not np.all(np.isfinite(blowup_states["x"]))  # went non-finite while stepping
    escape, _, _ = cpu_results("escape")
    assert np.all(escape.sums[..., S_NONFINITE].sum(axis=0) == _COMMON["paths"])
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


def test_float32_mean_energy_agrees_with_float64_in_standard_errors(simulated):
    """float32 (normals by Box-Muller in float32, step in float32) and float64, independent
    ensembles of PAIR_PATHS paths: <E> at each output time within Z_TOL combined standard
    errors. The test also requires <E>(t = 2) to have moved from its start by more than 10 of
    them, so an error of a few tens of per cent in the float32 noise's variance would fail."""
    from tests.conftest import Z_TOL

    means = {}
    for precision in ("float64", "float32"):
        total = simulated[f"precision_pair/{precision}_sums"].sum(axis=0)
        count = total[:, S_COUNT]
        assert np.all(count == PAIR_PATHS), f"{precision}: {count} finite paths"
        mean = total[:, S_E1] / count
        var = total[:, S_E2] / count - mean**2
        means[precision] = (mean, np.sqrt(var / count))
    (m64, se64), (m32, se32) = means["float64"], means["float32"]
    E0 = -math.cos(1.0)  # E = Omega**2/2 - omega**2 cos theta; omega = 1, theta0 = 1, Omega0 = 0
    assert m64[-1] - E0 > 10 * se64[-1], "the noise must have moved <E> for the test to mean much"
    z = (m32 - m64) / np.sqrt(se32**2 + se64**2)
    assert np.all(np.abs(z) < Z_TOL), f"<E> float32 {m32}, float64 {m64}: z = {z}"


def test_rng_in_kernel_equals_cpu(simulated):
    """Philox words (exactly), the float64 normal pair (to the last bit) and the float32 pair
    (to float32 round-off: the simulator's math functions return float64) computed in a CUDA
    kernel, against the CPU's Numba-compiled functions, for paths and counters with high words."""
    import numba

    from tests.unit._cudasim_check import rng_inputs

    case = next(c for c in EXTRAS if c["name"] == "rng")
    paths, counters = rng_inputs(case["n"])
    key0, key1 = rng.seed_to_key(case["seed"])
    words = numba.njit(rng.draw_words)
    normals64 = numba.njit(rng.draw_normals)
    normals32 = numba.njit(rng.normals_with(LIBM, np.float32))
    want_words = np.array([words(key0, key1, p, n) for p, n in zip(paths, counters, strict=True)], dtype=np.uint64)
    want64 = np.array([normals64(key0, key1, p, n) for p, n in zip(paths, counters, strict=True)])
    want32 = np.array([normals32(key0, key1, p, n) for p, n in zip(paths, counters, strict=True)], dtype=np.float32)
    np.testing.assert_array_equal(simulated["rng/words"], want_words)
    np.testing.assert_array_equal(simulated["rng/z64"], want64)
    np.testing.assert_allclose(simulated["rng/z32"], want32, rtol=4e-7, atol=4e-7)


def test_float32_pieces_compute_in_float32():
    """The float32 KernelSpec's device functions, built by the same factories as float64's (no source
    rewriting), type as float32 in Numba and agree with float64 to float32 round-off."""
    import numba

    f32 = integrator.build(integrator.spec("ou", precision="float32"))
    f64 = integrator.build(integrator.spec("ou"))
    verlet, step_size = f32.verlet, f32.step_size
    noise = ou.OU.kernel(np.float32, LIBM)
    coefficients, draw, update = noise.coefficients, noise.draw, noise.update
    f = np.float32

    @numba.njit
    def step(x, Om, h, omega2, I, xi, D, tau, key0, key1):
        x1, Om1 = verlet(x, Om, h, omega2, I, (2.0,))
        hh = step_size(x1, Om1, xi, h, f(0.25), omega2, (2.0,))
        C = coefficients(hh, (D, tau))
        z, _ = draw(key0, key1, np.uint64(3), np.uint64(3), 0)
        I2, xi2, _ = update(xi, xi, C, z)
        return x1, Om1, hh, C[0], C[1], C[2], C[3], C[4], z[0], z[1], I2, xi2

    key0, key1 = rng.seed_to_key(11)
    args = (f(3.1), f(2.5), f(0.05), f(1.0), f(0.01), f(0.4), f(1.0), f(1.0), key0, key1)
    out = step(*args)
    signature = step.nopython_signatures[0].return_type
    assert all(str(t) == "float32" for t in signature.types), signature
    x1, Om1 = f64.verlet(3.1, 2.5, 0.05, 1.0, 0.01, (2.0,))
    hh = f64.step_size(x1, Om1, 0.4, 0.05, 0.25, 1.0, (2.0,))
    C = ou.step_coefficients(hh, (1.0, 1.0))
    z1, z2 = rng.draw_normals(key0, key1, np.uint64(3), np.uint64(rng.N_FIRST_STEP + 3))
    ref = (x1, Om1, hh, *C, z1, z2, C[2] * 0.4 + C[3] * z1 + C[4] * z2, C[0] * 0.4 + C[1] * z1)
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
            runner.run_batches(config, 0, config.n_batches, backend="cuda")
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
        runner.run_batches(config, 0, 1, precision="float16", backend="cuda")


@pytest.mark.parametrize("name", ["ckpt_ou", "ckpt_dichotomous_f32"])
def test_gpu_checkpoint_then_resume_is_bit_identical(simulated, name):
    """The GPU run's checkpoint (taken by the shared runner, the device state copied to the
    host) resumes on the GPU to exactly the uninterrupted run's numbers."""
    case = next(c for c in EXTRAS if c["name"] == name)
    assert bool(simulated[f"{name}/interrupted"])
    assert str(simulated[f"{name}/saved_backend"]) == "cuda"
    assert str(simulated[f"{name}/saved_precision"]) == case.get("precision", "float64")
    assert str(simulated[f"{name}/saved_x_dtype"]) == case.get("precision", "float64")
    b0, j = simulated[f"{name}/saved_position"]
    assert (b0, j) != (0, 0)  # the interruption came after real work
    for var in ("mean_E", "mean_E4", "mean_Omega2", "E_hist", "batch_sum_E", "nonfinite_paths"):
        np.testing.assert_array_equal(simulated[f"{name}/resumed_{var}"],
                                      simulated[f"{name}/ref_{var}"], err_msg=var)
    assert int(simulated[f"{name}/resumed_path_steps"]) == int(simulated[f"{name}/ref_path_steps"])
    assert str(simulated[f"{name}/resumed_backend"]) == "cuda"


def test_gpu_sweep_equals_each_set_alone(simulated):
    assert str(simulated["sweep/backend"]) == "cuda"
    for i in range(2):
        for var in ("mean_E", "E_hist", "batch_sum_E"):
            np.testing.assert_array_equal(simulated[f"sweep/set{i}_{var}"],
                                          simulated[f"sweep/alone{i}_{var}"], err_msg=var)


def test_gpu_bias_pairs_equal_cpu(simulated, monkeypatch):
    """A GPU run's bias pairs run on the GPU (one thread a pair, the run's KernelSpec: the C library's
    math): every statistic's bias and coarse value equal the CPU's one-pair kernel of that KernelSpec
    to the last bits, and the pairs' path-steps exactly."""
    from stochpend import bias
    from stochpend.engine import cpu
    from stochpend.engine.integrator import KernelSpec

    case = next(c for c in EXTRAS if c["name"] == "bias_pairs")
    monkeypatch.setattr(cpu, "spec_for", lambda config, precision="float64": KernelSpec.of(config, precision=precision))
    est = bias.estimate(SimulationConfig.build(**case["config"]), case["pairs"])
    assert int(simulated["bias_pairs/path_steps"]) == est.path_steps
    checked = 0
    for stat, (value, _se) in est.bias.items():
        np.testing.assert_allclose(simulated[f"bias_pairs/bias_{stat}"], value, rtol=1e-9,
                                   atol=1e-12 * np.max(np.abs(est.coarse[stat][0])), err_msg=stat)
        np.testing.assert_allclose(simulated[f"bias_pairs/coarse_{stat}"], est.coarse[stat][0],
                                   rtol=1e-12, err_msg=stat)
        checked += int(np.sum(value != 0))
    assert checked > 0
    np.testing.assert_allclose(simulated["bias_pairs/decorrelation"], est.decorrelation, rtol=1e-6)


def test_simulator_reports_itself(simulated):
    assert bool(simulated["availability_ok"])
    assert "simulator" in str(simulated["availability_reason"])


def test_simulated_cases_are_small(simulated):
    """Keep this file fast: a bound on the work the simulated cases do, not on their time (no
    test asserts a wall time: issue 37). The simulator runs about 1e4 path-steps a second of
    CPU, so 4e6 path-steps is the 400 s this bound once stood for; it guards against a case
    grown by orders of magnitude."""
    work = {name: int(simulated[f"{name}/work"]) for name in CASE_NAMES}
    assert all(w > 0 for w in work.values()), work
    assert sum(work.values()) < 4_000_000, work


# -- on-disk cache of the kernels ---------------------------------------------------------------
def test_kernels_of_builtin_pieces_are_cached_on_disk_and_user_models_are_not(monkeypatch):
    """Each kernel factory declares ``cuda.jit(cache=...)`` from what the kernel depends on:
    the init kernel on the noise, the advance kernel on the whole KernelSpec, the statistics kernel
    on the oscillator. A user's pieces live in memory only, so their kernels are not cached.
    (Loading a cached kernel needs a GPU; this checks the declarations.)"""
    declared = []

    class RecordingCuda:
        @staticmethod
        def jit(*args, **kwargs):
            assert not args, "kernels are declared with keyword options only"
            declared.append(kwargs)
            return lambda function: function

    monkeypatch.setattr(gpu, "cuda", RecordingCuda)
    # Past the per-process caches (functools' __wrapped__); the statistics kernel without user
    # observables.
    factories = (gpu.init_kernel.__wrapped__, gpu.advance_kernel.__wrapped__,
                 lambda spec: gpu._accumulate_kernel.__wrapped__(spec, ()))
    cases = {
        "built-in": (integrator.spec("ou"), (True, True, True)),
        "built-in float32 fixed": (integrator.spec("white", "harmonic", "position", precision="float32",
                                                   adaptive=False), (True, True, True)),
        "user noise": (integrator.spec("phase-drive"), (False, False, True)),
        "user oscillator": (integrator.spec("ou", "double-well", "position"), (True, False, False)),
    }
    for name, (spec, expected) in cases.items():
        for factory, cache in zip(factories, expected, strict=True):
            declared.clear()
            factory(spec)
            assert declared == [{"cache": cache}], f"{name}: {factory} declared {declared}"
    # A user's observable lives in memory only: the built-in oscillator's statistics kernel that
    # sums it is not cached either.
    declared.clear()
    user = Observable("x2_user", lambda x, Omega, xi, t: x * x)
    gpu._accumulate_kernel.__wrapped__(integrator.spec("ou"), (user,))
    assert declared == [{"cache": False}]
