"""Weak order of the integrator against the exact harmonic reference (NOTES.md).

For the harmonic oscillator with white parametric noise, dOmega = -omega^2 x dt - x o dW,
dx = Omega dt, the second moments obey the closed linear system
    d<x^2>/dt = 2<x Omega>,  d<x Omega>/dt = <Omega^2> - omega^2 <x^2>,
    d<Omega^2>/dt = -2 omega^2 <x Omega> + D <x^2>.
Because the scheme is linear in the state for this model, its second moments also evolve by
an exact linear map per step, M_{n+1} = (B0 (x) B0 + D h B1 (x) B1) M_n, where the step is
z' = (B0 + I B1) z with the noise integral I ~ N(0, D h). B0 and B1 are read off the real
scheme function, so the weak error is computed without any sampling noise, and the kernel is
checked against the same map by Monte Carlo.
"""

from __future__ import annotations

import numpy as np
from scipy.linalg import expm

import stochpend
from stochpend.engine import integrator
from tests.conftest import SEED, Z_TOL

#: The harmonic oscillator with the noise on the force (G = x): a linear scheme.
VERLET = integrator.build(integrator.spec("white", "harmonic", "force")).verlet

OMEGA, D, X0, T = 1.0, 0.5, 1.0, 4.0


def exact_second_moments(t: float) -> np.ndarray:
    """(<x^2>, <x Omega>, <Omega^2>) at t from the closed linear ODE, start (X0, 0)."""
    A = np.array([[0.0, 2.0, 0.0], [-OMEGA**2, 0.0, 1.0], [D, -2.0 * OMEGA**2, 0.0]])
    return expm(A * t) @ np.array([X0**2, 0.0, 0.0])


def _step_matrix(h: float, noise_integral: float) -> np.ndarray:
    cols = []
    for z in (np.array([1.0, 0.0]), np.array([0.0, 1.0])):
        x, O = VERLET(z[0], z[1], h, OMEGA**2, noise_integral, 2)
        cols.append([x, O])
    return np.array(cols).T


def scheme_second_moments(h: float, n_steps: int) -> np.ndarray:
    """The scheme's own second moments after n_steps of size h (exact, no sampling)."""
    B0 = _step_matrix(h, 0.0)
    B1 = _step_matrix(h, 1.0) - B0
    K = np.kron(B0, B0) + D * h * np.kron(B1, B1)
    m = np.array([X0**2, 0.0, 0.0, 0.0])  # vec of [[x^2, xO], [Ox, O^2]]
    m = np.linalg.matrix_power(K, n_steps) @ m
    return np.array([m[0], m[1], m[3]])


def test_weak_order_two_on_exact_reference():
    exact = exact_second_moments(T)
    hs = [T / n for n in (20, 40, 80, 160, 320)]
    errors = [np.max(np.abs(scheme_second_moments(h, round(T / h)) - exact)) for h in hs]
    slopes = np.diff(np.log(errors)) / np.diff(np.log(hs))
    order = np.polyfit(np.log(hs), np.log(errors), 1)[0]
    assert abs(order - 2.0) < 0.1, f"weak order {order:.3f} (local slopes {slopes}), expected 2"
    assert np.all(np.abs(slopes - 2.0) < 0.15), f"local slopes {slopes} are not all close to 2"


def test_kernel_matches_the_scheme_moment_map():
    """Monte Carlo with the compiled kernel equals the scheme's exact moment map within 4 SE."""
    h, times = 0.1, [1.0, 2.0, 4.0]
    ds = stochpend.simulate(noise="white", D=D, omega=OMEGA, paths=100_000, t_max=T, times=times,
                            seed=SEED, theta0=X0, Omega0=0.0, potential="harmonic", h_max=h,
                            step_c=0.0)
    for i, t in enumerate(times):
        x2, _, O2 = scheme_second_moments(h, round(t / h))
        row = ds.isel(time=i)
        for name, want in (("mean_sin2theta", x2), ("mean_Omega2", O2)):
            z = (float(row[name]) - want) / float(row[f"{name}_stderr"])
            assert abs(z) < Z_TOL, f"t={t}: {name} = {float(row[name]):.5f}, scheme map {want:.5f}: z = {z:+.2f}"
    # and the scheme map is within its O(h^2) weak error of the exact moments
    x2_exact = exact_second_moments(T)[0]
    assert abs(scheme_second_moments(h, round(T / h))[0] - x2_exact) < 0.01 * x2_exact
