"""A noise defined in one test file (tests/unit/_phase_noise.py) runs everywhere.

The noise is registered at run time, nothing in stochpend names it; the integrator compiles
its step loop for it, the runner, checkpoints and the command line's validation take it by
name. Its closed form xi(t) = a cos(phi_0 + W t) makes the kernel's noise checkable to
round-off; the CUDA simulator runs it in tests/unit/test_cuda_sim.py (case "phase_drive").
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import stochpend
from stochpend.engine import integrator
from stochpend.model.settings import SimulationConfig
from stochpend.numerics import rng
from stochpend.runs import checkpoint
from tests._kernels import Paths, kernels
from tests.unit import _phase_noise

_phase_noise.register()

D, TAU, W = 0.8, 0.5, 3.0


@pytest.mark.parametrize("step_c", [0.0, 0.1])
def test_the_kernel_follows_the_closed_form(step_c):
    """A harmonic oscillator at rest (x = Omega = 0) leaves the noise free: at every output
    time xi = a cos(phi_0 + W t) with phi_0 = 2 pi u (u the path's N_INIT_XI uniform)."""
    kern = kernels(_phase_noise.NAME, "harmonic", adaptive=step_c > 0)
    n, seed = 500, 17
    p = Paths(n).init(kern, seed, theta0=0.0, D=D, tau=TAU, W=W)
    p.x[:] = 0.0
    key0, key1 = rng.seed_to_key(seed)
    phi0 = np.array([2 * math.pi * rng.draw_uniforms(key0, key1, np.uint64(i),
                                                    np.uint64(rng.N_INIT_XI))[0] for i in range(n)])
    a = math.sqrt(D / TAU)
    for t in (0.37, 1.0, 12.5):
        p.advance(kern, t, 10**9, seed, D=D, tau=TAU, W=W, h_max=0.05, step_c=step_c)
        np.testing.assert_allclose(p.xi, a * np.cos(phi0 + W * t), rtol=0, atol=1e-11)
        np.testing.assert_allclose(p.xi_aux, phi0 + W * t, rtol=1e-13)
    assert np.all(p.status == 0) and np.all(p.x == 0.0) and np.all(p.Omega == 0.0)


def test_the_drive_moves_the_pendulum_as_its_integral_says():
    """omega = 0: Omega(t) = -int xi sin(theta) dt; a pendulum started at theta0 = pi/2 with
    Omega0 = 0 and a weak drive barely moves, so Omega(t) ~ -(a/W)(sin(phi_0 + W t) - sin phi_0)
    to first order: the noise integral enters the kick with the right sign and size."""
    T = math.pi / W  # half a period of the drive: the kick is -2 (a/W) sin(phi_0)
    ds_args = dict(noise=_phase_noise.NAME, D=1e-6, tau=TAU, omega_noise=W, omega=0.0, paths=64,
                   t_max=T, times=[T], theta0=math.pi / 2, Omega0=0.0, seed=3, step_c=0.0,
                   h_max=0.01, n_batches=4)
    config = SimulationConfig.build(**ds_args)
    engine = stochpend.engine.cpu.Engine(config, integrator.KernelSpec.of(config), 64, 1)
    engine.start(0, 64, 1)
    engine.advance(T, 10**6)
    key0, key1 = rng.seed_to_key(3)
    phi0 = np.array([2 * math.pi * rng.draw_uniforms(key0, key1, np.uint64(i),
                                                    np.uint64(rng.N_INIT_XI))[0] for i in range(64)])
    a = math.sqrt(1e-6 / TAU)
    expected = -(a / W) * (np.sin(phi0 + W * T) - np.sin(phi0))
    # to 1e-3 of the amplitude 2a/W (the neglected terms: theta moves by ~1e-4)
    np.testing.assert_allclose(engine.Omega, expected, rtol=0, atol=1e-3 * 2 * a / W)
    assert np.max(np.abs(expected)) > 0.5 * (2 * a / W)  # the check is not vacuous


def test_public_api_checkpoint_and_validation_take_the_new_noise(tmp_path):
    kw = dict(noise=_phase_noise.NAME, D=1.0, tau=TAU, omega=1.0, paths=200, t_max=20.0,
              n_times=4, seed=5, n_batches=4)
    ds = stochpend.simulate(**kw)
    assert ds.attrs["noise"] == _phase_noise.NAME and ds.attrs["omega_noise"] == 1.0 / TAU
    assert np.all(np.isfinite(ds.mean_E.values)) and int(ds.nonfinite_paths[-1]) == 0
    # The default frequency, and the checkpointed run equals the plain one.
    config = SimulationConfig.build(**kw)
    resumed = checkpoint.run_checkpointed(config, checkpoint_path=tmp_path / "c.ckpt", every_s=0.0)
    for name in ("mean_E", "E_hist", "batch_sum_E"):
        np.testing.assert_array_equal(resumed[name].values, ds[name].values)
    with pytest.raises(ValueError, match="omega_noise=-1.0 is not accepted"):
        SimulationConfig.build(**{**kw, "omega_noise": -1.0})
    with pytest.raises(ValueError, match="omega_noise applies to noise="):
        SimulationConfig.build(noise="ou", omega_noise=2.0)


def test_a_noise_record_reads_the_config_then_noise_params():
    """``Noise.record``: each name of ``parameters`` from the config's field of that name (None
    as 0.0), else from ``noise_params``; the built-ins' records are prefixes of (D, tau, W)."""
    import dataclasses

    from stochpend import noises
    from stochpend.noises.base import Noise

    config = SimulationConfig.build(noise="ou", D=D, tau=TAU, paths=10, t_max=1.0, times=[1.0])
    assert noises.get("white").record(config) == (D,)
    assert noises.get("ou").record(config) == (D, TAU)
    assert noises.get("dichotomous").record(config) == (D, TAU)
    assert noises.get("harmonic").record(config) == (D, TAU, 0.0)  # omega_noise None: 0
    two_ou = Noise(name="two-ou", build=lambda real, mathlib: None, description="test only",
                   parameters=("D", "tau", "tau2", "weight"))
    mine = dataclasses.replace(config, noise_params=(("tau2", 0.125), ("weight", 0.25)))
    assert two_ou.record(mine) == (D, TAU, 0.125, 0.25)
    assert all(type(v) is float for v in two_ou.record(mine))
    with pytest.raises(ValueError, match="tau2"):
        two_ou.record(config)
