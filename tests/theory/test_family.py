"""The damped, driven family's laws (stochpend.theory.family), each against an independent
computation: quadrature of the Boltzmann density, a numerical Lyapunov solve, the package's own
noise spectra, eigenvalues by NumPy, mean first-passage-time integrals, a direct quadrature of
the Riccati density, deterministic orbits."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad, solve_ivp
from scipy.linalg import solve_continuous_lyapunov
from scipy.special import gamma as gamma_fn

from stochpend.noises import ou as ou_noise
from stochpend.noises import white as white_noise
from stochpend.theory import family as f
from stochpend.theory.scaling import harmonic_growth_rate

# ---------------------------------------------------------------------------------------------
# 1. Temperature and Boltzmann averages
# ---------------------------------------------------------------------------------------------


def test_temperature_from_the_package_white_noise_spectrum() -> None:
    # Var Omega of dOmega = -gamma Omega dt + xi_a is (1/2 pi) int S(nu)/(gamma^2 + nu^2) dnu with the
    # package's own spectrum S(nu) = D_a: the temperature is D_a/(2 gamma), not D_a/gamma.
    D_a, gamma = 0.7, 0.3
    S = white_noise.WHITE.spectral_density
    var = quad(lambda nu: float(S(nu, D_a)) / (gamma**2 + nu**2), -np.inf, np.inf)[0] / (2 * math.pi)
    assert f.temperature(D_a=D_a, gamma=gamma) == pytest.approx(var, rel=1e-9)
    assert f.boltzmann_mean_Omega2(D_a=D_a, gamma=gamma) == pytest.approx(D_a / (2 * gamma), rel=1e-15)


@pytest.mark.parametrize("kappa", [0.05, 1.0, 7.0, 40.0])
def test_pendulum_boltzmann_averages_by_quadrature(kappa: float) -> None:
    gamma, omega = 0.5, 1.3
    T = omega**2 / kappa
    D_a = 2 * gamma * T
    w = lambda x: math.exp(kappa * (math.cos(x) - 1.0))  # noqa: E731
    Z = quad(w, -math.pi, math.pi, epsrel=1e-12)[0]
    c1 = quad(lambda x: math.cos(x) * w(x), -math.pi, math.pi, epsrel=1e-12)[0] / Z
    c2 = quad(lambda x: math.cos(x) ** 2 * w(x), -math.pi, math.pi, epsrel=1e-12)[0] / Z
    kw = {"D_a": D_a, "gamma": gamma, "omega": omega}
    assert f.boltzmann_pendulum_mean_cos(**kw) == pytest.approx(c1, rel=1e-10)
    assert f.boltzmann_pendulum_mean_cos2(**kw) == pytest.approx(c2, rel=1e-10)
    assert f.boltzmann_pendulum_mean_E(**kw) == pytest.approx(T / 2 - omega**2 * c1, rel=1e-10, abs=1e-12)


@pytest.mark.parametrize("kappa", [0.05, 1.0, 7.0, 40.0])
def test_pendulum_boltzmann_energy_moments_by_quadrature(kappa: float) -> None:
    """<E**n>, n = 1..4 (the paper's S and F of the Boltzmann law), against a double quadrature
    over the Maxwell velocity and the von Mises angle."""
    gamma, omega = 0.5, 1.3
    T = omega**2 / kappa
    kw = {"D_a": 2 * gamma * T, "gamma": gamma, "omega": omega}
    w = lambda x: math.exp(kappa * (math.cos(x) - 1.0))  # noqa: E731
    Z = quad(w, -math.pi, math.pi, epsrel=1e-12)[0]
    for n in range(1, 5):
        def at_angle(x: float, n: int = n) -> float:
            g = lambda v: (v * v / 2 - omega**2 * math.cos(x)) ** n * math.exp(-v * v / (2 * T))  # noqa: E731
            return quad(g, -np.inf, np.inf, epsrel=1e-12)[0] / math.sqrt(2 * math.pi * T) * w(x)

        exact = quad(at_angle, -math.pi, math.pi, epsrel=1e-11)[0] / Z
        assert f.boltzmann_pendulum_energy_moment(n, **kw) == pytest.approx(exact, rel=1e-8, abs=1e-12 * T**n), n
    assert f.boltzmann_pendulum_energy_moment(1, **kw) == pytest.approx(f.boltzmann_pendulum_mean_E(**kw), rel=1e-12)
    with pytest.raises(ValueError, match="n=0 is not accepted"):
        f.boltzmann_pendulum_energy_moment(0, **kw)


def test_pendulum_boltzmann_limits_without_overflow() -> None:
    # kappa = 1e5: I1/I0 = 1 - 1/(2 kappa) - 1/(8 kappa^2) + ...; kappa -> 0: <cos> = kappa/2
    assert f.boltzmann_pendulum_mean_cos(D_a=2e-5, gamma=1.0, omega=1.0) == pytest.approx(1 - 5e-6 - 1.25e-11, rel=1e-12)
    assert f.boltzmann_pendulum_mean_cos(D_a=2e5, gamma=1.0, omega=1.0) == pytest.approx(5e-6, rel=1e-9)
    assert f.boltzmann_pendulum_mean_cos(D_a=1.0, gamma=1.0, omega=0.0) == 0.0


@pytest.mark.parametrize("n", [1, 2, 3])
def test_power_boltzmann_by_quadrature(n: int) -> None:
    D_a, gamma, omega = 0.8, 0.25, 1.7
    T = D_a / (2 * gamma)
    w = lambda x: math.exp(-(omega**2) * x ** (2 * n) / (2 * n) / T)  # noqa: E731
    Z = quad(w, -np.inf, np.inf)[0]
    x2 = quad(lambda x: x * x * w(x), -np.inf, np.inf)[0] / Z
    U = quad(lambda x: omega**2 * x ** (2 * n) / (2 * n) * w(x), -np.inf, np.inf)[0] / Z
    kw = {"D_a": D_a, "gamma": gamma, "omega": omega}
    assert f.boltzmann_power_mean_x2(**kw, power_n=n) == pytest.approx(x2, rel=1e-9)
    assert f.boltzmann_power_mean_E(**kw, power_n=n) == pytest.approx(T / 2 + U, rel=1e-9)
    if n == 1:
        assert f.boltzmann_harmonic_mean_x2(**kw) == pytest.approx(x2, rel=1e-9)
        assert f.boltzmann_harmonic_mean_E(**kw) == pytest.approx(T, rel=1e-15)


# ---------------------------------------------------------------------------------------------
# 2. Harmonic oscillator with additive OU noise
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("D_a,tau,gamma,omega", [(1.0, 0.5, 0.2, 1.0), (0.3, 3.0, 2.0, 0.4), (2.0, 0.01, 0.05, 5.0)])
def test_ou_additive_variances_against_numerical_lyapunov(D_a, tau, gamma, omega) -> None:
    M = np.array([[0.0, 1.0, 0.0], [-(omega**2), -gamma, 1.0], [0.0, 0.0, -1.0 / tau]])
    Q = np.diag([0.0, 0.0, D_a / tau**2])
    S = solve_continuous_lyapunov(M, -Q)
    v = f.harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    got = np.array([[v.mean_x2, v.mean_xOmega, v.mean_x_xi],
                    [v.mean_xOmega, v.mean_Omega2, v.mean_Omega_xi],
                    [v.mean_x_xi, v.mean_Omega_xi, v.mean_xi2]])
    np.testing.assert_allclose(got, S, rtol=1e-9, atol=1e-12 * np.max(np.abs(S)))
    E = f.harmonic_ou_additive_mean_E(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    assert E == pytest.approx((S[1, 1] + omega**2 * S[0, 0]) / 2, rel=1e-9)


def test_ou_additive_matches_the_package_ou_noise() -> None:
    # The OU convention is the package's: its stationary variance and spectrum give the same numbers.
    D_a, tau, gamma, omega = 0.9, 0.7, 0.3, 1.2
    v = f.harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    assert v.mean_xi2 == pytest.approx(ou_noise.OU.variance(D_a, tau), rel=1e-15)
    S = ou_noise.OU.spectral_density
    chi2 = lambda nu: 1.0 / ((omega**2 - nu**2) ** 2 + (gamma * nu) ** 2)  # noqa: E731
    x2 = quad(lambda nu: float(S(nu, D_a, tau)) * chi2(nu), -np.inf, np.inf, limit=200)[0] / (2 * math.pi)
    O2 = quad(lambda nu: float(S(nu, D_a, tau)) * nu**2 * chi2(nu), -np.inf, np.inf, limit=200)[0] / (2 * math.pi)
    assert v.mean_x2 == pytest.approx(x2, rel=1e-8)
    assert v.mean_Omega2 == pytest.approx(O2, rel=1e-8)


def test_ou_additive_white_limit_is_boltzmann() -> None:
    kw = {"D_a": 0.6, "gamma": 0.4, "omega": 1.5}
    v = f.harmonic_ou_additive_variances(tau=1e-9, **kw)
    assert v.mean_x2 == pytest.approx(f.boltzmann_harmonic_mean_x2(**kw), rel=1e-8)
    assert v.mean_Omega2 == pytest.approx(f.boltzmann_mean_Omega2(D_a=0.6, gamma=0.4), rel=1e-8)


# ---------------------------------------------------------------------------------------------
# 3. Kramers rates over the pendulum barrier
# ---------------------------------------------------------------------------------------------


def test_barrier_and_branch_action() -> None:
    omega = 1.7
    assert f.pendulum_barrier(omega=omega) == pytest.approx(2 * omega**2)
    # one separatrix branch: int Omega dx, Omega = sqrt(2 (omega^2 + omega^2 cos x))
    branch = quad(lambda x: math.sqrt(2 * omega**2 * (1 + math.cos(x))), -math.pi, math.pi)[0]
    assert branch == pytest.approx(8 * omega, rel=1e-10)
    T = f.temperature(D_a=0.3, gamma=0.2)
    assert f.pendulum_energy_loss(D_a=0.3, gamma=0.2, omega=omega) == pytest.approx(0.2 * branch / T, rel=1e-10)
    # the elliptic closed-orbit action used by the MFPT rate: both branches at the separatrix, and
    # an elementary quadrature inside the well
    assert f._pendulum_action(omega**2, omega) == pytest.approx(2 * branch, rel=1e-10)
    E = -0.3 * omega**2
    xt = math.acos(-E / omega**2)
    loop = 2 * quad(lambda x: math.sqrt(max(2 * (E + omega**2 * math.cos(x)), 0.0)), -xt, xt)[0]
    assert f._pendulum_action(E, omega) == pytest.approx(loop, rel=1e-8)


def test_melnikov_meshkov_limits() -> None:
    for d in (1e-8, 1e-6):
        assert f.melnikov_meshkov_A(d) / d == pytest.approx(1.0, abs=5 * math.sqrt(d))
    assert f.melnikov_meshkov_A(50.0) == pytest.approx(1.0, abs=1e-5)
    assert f.melnikov_meshkov_A(1e3) == 1.0
    values = [f.melnikov_meshkov_A(d) for d in np.geomspace(1e-4, 1e2, 25)]
    assert all(0 < a <= 1 for a in values) and np.all(np.diff(values) > 0)


def test_kramers_limits() -> None:
    omega, T = 1.0, 0.1  # Delta U/T = 20
    kw = lambda g: {"D_a": 2 * g * T, "gamma": g, "omega": omega}  # noqa: E731
    arrhenius = math.exp(-2 * omega**2 / T)
    # gamma -> 0: transmission -> 1; gamma >> omega: Smoluchowski omega^2/(2 pi gamma)
    assert f.kramers_rate_spatial_diffusion(**kw(1e-9)) == pytest.approx(omega / (2 * math.pi) * arrhenius, rel=1e-8)
    g = 1e4
    assert f.kramers_rate_spatial_diffusion(**kw(g)) == pytest.approx(omega**2 / (2 * math.pi * g) * arrhenius,
                                                                      rel=1e-7)
    # Mel'nikov-Meshkov reduces to energy diffusion at small Delta and to Kramers at large Delta
    g = 1e-9
    assert f.kramers_rate_melnikov_meshkov(**kw(g)) == pytest.approx(f.kramers_rate_energy_diffusion(**kw(g)),
                                                                     rel=1e-3)
    g = 10.0
    assert f.kramers_rate_melnikov_meshkov(**kw(g)) == pytest.approx(f.kramers_rate_spatial_diffusion(**kw(g)),
                                                                     rel=1e-12)
    assert f.kramers_regime(**kw(1e-6)) == "energy diffusion"
    assert f.kramers_regime(**kw(0.01)) == "turnover"
    assert f.kramers_regime(**kw(1.0)) == "spatial diffusion"
    for regime in ("spatial diffusion", "energy diffusion", "turnover"):
        assert f.pendulum_slip_rate(**kw(0.01), regime=regime) > 0
    assert f.pendulum_slip_rate(**kw(1.0)) == pytest.approx(2 * f.kramers_rate_spatial_diffusion(**kw(1.0)))
    assert f.pendulum_slip_rate(**kw(0.01)) == pytest.approx(2 * f.kramers_rate_melnikov_meshkov(**kw(0.01)))


def _smoluchowski_mfpt(omega: float, T: float, gamma: float) -> float:
    """Mean first-passage time from x = 0 to x = +-2 pi (the next minima) of the overdamped pendulum
    gamma dx = -omega^2 sin x dt + xi_a dt, diffusion T/gamma (the Smoluchowski double integral,
    reflecting at 0 by symmetry)."""
    V = lambda x: -(omega**2) * math.cos(x)  # noqa: E731
    inner = lambda y: quad(lambda z: math.exp(-(V(z) - V(0)) / T), 0, y, epsrel=1e-12)[0]  # noqa: E731
    outer = quad(lambda y: math.exp((V(y) - V(0)) / T) * inner(y), 0, 2 * math.pi, points=[math.pi],
                 epsrel=1e-10, limit=200)[0]
    return outer / (T / gamma)


@pytest.mark.parametrize("barrier", [5.0, 10.0, 20.0, 40.0])
def test_spatial_diffusion_against_smoluchowski_mfpt(barrier: float) -> None:
    omega, gamma = 1.0, 200.0
    T = 2 * omega**2 / barrier
    kw = {"D_a": 2 * gamma * T, "gamma": gamma, "omega": omega}
    exact = 1.0 / (2.0 * _smoluchowski_mfpt(omega, T, gamma))  # rate over one barrier
    # Lifson-Jackson, from an independent route, equals the MFPT rate
    assert f.smoluchowski_effective_diffusion(**kw) / (2 * math.pi) ** 2 == pytest.approx(exact, rel=1e-7)
    # Kramers within its stated accuracy, T/(2 Delta U) to leading order (and from above)
    ratio = exact / f.kramers_rate_spatial_diffusion(**kw)
    assert 1 - ratio == pytest.approx(1 / (2 * barrier), rel=0.3)
    assert ratio < 1


@pytest.mark.parametrize("barrier", [5.0, 10.0, 20.0, 40.0])
def test_energy_diffusion_against_its_mfpt(barrier: float) -> None:
    omega, gamma = 1.0, 1e-3
    T = 2 * omega**2 / barrier
    kw = {"D_a": 2 * gamma * T, "gamma": gamma, "omega": omega}
    ratio = f.kramers_rate_energy_diffusion_mfpt(**kw) / f.kramers_rate_energy_diffusion(**kw)
    # the per-barrier action 8 omega (half the separatrix loop) is the right one: ratio -> 1, and
    # the stated error of the Laplace evaluation, about 2 T/Delta U
    assert 1 - ratio == pytest.approx(2 / barrier, rel=0.25)
    assert ratio < 1


# ---------------------------------------------------------------------------------------------
# 4. Tilted washboard
# ---------------------------------------------------------------------------------------------


def test_free_particle_laws() -> None:
    F, gamma, D_a = 0.7, 0.4, 0.3
    assert f.running_velocity(F=F, gamma=gamma) == pytest.approx(F / gamma)
    assert f.free_particle_drift(F=-F, gamma=gamma) == pytest.approx(-F / gamma)
    # D_eff = S_Omega(0)/2, S_Omega = S_xi/(gamma^2 + nu^2) with the package's white spectrum
    S0 = float(white_noise.WHITE.spectral_density(0.0, D_a))
    assert f.free_particle_diffusion(D_a=D_a, gamma=gamma) == pytest.approx(S0 / gamma**2 / 2, rel=1e-15)
    assert f.locking_torque(omega=1.5) == pytest.approx(2.25)


def _mean_velocity(F: float, gamma: float, omega: float, t_end: float, Omega0: float, rtol: float = 1e-10) -> float:
    """Mean Omega over the second half of a noiseless orbit from (0, Omega0)."""
    sol = solve_ivp(lambda t, y: [y[1], -gamma * y[1] - omega**2 * math.sin(y[0]) + F], (0, t_end), [0.0, Omega0],
                    rtol=rtol, atol=1e-10, dense_output=True)
    t0 = t_end / 2
    return float((sol.sol(t_end)[0] - sol.sol(t0)[0]) / (t_end - t0))


def test_running_velocity_at_large_torque() -> None:
    gamma, omega, F = 1.0, 1.0, 4.0
    v = F / gamma
    measured = _mean_velocity(F, gamma, omega, 400.0, v)
    corrected = v - omega**4 / (2 * v * (gamma**2 + v**2))  # the docstring's first correction
    assert measured == pytest.approx(corrected, rel=2e-4)
    assert abs(measured - v) / v < 0.01  # F/gamma itself within the O(omega^4/F^2) stated


def test_retrapping_torque_small_damping() -> None:
    gamma, omega = 0.02, 1.0
    F_r = f.retrapping_torque(gamma=gamma, omega=omega)
    assert F_r == pytest.approx(4 * gamma * omega / math.pi)
    # start running (Omega = 3): 3 % above F_r it keeps running (slowly: near the separatrix the
    # mean velocity is ~0.65 F/gamma), 3 % below it is trapped
    assert _mean_velocity(1.03 * F_r, gamma, omega, 2000.0, 3.0, rtol=1e-8) > 0.5 * 1.03 * F_r / gamma
    assert abs(_mean_velocity(0.97 * F_r, gamma, omega, 2000.0, 3.0, rtol=1e-8)) < 1e-3


# ---------------------------------------------------------------------------------------------
# 5. Damped random-frequency oscillator
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("D,gamma,omega", [(0.0, 0.3, 1.0), (0.5, 0.3, 1.0), (3.0, 0.1, 0.5), (1.0, 3.0, 1.0),
                                           (2.0, 0.0, 1.0), (0.7, 0.4, 0.0)])
def test_moment_growth_rate_is_the_top_eigenvalue(D, gamma, omega) -> None:
    M = f.random_frequency_moment_matrix(D=D, gamma=gamma, omega=omega)
    top = float(np.max(np.linalg.eigvals(M).real))
    assert f.random_frequency_moment_growth_rate(D=D, gamma=gamma, omega=omega) == pytest.approx(top, abs=1e-10)


def test_moment_growth_rate_undamped_is_the_scaling_law() -> None:
    for D in (0.01, 1.0, 30.0):
        assert f.random_frequency_moment_growth_rate(D=D, gamma=0.0, omega=1.3) == pytest.approx(
            harmonic_growth_rate("white", D=D, omega=1.3), rel=1e-10)


@pytest.mark.parametrize("gamma,omega", [(0.1, 1.0), (1.0, 0.7), (5.0, 1.0)])
def test_threshold_is_where_the_top_eigenvalue_crosses_zero(gamma, omega) -> None:
    Dc = f.random_frequency_threshold(gamma=gamma, omega=omega)
    assert Dc == pytest.approx(2 * gamma * omega**2)
    for D, sign in ((Dc * (1 - 1e-6), -1), (Dc * (1 + 1e-6), 1)):
        top = np.max(np.linalg.eigvals(f.random_frequency_moment_matrix(D=D, gamma=gamma, omega=omega)).real)
        assert np.sign(top) == sign
    # classical form: x'' + 2 zeta w x' + w^2 (1 + sigma n) x = 0 is mean-square stable iff sigma^2 w < 4 zeta
    zeta = gamma / (2 * omega)
    sigma2 = Dc / omega**4
    assert sigma2 * omega == pytest.approx(4 * zeta)


def test_ou_hierarchy_white_limit_and_convergence() -> None:
    gamma, omega = 0.2, 1.0
    for D in (0.1, 0.4, 2.0):
        white = f.random_frequency_moment_growth_rate(D=D, gamma=gamma, omega=omega)
        ou = f.random_frequency_ou_growth_rate(D=D, tau=1e-5, gamma=gamma, omega=omega)
        assert ou == pytest.approx(white, abs=1e-3 * max(1.0, abs(white)))
    for tau in (0.1, 1.0):
        a = f.random_frequency_ou_growth_rate(D=0.5, tau=tau, gamma=gamma, omega=omega, levels=64)
        b = f.random_frequency_ou_growth_rate(D=0.5, tau=tau, gamma=gamma, omega=omega, levels=128)
        assert a == pytest.approx(b, abs=1e-10)


def test_ou_hierarchy_weak_noise_is_the_averaging_rate() -> None:
    # weak noise: <E> grows at S(2 omega)/(2 omega^2) (harmonic_growth_rate, from averaging) minus gamma
    D, tau, gamma, omega = 1e-4, 0.4, 1e-4, 1.0
    rate = f.random_frequency_ou_growth_rate(D=D, tau=tau, gamma=gamma, omega=omega)
    assert rate == pytest.approx(harmonic_growth_rate("ou", D=D, tau=tau, omega=omega) - gamma, rel=2e-3)


def test_ou_threshold_series_error_is_third_order() -> None:
    gamma, omega = 0.5, 1.0
    errors = []
    for tau in (0.02, 0.01, 0.005):
        exact = f.random_frequency_ou_threshold(tau=tau, gamma=gamma, omega=omega)
        errors.append(abs(f.random_frequency_ou_threshold_series(tau=tau, gamma=gamma, omega=omega) - exact) / exact)
    assert errors[0] < 2e-4
    for a, b in zip(errors, errors[1:], strict=False):
        assert a / b == pytest.approx(8.0, rel=0.1)  # O(tau^3)
    assert f.random_frequency_ou_threshold_series(tau=0.0, gamma=gamma, omega=omega) == f.random_frequency_threshold(
        gamma=gamma, omega=omega)


def test_ou_threshold_weak_damping() -> None:
    omega = 1.0
    for gamma, tau, rel in ((1e-3, 0.3, 1e-3), (1e-3, 1.0, 1e-2), (1e-2, 0.3, 1e-2)):
        exact = f.random_frequency_ou_threshold(tau=tau, gamma=gamma, omega=omega)
        weak = f.random_frequency_ou_threshold_weak_noise(tau=tau, gamma=gamma, omega=omega)
        assert weak == pytest.approx(exact, rel=rel)


def _lyapunov_direct(D: float, w2: float, L: float = 400.0) -> float:
    """<z> of the stationary Riccati density P(z) ~ int_0^inf exp(Phi(z - s) - Phi(z)) ds, by quadrature
    over z in [-L, L] (principal value; the 1/z^2 tails add D/L to the norm)."""

    def P(z: float) -> float:
        g = lambda s: math.exp(-(2 / D) * (w2 * s + z * z * s - z * s * s + s**3 / 3))  # noqa: E731
        if z * z + w2 > D / 2:
            sc = D / (2 * (z * z + w2))
            return sum(quad(g, a, b, limit=200)[0] for a, b in ((0, sc), (sc, 50 * sc), (50 * sc, np.inf)))
        return quad(g, 0, np.inf, limit=400)[0]

    edges = np.concatenate([-np.geomspace(L, 1, 40), np.linspace(-1, 1, 21)[1:-1], np.geomspace(1, L, 40)])
    pieces = list(zip(edges[:-1], edges[1:], strict=True))
    norm = sum(quad(P, a, b, limit=200)[0] for a, b in pieces) + D / L
    first = sum(quad(lambda z: z * P(z), a, b, limit=200)[0] for a, b in pieces)
    return first / norm


@pytest.mark.parametrize("D,gamma,omega", [(1.0, 0.0, 1.0), (2.0, 2.0 * math.sqrt(1.5), 1.0)])
def test_lyapunov_against_the_riccati_density(D, gamma, omega) -> None:
    w2 = omega**2 - gamma**2 / 4  # 1 and -0.5
    expected = _lyapunov_direct(D, w2) - gamma / 2
    assert f.random_frequency_lyapunov(D=D, gamma=gamma, omega=omega) == pytest.approx(expected, rel=1e-6)


def test_lyapunov_limits() -> None:
    # small noise: D/(8 w1^2) - gamma/2 (Arnold, Papanicolaou & Wihstutz 1986)
    for D, gamma in ((1e-3, 0.0), (1e-3, 0.2)):
        small = f.random_frequency_lyapunov_small_noise(D=D, gamma=gamma, omega=1.0)
        assert f.random_frequency_lyapunov(D=D, gamma=gamma, omega=1.0) == pytest.approx(small, abs=1e-3 * D)
    # omega = gamma = 0: (sqrt(pi)/(2 Gamma(1/6))) (6 D)^(1/3)
    D = 0.37
    closed = math.sqrt(math.pi) / (2 * gamma_fn(1 / 6)) * (6 * D) ** (1 / 3)
    assert f.random_frequency_lyapunov(D=D, gamma=0.0, omega=0.0) == pytest.approx(closed, rel=1e-9)
    # overdamped, D -> 0: the deterministic rate -gamma/2 + sqrt(gamma^2/4 - omega^2)
    assert f.random_frequency_lyapunov(D=1e-6, gamma=3.0, omega=1.0) == pytest.approx(
        -1.5 + math.sqrt(1.25), abs=1e-5)
    # the mean-square rate bounds the typical one (Jensen: 2 lambda <= lambda_2)
    for D in (0.1, 1.0, 5.0):
        assert 2 * f.random_frequency_lyapunov(D=D, gamma=0.3, omega=1.0) <= f.random_frequency_moment_growth_rate(
            D=D, gamma=0.3, omega=1.0) + 1e-12


@pytest.mark.parametrize("gamma", [1e-3, 0.05, 0.5])
def test_typical_threshold(gamma: float) -> None:
    omega = 1.0
    Dt = f.random_frequency_typical_threshold(gamma=gamma, omega=omega)
    assert f.random_frequency_lyapunov(D=Dt, gamma=gamma, omega=omega) == pytest.approx(0.0, abs=1e-10)
    assert Dt > f.random_frequency_threshold(gamma=gamma, omega=omega)
    small = f.random_frequency_typical_threshold_small_noise(gamma=gamma, omega=omega)
    if gamma <= 0.05:
        assert Dt == pytest.approx(small, rel=5 * gamma)


# ---------------------------------------------------------------------------------------------
# 6. The table
# ---------------------------------------------------------------------------------------------


def test_family_predictions_rows() -> None:
    rows = f.family_predictions(D_a=0.2, gamma=0.5, omega=1.0, D=0.5, F=2.0)
    get = {(r.regime.split(",")[0], r.quantity, r.equation): r for r in rows}
    assert get[("Boltzmann", "T", "FPE stationary law")].value == pytest.approx(0.2)
    assert get[("random frequency", "D_c", "closed 2nd moments")].value == pytest.approx(1.0)
    assert get[("tilted washboard (torque F)", "<Omega>", "force balance")].value == pytest.approx(4.0)
    assert not any("outside validity" in r.note for r in rows)
    assert all(r.validity and r.equation for r in rows)
    low = f.family_predictions(D_a=1.0, gamma=0.5, omega=1.0)  # Delta U/T = 2
    assert any("outside validity" in r.note for r in low)
    ou = f.family_predictions(noise="ou", tau=0.5, D_a=0.2, gamma=0.5, omega=1.0, D=0.5)
    assert {r.regime.split(",")[0] for r in ou} == {"harmonic", "random frequency"}
    assert math.isnan([r for r in ou if r.quantity == "lambda"][0].value)
    assert [r for r in ou if r.quantity == "<x^2>"][0].value == pytest.approx(1 / 6)


# ---------------------------------------------------------------------------------------------
# Bad input: one line naming the parameter
# ---------------------------------------------------------------------------------------------

BAD = [
    (lambda: f.temperature(D_a=-1.0, gamma=1.0), "D_a=-1.0 is not accepted"),
    (lambda: f.temperature(D_a=1.0, gamma=0.0), "gamma=0.0 is not accepted"),
    (lambda: f.boltzmann_pendulum_mean_cos(D_a=1.0, gamma=1.0, omega=-1.0), "omega=-1.0"),
    (lambda: f.boltzmann_harmonic_mean_x2(D_a=1.0, gamma=1.0, omega=0.0), "omega=0.0"),
    (lambda: f.boltzmann_power_mean_x2(D_a=1.0, gamma=1.0, omega=1.0, power_n=1.5), "power_n=1.5"),
    (lambda: f.harmonic_ou_additive_variances(D_a=1.0, tau=0.0, gamma=1.0, omega=1.0), "tau=0.0"),
    (lambda: f.harmonic_ou_additive_variances(D_a=float("nan"), tau=1.0, gamma=1.0, omega=1.0), "D_a=nan"),
    (lambda: f.kramers_rate_spatial_diffusion(D_a=1.0, gamma=1.0, omega=0.0), "omega=0.0"),
    (lambda: f.melnikov_meshkov_A(0.0), "Delta=0.0"),
    (lambda: f.pendulum_slip_rate(D_a=1.0, gamma=1.0, omega=1.0, regime="fast"), "regime='fast'"),
    (lambda: f.running_velocity(F=float("inf"), gamma=1.0), "F=inf"),
    (lambda: f.random_frequency_moment_growth_rate(D=-1.0, gamma=0.1, omega=1.0), "D=-1.0"),
    (lambda: f.random_frequency_ou_growth_rate(D=1.0, tau=1.0, gamma=0.1, omega=1.0, levels=2), "levels=2"),
    (lambda: f.random_frequency_ou_threshold(tau=1.0, gamma=0.0, omega=1.0), "gamma=0.0"),
    (lambda: f.random_frequency_lyapunov(D=0.0, gamma=0.1, omega=1.0), "D=0.0"),
    (lambda: f.random_frequency_lyapunov_small_noise(D=0.1, gamma=3.0, omega=1.0), "omega=1.0"),
    (lambda: f.random_frequency_typical_threshold(gamma=0.1, omega=0.0), "omega=0.0"),
    (lambda: f.family_predictions(noise="pink", D_a=1.0, gamma=1.0), "noise='pink'"),
    (lambda: f.family_predictions(noise="ou", D_a=1.0, gamma=1.0), "tau=None"),
    (lambda: f.family_predictions(D_a=1.0, gamma=1.0, omega="x"), "omega='x'"),
]


@pytest.mark.parametrize("call,needle", BAD)
def test_bad_input_is_one_line(call, needle) -> None:
    with pytest.raises(ValueError) as info:
        call()
    message = str(info.value)
    assert needle in message and "\n" not in message and "is not accepted" in message


# ---------------------------------------------------------------------------------------------
# The command: stochpend theory --family
# ---------------------------------------------------------------------------------------------


def _invoke(args: list[str]):
    from typer.testing import CliRunner

    from stochpend import cli

    return CliRunner().invoke(cli.app, ["theory", *args])


def test_cli_family_tables() -> None:
    result = _invoke(["--family", "--noise", "white", "--gamma", "0.5", "--D-a", "0.2", "--F", "2"])
    assert result.exit_code == 0, result.output
    for needle in ("Damped, driven family, white noise", "Boltzmann", "Kramers", "washboard", "random frequency",
                   "0.893383", "1.12832e-05"):
        assert needle in result.output, (needle, result.output)
    result = _invoke(["--family", "--noise", "ou", "--tau", "0.5", "--D-a", "0.2", "--gamma", "0.5"])
    assert result.exit_code == 0, result.output
    assert "Hermite hierarchy" in result.output and "0.166667" in result.output


@pytest.mark.parametrize("args,needle", [
    (["--family", "--gamma", "0"], "--gamma 0.0 is not accepted"),
    (["--family", "--D-a", "-1"], "--D-a -1.0 is not accepted"),
    (["--family", "--bfpe"], "--bfpe"),
    (["--family", "--noise", "dichotomous"], "--noise 'dichotomous' is not accepted"),
])
def test_cli_family_bad_input_one_line(args, needle) -> None:
    result = _invoke(args)
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:"), result.output
    assert needle in lines[0]


def test_cli_family_table_fits_80_columns() -> None:
    from rich.console import Console

    from stochpend.cli._theory import theory_table

    for kw in ({"noise": "white", "F": 2.0}, {"noise": "ou", "tau": 0.5}):
        console = Console(width=80, record=True, file=__import__("io").StringIO())
        console.print(theory_table(f.family_predictions(D_a=0.2, gamma=0.5, omega=1.0, D=1.0, **kw), title="t"))
        assert max(len(line) for line in console.export_text().splitlines()) <= 80
