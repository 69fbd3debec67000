"""The integrator's pieces, checked against independent formulas (plain-Python calls).

The device functions of a KernelSpec (``integrator.build``) are ``register_jitable`` closures, so
Python can call them; they are the code the kernels inline.
"""

from __future__ import annotations

import math
from decimal import Decimal, getcontext

import numpy as np
import pytest

import stochpend
from stochpend import oscillators
from stochpend.engine import integrator
from stochpend.model.settings import SimulationConfig
from stochpend.noises import ou


def _steps(potential="pendulum", coupling="force"):
    return integrator.build(integrator.spec("ou", potential, coupling))


def _x_minus_2tanh_half_decimal(x: float) -> float:
    getcontext().prec = 60
    X = Decimal(x)
    e = (-X).exp()
    return float(X - 2 * (1 - e) / (1 + e))


@pytest.mark.parametrize("x", [1e-8, 1e-5, 1e-3, 0.02, 0.1, 0.3, 0.5999, 0.6, 0.6001, 1.0, 3.0, 40.0])
def test_conditional_variance_function_is_accurate_everywhere(x):
    exact = _x_minus_2tanh_half_decimal(x)
    got = ou.x_minus_2tanh_half(x)
    eps = np.finfo(float).eps
    # series: a few ulps; direct difference: the cancellation bound 12 eps / x^2 (x >= 0.6)
    tol = 4 * eps if x < 0.6 else 2 * 12 * eps / x**2
    assert abs(got - exact) <= tol * abs(exact), f"x={x}: {got!r} vs {exact!r}"
    assert ou.x_minus_2tanh_half(x) == __import__("numba").njit(ou.x_minus_2tanh_half)(x)


@pytest.mark.parametrize("h,tau", [(0.01, 1.0), (0.5, 1.0), (1.0, 0.1), (0.05, 0.01), (3.0, 10.0), (20.0, 0.5)])
def test_ou_coefficients_reproduce_the_exact_joint_covariance(h, tau):
    """NOTES.md: var xi' = D(1-a^2)/(2 tau), var I = D[h - 2 tau(1-a) + tau(1-a^2)/2], cov = D(1-a)^2/2."""
    D = 2.5
    a, s_xi, m_I, c_I, s_I = ou.step_coefficients(h, (D, tau))
    e = math.exp(-h / tau)
    assert a == pytest.approx(e, rel=1e-14)
    assert m_I == pytest.approx(tau * (1 - e), rel=1e-14)
    assert s_xi**2 == pytest.approx(D * (1 - e * e) / (2 * tau), rel=1e-13)
    assert s_xi * c_I == pytest.approx(D * (1 - e) ** 2 / 2, rel=1e-13)
    var_I = D * (h - 2 * tau * (1 - e) + tau * (1 - e * e) / 2)
    assert c_I**2 + s_I**2 == pytest.approx(var_I, rel=1e-9 if h / tau > 0.05 else 1e-6)


def test_ou_coefficients_tend_to_white_noise_as_tau_vanishes():
    h, D = 0.1, 1.7
    _, _, m_I, c_I, s_I = ou.step_coefficients(h, (D, 1e-9))
    assert c_I**2 + s_I**2 == pytest.approx(D * h, rel=1e-7)
    assert m_I == pytest.approx(1e-9, rel=1e-6)


def test_verlet_is_time_reversible_and_symplectic_at_zero_noise():
    x, O, h, w2 = 0.7, -0.3, 0.05, 1.3
    verlet = _steps().verlet
    x1, O1 = verlet(x, O, h, w2, 0.0, (2.0,))
    xb, Ob = verlet(x1, -O1, h, w2, 0.0, (2.0,))
    assert xb == pytest.approx(x, abs=1e-14) and -Ob == pytest.approx(O, abs=1e-14)
    # Jacobian determinant 1 (area preserving), by central differences
    eps = 1e-6

    def f(v):
        return np.array(verlet(v[0], v[1], h, w2, 0.0, (2.0,)))

    J = np.column_stack([(f(np.array([x, O]) + eps * e) - f(np.array([x, O]) - eps * e)) / (2 * eps)
                         for e in np.eye(2)])
    assert np.linalg.det(J) == pytest.approx(1.0, abs=1e-8)


def test_ito_and_stratonovich_coincide():
    """The Stratonovich-to-Ito drift correction (1/2) sum_j b_j d_j b_i vanishes.

    State (x, Omega), diffusion b = (0, -G(x)): b_x = 0, so the only derivative that could
    contribute, d b_Omega / d Omega, multiplies b_Omega and is zero because G does not depend
    on Omega. Checked numerically for every potential and coupling.
    """
    eps = 1e-6
    for pot, cpl in [("pendulum", "force"), ("harmonic", "force"), ("harmonic", "position"),
                     ("power", "force")]:
        G = _steps(pot, cpl).G
        for x, O in [(0.3, 1.1), (-1.2, 4.0), (2.0, -0.5)]:
            def b(xx, OO, G=G):
                return np.array([0.0, -G(xx, (2.0,)) + 0.0 * OO])

            db_dx = (b(x + eps, O) - b(x - eps, O)) / (2 * eps)
            db_dO = (b(x, O + eps) - b(x, O - eps)) / (2 * eps)
            bx, bO = b(x, O)
            correction = 0.5 * (bx * db_dx + bO * db_dO)
            assert np.allclose(correction, 0.0, atol=1e-12), (pot, cpl, x, O, correction)


def test_step_size_rules():
    h_max, c = 0.05, 0.25
    step_size = _steps().step_size  # (x, Omega, xi, h_max, c, omega2, q)
    assert step_size(0.0, 0.1, 0.0, h_max, c, 1.0, (2.0,)) == h_max
    assert step_size(0.0, 100.0, 0.0, h_max, c, 1.0, (2.0,)) == pytest.approx(c / 100.0)
    assert step_size(0.0, 0.0, 399.0, h_max, c, 1.0, (2.0,)) == pytest.approx(c / 20.0)


def test_zero_step_c_compiles_the_fixed_step():
    """step_c = 0 selects the fixed-step KernelSpec (no step control compiled in): every path takes
    exactly t/h_max steps, however fast it turns or however large the noise."""
    config = SimulationConfig.build(noise="ou", D=400.0, tau=0.1, paths=50, t_max=2.0, times=[1.0, 2.0],
                                    h_max=0.05, step_c=0.0, Omega0=100.0, n_batches=2)
    assert integrator.KernelSpec.of(config).adaptive is False
    assert integrator.KernelSpec.of(SimulationConfig.build(step_c=0.1)).adaptive is True
    ds = stochpend.simulate(noise="ou", D=400.0, tau=0.1, paths=50, t_max=2.0, times=[1.0, 2.0],
                            h_max=0.05, step_c=0.0, Omega0=100.0, n_batches=2)
    assert ds.attrs["path_steps"] == 50 * 40


def test_angle_wrapping():
    for x in (-7.0, -math.pi, 0.0, 3.0, math.pi, 10.0, 1e6):
        w = oscillators.get("pendulum").functions.wrap(x)
        assert -math.pi <= w < math.pi
        assert math.sin(w) == pytest.approx(math.sin(x), abs=1e-9)
    assert oscillators.get("harmonic").functions.wrap(10.0) == 10.0


def test_step_size_stiffness_follows_the_coupling():
    """Force coupling: k = |omega**2 + xi| |U''|; position coupling: k = |omega**2 U'' + xi|
    (the linearized force of each model)."""
    c, h_max, x, xi = 0.1, 1.0, 2.0, 30.0  # quartic: U'' = 3 x**2 = 12
    # omega = 0 makes the power oscillator's step control use the instantaneous U''(x)
    force = _steps("power", "force").step_size(x, 0.0, xi, h_max, c, 0.0, (2.0,))
    position = _steps("power", "position").step_size(x, 0.0, xi, h_max, c, 0.0, (2.0,))
    assert force == pytest.approx(c / math.sqrt(30.0 * 12.0))
    assert position == pytest.approx(c / math.sqrt(30.0))
    # omega = 1: the orbit's U'' at the amplitude A (A**4/4 = U(2) = 4, so U''(A) = 12 too)
    force = _steps("power", "force").step_size(x, 0.0, xi, h_max, c, 1.0, (2.0,))
    position = _steps("power", "position").step_size(x, 0.0, xi, h_max, c, 1.0, (2.0,))
    assert force == pytest.approx(c / math.sqrt(31.0 * 12.0))
    assert position == pytest.approx(c / math.sqrt(12.0 + 30.0))


def test_runaway_paths_are_frozen_and_counted():
    """The quartic oscillator with the noise on the force blows up in finite time
    (docs/scaling.md). The shrinking adaptive steps would follow a runaway path forever; the
    escape rule (step below ESCAPE_STEP_FRACTION h_max) freezes it, so the run ends and the
    path is counted as non-finite, never averaged."""
    import json
    import subprocess
    import sys

    # In a subprocess with a time limit: without the escape rule the run never returns, and
    # the test must fail rather than hang the suite.
    code = (
        "import json, stochpend\n"
        "ds = stochpend.simulate(noise='white', D=1.0, potential='power', power_n=2, "
        "coupling='force', paths=200, t_max=3.0, times=[0.5, 3.0], seed=4, n_batches=4)\n"
        "print(json.dumps({'nonfinite': ds.nonfinite_paths.values.tolist(), "
        "'finite': ds.n_finite_paths.values.tolist(), 'mean_E': ds.mean_E.values.tolist()}))\n"
    )
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=300, check=False)
    except subprocess.TimeoutExpired:
        pytest.fail("a run with blowing-up paths did not return within 300 s")
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out["nonfinite"][-1] > 10
    assert out["finite"][-1] + out["nonfinite"][-1] == 200
    assert np.isfinite(out["mean_E"]).all()


def test_step_of_an_oscillator_is_constant_along_its_orbit():
    """Harmonic and power potentials: the step depends on the orbit (energy), not on where on
    it the path is, so Stormer-Verlet stays symplectic between noise kicks; the pendulum keeps
    the instantaneous rule of the accuracy study."""
    c, h_max, omega2, E = 0.1, 1.0, 1.0, 50.0
    for pot in ("harmonic", "power"):
        steps = []
        step_size = _steps(pot, "position").step_size
        for x in (0.0, 0.7, 1.9, 2.5):
            U = oscillators.get(pot).functions.potential(x, (2.0,))
            if U > E:
                continue
            Omega = math.sqrt(2.0 * (E - omega2 * U))
            steps.append(step_size(x, Omega, 0.0, h_max, c, omega2, (2.0,)))
        assert len(steps) >= 3 and max(steps) == pytest.approx(min(steps), rel=1e-12), (pot, steps)
    step_size = _steps().step_size
    a = step_size(0.0, 3.0, 0.0, h_max, c, omega2, (2.0,))
    b = step_size(2.0, 1.0, 0.0, h_max, c, omega2, (2.0,))
    assert a == pytest.approx(c / 3.0) and b == pytest.approx(c / 1.0)


def test_the_step_record_is_read_by_its_declared_names():
    """``integrator.STEP_RECORD`` declares the step record's fields once; the kernels read them by
    their ``STEP_*`` positions: each holds the configuration's value (the generic additive
    channel's run, which has every field)."""
    from stochpend.engine import integrator
    from stochpend.model import dynamics
    from stochpend.model.settings import SimulationConfig
    from stochpend.numerics import rng

    cfg = SimulationConfig.build(noise="white", D=0.5, omega=1.5, h_max=0.03, step_c=0.2, seed=11,
                                 additive_noise="harmonic",
                                 noise_params=dict(gamma=0.3, additive_D=0.4, additive_tau=0.5))
    run = integrator.step_record(cfg)
    assert len(run) == len(integrator.STEP_RECORD)
    assert run[integrator.STEP_OMEGA2] == 1.5**2 and run[integrator.STEP_H_MAX] == 0.03
    assert run[integrator.STEP_STEP_C] == 0.2 and run[integrator.STEP_D] == dynamics.record(cfg)
    assert run[integrator.STEP_CHANNEL_RECORD] == dynamics.channel_record(cfg)
    assert run[integrator.STEP_CHANNEL_KEY] == rng.run_keys(11).additive
