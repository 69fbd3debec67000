r"""Closed forms for the damped, driven oscillator family, one function per law.

The family is

    dx/dt = Omega
    dOmega/dt = -gamma Omega - omega**2 U'(x) - (xi(t) + eps cos(nu_p t)) G(x)
                + F + A cos(nu t + phi) + xi_a(t)

with gamma >= 0 the damping, F a constant torque, A, nu, phi an external drive, eps, nu_p a
parametric modulation, xi a multiplicative noise and xi_a an independent additive noise. Each
function below states the special case it is exact or asymptotic for.

Noise normalisation: the package's (:mod:`stochpend.noises`, docs/models.md). White noise of
intensity D has <xi(t) xi(s)> = D delta(t - s) (NOT 2 D delta), spectrum S(0) = D; the OU noise
has dxi = -xi/tau dt + sqrt(D)/tau dW, <xi(t) xi(s)> = D/(2 tau) exp(-|t - s|/tau), again
S(0) = D. The additive noise xi_a has its own intensity ``D_a`` in the same convention. Units:
Omega is 1/time, the noises are 1/time**2, D and D_a are 1/time**3, energies
E = Omega**2/2 + omega**2 U(x) and the temperature T are 1/time**2.

Temperature (derived, the one place where the factor 2 enters): with additive white noise
only, the Fokker-Planck equation is

    dP/dt = -Omega dP/dx + d/dOmega[(gamma Omega + omega**2 U'(x)) P] + (D_a/2) d2P/dOmega2

(the diffusion coefficient is half the noise intensity, D_a/2). The Hamiltonian part leaves
any function of E invariant; the damping and diffusion terms cancel when
gamma Omega P + (D_a/2) dP/dOmega = 0, i.e. P ~ exp(-gamma Omega**2/D_a) = exp(-Omega**2/(2T)):

    T = D_a/(2 gamma)            (package convention <xi_a xi_a'> = D_a delta)

The physics convention <xi_a xi_a'> = 2 D_a delta would give T = D_a/gamma; it is NOT the
package's and is not used here. Every function takes ``D_a`` and ``gamma`` and computes T
itself (:func:`temperature`).

Bad inputs raise a one-line :class:`ValueError` naming the parameter, the value received and
what is accepted. All functions take and return Python scalars (no broadcasting), except
:func:`random_frequency_moment_matrix` (a 3x3 array) and the NamedTuple results.

References
----------
* H. A. Kramers, Physica 7, 284 (1940).
* P. Hänggi, P. Talkner and M. Borkovec, Rev. Mod. Phys. 62, 251 (1990) ("HTB").
* V. I. Mel'nikov and S. V. Meshkov, J. Chem. Phys. 85, 1018 (1986).
* S. Lifson and J. L. Jackson, J. Chem. Phys. 36, 2410 (1962) (effective diffusion in a
  periodic potential, used in the tests).
* L. Arnold, G. Papanicolaou and V. Wihstutz, SIAM J. Appl. Math. 46, 427 (1986) (small-noise
  Lyapunov exponent of the random oscillator).
* Derivations not found in these are written out in docs/theory.md ("The damped, driven
  family") and in the docstrings.
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray
from scipy.special import ive as _ive

from stochpend.theory.laws import _fail, _scalar
from stochpend.theory.table import Prediction

__all__ = [
    "KRAMERS_MIN_BARRIER",
    "REGIME_ENERGY_BELOW",
    "REGIME_SPATIAL_ABOVE",
    "HarmonicAdditiveVariances",
    "OUAdditiveVariances",
    "boltzmann_harmonic_mean_E",
    "boltzmann_harmonic_mean_x2",
    "boltzmann_mean_Omega2",
    "boltzmann_pendulum_energy_moment",
    "boltzmann_pendulum_mean_E",
    "boltzmann_pendulum_mean_cos",
    "boltzmann_pendulum_mean_cos2",
    "boltzmann_power_mean_E",
    "boltzmann_power_mean_x2",
    "FAMILY_NOISES",
    "family_predictions",
    "free_particle_diffusion",
    "free_particle_drift",
    "harmonic_harmonic_additive_variances",
    "harmonic_ou_additive_mean_E",
    "harmonic_ou_additive_variances",
    "kramers_rate_energy_diffusion",
    "kramers_rate_energy_diffusion_mfpt",
    "kramers_rate_melnikov_meshkov",
    "kramers_rate_spatial_diffusion",
    "kramers_regime",
    "locking_torque",
    "melnikov_meshkov_A",
    "pendulum_barrier",
    "pendulum_energy_loss",
    "pendulum_slip_rate",
    "random_frequency_lyapunov",
    "random_frequency_lyapunov_small_noise",
    "random_frequency_moment_growth_rate",
    "random_frequency_moment_matrix",
    "random_frequency_ou_growth_rate",
    "random_frequency_ou_threshold",
    "random_frequency_ou_threshold_series",
    "random_frequency_ou_threshold_weak_noise",
    "random_frequency_threshold",
    "random_frequency_typical_threshold",
    "random_frequency_typical_threshold_small_noise",
    "retrapping_torque",
    "running_velocity",
    "smoluchowski_effective_diffusion",
    "temperature",
]

#: Kramers' formulas are asymptotic in T/Delta U; below this barrier height (in units of T)
#: their rows say they are outside their validity (relative errors of order T/Delta U).
KRAMERS_MIN_BARRIER: float = 5.0
#: Below this energy loss per branch Delta (in units of T) the energy-diffusion rate is within
#: 10 % of the Mel'nikov-Meshkov interpolation (A(0.01)/0.01 = 0.92).
REGIME_ENERGY_BELOW: float = 0.01
#: Above this Delta the spatial-diffusion rate is within 15 % of Mel'nikov-Meshkov
#: (A(5) = 0.879, A(10) = 0.974).
REGIME_SPATIAL_ABOVE: float = 5.0


# ---------------------------------------------------------------------------------------------
# Validation
# ---------------------------------------------------------------------------------------------


def _positive(name: str, value: Any, meaning: str) -> float:
    msg = f"{name} must be a finite number > 0 ({meaning})"
    v = _scalar(name, value, msg)
    if v <= 0:
        _fail(name, value, msg)
    return v


def _nonnegative(name: str, value: Any, meaning: str) -> float:
    msg = f"{name} must be a finite number >= 0 ({meaning})"
    v = _scalar(name, value, msg)
    if v < 0:
        _fail(name, value, msg)
    return v


def _finite(name: str, value: Any, meaning: str) -> float:
    return _scalar(name, value, f"{name} must be a finite number ({meaning})")


_GAMMA = "the damping rate"
_DA = "the additive white-noise intensity, <xi_a xi_a'> = D_a delta"
_D = "the multiplicative noise intensity, <xi xi'> = D delta (white) or S(0) = D (OU)"
_OMEGA = "the oscillator frequency"
_TAU = "the OU correlation time"


# ---------------------------------------------------------------------------------------------
# 1. Boltzmann equilibrium: additive white noise, gamma > 0, no multiplicative noise,
#    F = A = eps = 0
# ---------------------------------------------------------------------------------------------


def temperature(*, D_a: float, gamma: float) -> float:
    """The temperature T = D_a/(2 gamma) of the additive white noise (units 1/time**2).

    Derived in the module docstring from the package's normalisation <xi_a xi_a'> = D_a delta
    (fluctuation-dissipation: the Fokker-Planck diffusion coefficient is D_a/2). Requires
    D_a > 0 and gamma > 0.
    """
    D_a = _positive("D_a", D_a, _DA)
    gamma = _positive("gamma", gamma, _GAMMA)
    return D_a / (2.0 * gamma)


def boltzmann_mean_Omega2(*, D_a: float, gamma: float) -> float:
    """<Omega**2> = T = D_a/(2 gamma) in the Boltzmann state P ~ exp(-E/T) (equipartition).

    Conditions: additive white noise of intensity D_a > 0, damping gamma > 0, no multiplicative
    noise, F = A = eps = 0; any confining or periodic potential (the Omega marginal is the
    Maxwellian of variance T whatever U). Units 1/time**2.
    """
    return temperature(D_a=D_a, gamma=gamma)


def _kappa(D_a: float, gamma: float, omega: float) -> tuple[float, float]:
    T = temperature(D_a=D_a, gamma=gamma)
    omega = _nonnegative("omega", omega, _OMEGA + "; omega = 0 is the free rotor, <cos x> = 0")
    return T, omega * omega / T


def boltzmann_pendulum_mean_cos(*, D_a: float, gamma: float, omega: float) -> float:
    """Pendulum (U = -cos x) in the Boltzmann state: <cos x> = I_1(kappa)/I_0(kappa), kappa = omega**2/T.

    The x marginal is the von Mises law exp(kappa cos x)/(2 pi I_0(kappa)) on one turn (x an
    angle), T = D_a/(2 gamma). Conditions as :func:`boltzmann_mean_Omega2`, omega >= 0.
    Dimensionless. Evaluated with exponentially scaled Bessel functions (no overflow).
    """
    _, k = _kappa(D_a, gamma, omega)
    return float(_ive(1, k) / _ive(0, k))


def boltzmann_pendulum_mean_cos2(*, D_a: float, gamma: float, omega: float) -> float:
    """Pendulum in the Boltzmann state: <cos**2 x> = 1/2 + I_2(kappa)/(2 I_0(kappa)), kappa = omega**2/T.

    From cos**2 x = (1 + cos 2x)/2 and <cos n x> = I_n(kappa)/I_0(kappa) for the von Mises law.
    Conditions as :func:`boltzmann_pendulum_mean_cos`. Dimensionless.
    """
    _, k = _kappa(D_a, gamma, omega)
    return float(0.5 + 0.5 * _ive(2, k) / _ive(0, k))


def boltzmann_pendulum_mean_E(*, D_a: float, gamma: float, omega: float) -> float:
    """Pendulum in the Boltzmann state: <E> = T/2 - omega**2 I_1(kappa)/I_0(kappa), E = Omega**2/2 - omega**2 cos x.

    Conditions as :func:`boltzmann_pendulum_mean_cos`. Units 1/time**2.
    """
    T, k = _kappa(D_a, gamma, omega)
    return float(0.5 * T - omega * omega * _ive(1, k) / _ive(0, k))


def boltzmann_pendulum_energy_moment(n: int, *, D_a: float, gamma: float, omega: float) -> float:
    """Pendulum in the Boltzmann state: <E**n>, E = Omega**2/2 - omega**2 cos x, n = 1, 2, ...

    Omega ~ N(0, T) is independent of the von Mises angle, so <E**n> = sum_j C(n, j)
    <(Omega**2/2)**j> <(-omega**2 cos x)**(n-j)>, with <(Omega**2/2)**j> = T**j (2j-1)!!/2**j and
    <cos**m x> = 2**-m sum_k C(m, k) I_|m-2k|(kappa)/I_0(kappa) (cos**m as a sum of cos(l x)).
    The paper's skewness and flatness of the Boltzmann law follow: S = <E^3>/<E^2>^(3/2), F =
    <E^4>/<E^2>^2. Conditions as :func:`boltzmann_pendulum_mean_cos`. Units 1/time**(2n).
    """
    if isinstance(n, bool) or not isinstance(n, int) or n < 1:
        raise ValueError(f"n={n!r} is not accepted: an integer >= 1")
    T, k = _kappa(D_a, gamma, omega)
    i0 = _ive(0, k)

    def mean_cos_power(m: int) -> float:
        return sum(math.comb(m, j) * float(_ive(abs(m - 2 * j), k)) for j in range(m + 1)) / (2.0**m * i0)

    def kinetic(j: int) -> float:
        return T**j * math.prod(range(1, 2 * j, 2)) / 2.0**j

    return float(sum(math.comb(n, j) * kinetic(j) * (-omega * omega) ** (n - j) * mean_cos_power(n - j)
                     for j in range(n + 1)))


def _harmonic_T(D_a: float, gamma: float, omega: float) -> tuple[float, float]:
    T = temperature(D_a=D_a, gamma=gamma)
    omega = _positive("omega", omega, _OMEGA + "; omega = 0 has no equilibrium")
    return T, omega


def boltzmann_harmonic_mean_x2(*, D_a: float, gamma: float, omega: float) -> float:
    """Harmonic oscillator (U = x**2/2) in the Boltzmann state: <x**2> = T/omega**2 = D_a/(2 gamma omega**2).

    Exact stationary law (Gaussian); also the tau -> 0 limit of
    :func:`harmonic_ou_additive_variances`. Conditions as :func:`boltzmann_mean_Omega2` and
    omega > 0. Units of x**2 (dimensionless x).
    """
    T, omega = _harmonic_T(D_a, gamma, omega)
    return T / (omega * omega)


def boltzmann_harmonic_mean_E(*, D_a: float, gamma: float, omega: float) -> float:
    """Harmonic oscillator in the Boltzmann state: <E> = T (T/2 kinetic + T/2 potential).

    Conditions as :func:`boltzmann_harmonic_mean_x2`. Units 1/time**2.
    """
    T, _ = _harmonic_T(D_a, gamma, omega)
    return T


def _power_n(power_n: Any) -> int:
    if isinstance(power_n, bool) or not isinstance(power_n, (int, np.integer)) or power_n < 1:
        _fail("power_n", power_n, "power_n must be an integer >= 1 (U = x^(2n)/(2n))")
    return int(power_n)


def boltzmann_power_mean_x2(*, D_a: float, gamma: float, omega: float, power_n: int) -> float:
    """U = x**(2n)/(2n) in the Boltzmann state: <x**2> = (2 n T/omega**2)**(1/n) Gamma(3/(2n))/Gamma(1/(2n)).

    From the x marginal exp(-omega**2 x**(2n)/(2 n T)) (substitute u = omega**2 x**(2n)/(2nT)).
    n = 1 is :func:`boltzmann_harmonic_mean_x2`. Conditions as :func:`boltzmann_mean_Omega2`,
    omega > 0, n >= 1 an integer.
    """
    T, omega = _harmonic_T(D_a, gamma, omega)
    n = _power_n(power_n)
    return float((2.0 * n * T / omega**2) ** (1.0 / n) * math.exp(math.lgamma(1.5 / n) - math.lgamma(0.5 / n)))


def boltzmann_power_mean_E(*, D_a: float, gamma: float, omega: float, power_n: int) -> float:
    """U = x**(2n)/(2n) in the Boltzmann state: <E> = T/2 + T/(2n) (virial: <omega**2 U> = T/(2n)).

    Conditions as :func:`boltzmann_power_mean_x2`.
    """
    T, _ = _harmonic_T(D_a, gamma, omega)
    n = _power_n(power_n)
    return 0.5 * T + T / (2.0 * n)


# ---------------------------------------------------------------------------------------------
# 2. Damped harmonic oscillator with additive OU noise
# ---------------------------------------------------------------------------------------------


class OUAdditiveVariances(NamedTuple):
    """Stationary second moments of (x, Omega, xi_a), see :func:`harmonic_ou_additive_variances`."""

    mean_x2: float
    mean_xOmega: float
    mean_Omega2: float
    mean_x_xi: float
    mean_Omega_xi: float
    mean_xi2: float


def harmonic_ou_additive_variances(*, D_a: float, tau: float, gamma: float, omega: float) -> OUAdditiveVariances:
    """Stationary covariances of the damped harmonic oscillator driven by additive OU noise.

    Model: dx = Omega dt, dOmega = (-gamma Omega - omega**2 x + xi_a) dt,
    dxi_a = -xi_a/tau dt + sqrt(D_a)/tau dW (package OU: <xi_a xi_a'> = D_a/(2 tau) e^{-|t-t'|/tau}).
    No multiplicative noise, F = A = eps = 0.

    Derivation: the covariance Sigma of z = (x, Omega, xi_a) solves the Lyapunov equation
    M Sigma + Sigma M^T + Q = 0, M = [[0, 1, 0], [-omega**2, -gamma, 1], [0, 0, -1/tau]],
    Q = diag(0, 0, D_a/tau**2). Entry by entry: (xi, xi) gives <xi**2> = D_a/(2 tau);
    (x, x) gives <x Omega> = 0; (x, xi) gives <Omega xi> = <x xi>/tau; (Omega, xi) gives
    <x xi> (omega**2 + gamma/tau + 1/tau**2) = D_a/(2 tau); (Omega, Omega) gives
    <Omega**2> = <Omega xi>/gamma; (x, Omega) gives omega**2 <x**2> = <Omega**2> + <x xi>. With
    N = 1 + gamma tau + omega**2 tau**2:

        <x**2>      = D_a (1 + gamma tau) / (2 gamma omega**2 N)
        <Omega**2>  = D_a / (2 gamma N)
        <x Omega>   = 0
        <x xi_a>    = D_a tau / (2 N),   <Omega xi_a> = D_a / (2 N),   <xi_a**2> = D_a/(2 tau)

    tau -> 0 gives the Boltzmann values T/omega**2 and T, T = D_a/(2 gamma).

    Parameters: D_a > 0 (1/time**3), tau > 0, gamma > 0, omega > 0.
    """
    D_a = _positive("D_a", D_a, "the additive OU noise intensity, S(0) = D_a")
    tau = _positive("tau", tau, _TAU)
    gamma = _positive("gamma", gamma, _GAMMA + "; gamma = 0 has no stationary state")
    omega = _positive("omega", omega, _OMEGA + "; omega = 0 has no stationary <x^2>")
    N = 1.0 + gamma * tau + (omega * tau) ** 2
    return OUAdditiveVariances(
        mean_x2=D_a * (1.0 + gamma * tau) / (2.0 * gamma * omega**2 * N),
        mean_xOmega=0.0,
        mean_Omega2=D_a / (2.0 * gamma * N),
        mean_x_xi=D_a * tau / (2.0 * N),
        mean_Omega_xi=D_a / (2.0 * N),
        mean_xi2=D_a / (2.0 * tau),
    )


def harmonic_ou_additive_mean_E(*, D_a: float, tau: float, gamma: float, omega: float) -> float:
    """<E> = (<Omega**2> + omega**2 <x**2>)/2 = D_a (2 + gamma tau) / (4 gamma N), N = 1 + gamma tau + omega**2 tau**2.

    Conditions as :func:`harmonic_ou_additive_variances`. Units 1/time**2.
    """
    v = harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    return 0.5 * (v.mean_Omega2 + omega * omega * v.mean_x2)


class HarmonicAdditiveVariances(NamedTuple):
    """Stationary second moments of (x, Omega, xi_a, eta_a = dxi_a/dt), see
    :func:`harmonic_harmonic_additive_variances`."""

    mean_x2: float
    mean_xOmega: float
    mean_Omega2: float
    mean_x_xi: float
    mean_Omega_xi: float
    mean_xi2: float
    mean_eta2: float


def harmonic_harmonic_additive_variances(*, D_a: float, tau: float, gamma: float, omega: float,
                                         omega_noise: float | None = None) -> HarmonicAdditiveVariances:
    """Stationary covariances of the damped harmonic oscillator driven by additive HARMONIC noise
    (``additive_noise="harmonic"``, :mod:`stochpend.noises.harmonic`).

    Model: dx = Omega dt, dOmega = (-gamma Omega - omega**2 x + xi_a) dt, and
    xi_a'' + Gamma xi_a' + W**2 xi_a = W**2 sqrt(D_a) zeta(t) (zeta unit white noise, Gamma =
    W**2 tau, W = ``omega_noise``, default 2/tau: critical damping), so S(0) = D_a and
    <xi_a**2> = D_a/(2 tau). No multiplicative noise, F = A = eps = 0.

    The vector z = (x, Omega, xi_a, eta_a) is linear, dz = M z dt + b dW with
    M = [[0, 1, 0, 0], [-omega**2, -gamma, 1, 0], [0, 0, 0, 1], [0, 0, -W**2, -Gamma]],
    b = (0, 0, 0, W**2 sqrt(D_a)), so its stationary covariance Sigma solves the Lyapunov equation
    M Sigma + Sigma M^T + b b^T = 0 exactly; it is solved numerically here
    (``scipy.linalg.solve_continuous_lyapunov``, round-off accurate for these 4 x 4 systems).
    Closed form for a check: <Omega**2> = (1/2pi) int S(nu) nu**2 / |omega**2 - nu**2 + i gamma nu|**2 dnu.

    Parameters: D_a > 0 (1/time**3), tau > 0, gamma > 0, omega > 0, omega_noise > 0 (1/time).
    """
    import numpy as np
    from scipy.linalg import solve_continuous_lyapunov

    D_a = _positive("D_a", D_a, "the additive harmonic noise intensity, S(0) = D_a")
    tau = _positive("tau", tau, _TAU)
    gamma = _positive("gamma", gamma, _GAMMA + "; gamma = 0 has no stationary state")
    omega = _positive("omega", omega, _OMEGA + "; omega = 0 has no stationary <x^2>")
    W = _positive("omega_noise", 2.0 / tau if omega_noise is None else omega_noise,
                  "the harmonic noise's frequency W (default 2/tau)")
    G = W * W * tau
    M = np.array([[0.0, 1.0, 0.0, 0.0], [-omega * omega, -gamma, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0],
                  [0.0, 0.0, -W * W, -G]])
    Q = np.zeros((4, 4))
    Q[3, 3] = W**4 * D_a
    S = solve_continuous_lyapunov(M, -Q)
    S = 0.5 * (S + S.T)
    return HarmonicAdditiveVariances(
        mean_x2=float(S[0, 0]), mean_xOmega=float(S[0, 1]), mean_Omega2=float(S[1, 1]),
        mean_x_xi=float(S[0, 2]), mean_Omega_xi=float(S[1, 2]), mean_xi2=float(S[2, 2]),
        mean_eta2=float(S[3, 3]),
    )


# ---------------------------------------------------------------------------------------------
# 3. Kramers escape over the pendulum's barrier (additive white noise)
# ---------------------------------------------------------------------------------------------


def pendulum_barrier(*, omega: float) -> float:
    """The pendulum's barrier Delta U = 2 omega**2 (from the bottom x = 0 to the tops x = +-pi).

    The well and barrier curvatures are both omega**2 (omega_0 = omega_b = omega), and the
    action of one separatrix branch (x from -pi to pi at E = omega**2) is
    int 2 omega cos(x/2) dx = 8 omega (:func:`pendulum_energy_loss`).
    """
    omega = _positive("omega", omega, _OMEGA + "; omega = 0 has no barrier")
    return 2.0 * omega * omega


def _kramers_args(D_a: float, gamma: float, omega: float) -> tuple[float, float, float, float]:
    T = temperature(D_a=D_a, gamma=gamma)
    omega = _positive("omega", omega, _OMEGA + "; omega = 0 has no barrier")
    return T, float(gamma), omega, 2.0 * omega * omega


def pendulum_energy_loss(*, D_a: float, gamma: float, omega: float) -> float:
    """Delta = gamma I_b/T = 8 gamma omega/T = 4 (gamma/omega)(Delta U/T), I_b = 8 omega.

    The energy lost to friction along one separatrix branch (from one barrier top to the other,
    int gamma Omega dx = gamma I_b), in units of T = D_a/(2 gamma). Delta << 1: energy-diffusion
    (underdamped) regime; Delta >> 1: spatial-diffusion regime (HTB sec. IV). Dimensionless.
    """
    T, gamma, omega, _ = _kramers_args(D_a, gamma, omega)
    return 8.0 * gamma * omega / T


def kramers_rate_spatial_diffusion(*, D_a: float, gamma: float, omega: float) -> float:
    """Kramers' moderate-to-high friction rate over ONE barrier of the pendulum (1/time).

        k = (omega_0/(2 pi)) (sqrt(gamma**2/4 + omega_b**2) - gamma/2)/omega_b exp(-Delta U/T)

    with omega_0 = omega_b = omega, Delta U = 2 omega**2, T = D_a/(2 gamma) (Kramers 1940;
    HTB Eq. 4.7). gamma >> omega gives the Smoluchowski rate omega_0 omega_b/(2 pi gamma)
    e^{-Delta U/T}. Validity: Delta U/T >= 5 (relative error O(T/Delta U): at high friction it
    overestimates the exact Smoluchowski rate (:func:`smoluchowski_effective_diffusion`) by about
    T/(2 Delta U): 13 % at Delta U/T = 5, 5.5 % at 10, 2.6 % at 20, checked in the tests) and
    energy loss per branch Delta = 8 gamma omega/T >~ 5 (:func:`kramers_regime`); at lower
    friction it overestimates the rate (by 1/A(Delta), :func:`melnikov_meshkov_A`).
    """
    T, gamma, omega, dU = _kramers_args(D_a, gamma, omega)
    h = 0.5 * gamma / omega
    transmission = math.sqrt(h * h + 1.0) - h  # (sqrt(gamma^2/4 + w_b^2) - gamma/2)/w_b, w_b = omega
    return omega / (2.0 * math.pi) * transmission * math.exp(-dU / T)


def kramers_rate_energy_diffusion(*, D_a: float, gamma: float, omega: float) -> float:
    """Kramers' low-friction (energy-diffusion) rate over ONE barrier of the pendulum (1/time).

        k = gamma I_b/T (omega_0/(2 pi)) exp(-Delta U/T),   I_b = 8 omega

    (Kramers 1940; HTB Eq. 4.48), I_b the action of one separatrix branch, T = D_a/(2 gamma).
    Derivation of the factor: the averaged energy diffusion (drift -gamma I(E)/P(E) + D_a/2,
    diffusion D_a I(E)/P(E), P the period, I the action of the closed orbit) has mean first
    passage time (2 pi/omega)(T/gamma) e^{Delta U/T}/I(E_b) from the bottom to the separatrix,
    where the closed orbit is both branches, I(E_b) = 16 omega: that is the total rate of
    leaving the well, split equally between the two barriers (the sign of Omega on arrival),
    2 k with I_b = 8 omega per barrier (checked against the MFPT quadrature in the tests).
    Validity: Delta = 8 gamma omega/T <~ 0.01 (within 10 % of the Mel'nikov-Meshkov
    interpolation; the approach to it is slow, A(Delta)/Delta - 1 ~ sqrt(Delta)) and Delta U/T
    >= 5, with a relative error of about 2 T/Delta U from the Laplace evaluation of the mean
    first-passage time (the rate is too high by 33 % at Delta U/T = 5, 19 % at 10, 10 % at 20,
    against :func:`kramers_rate_energy_diffusion_mfpt`, which has no such error).
    Note: at such low friction an escaped pendulum runs over several wells before it is
    retrapped (HTB sec. IV.C), so this rate of leaving a well is not the rate of 2 pi slips.
    """
    T, gamma, omega, dU = _kramers_args(D_a, gamma, omega)
    return gamma * 8.0 * omega / T * omega / (2.0 * math.pi) * math.exp(-dU / T)


def _pendulum_action(E: float, omega: float) -> float:
    """Action int Omega dx around the closed pendulum orbit of energy -omega**2 <= E <= omega**2.

    16 omega [E(m) - (1 - m) K(m)], m = (E + omega**2)/(2 omega**2) (complete elliptic
    integrals, parameter m); 16 omega on the separatrix (both branches).
    """
    from scipy.special import ellipe, ellipk

    m = min(max((E + omega * omega) / (2.0 * omega * omega), 0.0), 1.0)
    if m >= 1.0:
        return 16.0 * omega
    return float(16.0 * omega * (ellipe(m) - (1.0 - m) * ellipk(m)))


def kramers_rate_energy_diffusion_mfpt(*, D_a: float, gamma: float, omega: float) -> float:
    """Low-friction rate over ONE barrier from the mean first-passage time of the energy diffusion (1/time).

    The averaged energy of the weakly damped pendulum (HTB sec. IV.A) diffuses with drift
    -gamma I(E)/P(E) + D_a/2 and diffusion coefficient D_a I(E)/P(E), I the action of the
    closed orbit (:func:`_pendulum_action`), P = dI/dE its period. With reflection at the bottom
    E = -omega**2 and absorption at the separatrix E_b = omega**2 the mean first-passage time
    from the bottom is, after an integration by parts that removes P,

        tau = (2/D_a) int_{-omega^2}^{E_b} dy [1 + e^{y/T}/(T I(y)) int_{-omega^2}^y I(z) e^{-z/T} dz]

    and the rate over one barrier is 1/(2 tau) (the total rate 1/tau is split between the two
    barriers). For Delta U/T -> infinity it tends to :func:`kramers_rate_energy_diffusion`.
    Validity: Delta = 8 gamma omega/T << 1 (energy diffusion), any barrier height for which
    escape is still a rare event. Nested quadrature, about 0.1 s.
    """
    from scipy.integrate import quad

    T, gamma, omega, _ = _kramers_args(D_a, gamma, omega)
    e_min, e_b = -omega * omega, omega * omega

    def integrand(y: float) -> float:
        I_y = _pendulum_action(y, omega)
        if I_y <= 0.0:
            return 1.0
        inner = quad(lambda z: _pendulum_action(z, omega) * math.exp((y - z) / T), e_min, y, epsrel=1e-11,
                     limit=200)[0]
        return 1.0 + inner / (T * I_y)

    tau = (2.0 / D_a) * quad(integrand, e_min, e_b, epsrel=1e-10, limit=200)[0]
    return 1.0 / (2.0 * tau)


def smoluchowski_effective_diffusion(*, D_a: float, gamma: float, omega: float) -> float:
    """Exact effective diffusion of the overdamped pendulum: D_eff = (T/gamma)/I_0(omega**2/T)**2 (1/time).

    Lifson & Jackson (1962): for gamma dx/dt = -omega**2 sin x + xi_a, D_eff =
    D_x/(<e^{U/T}> <e^{-U/T}>) with D_x = T/gamma and the averages over one period,
    <e^{+-omega**2 cos x/T}> = I_0(omega**2/T). With nearest-neighbour hops at rate k per
    direction D_eff = (2 pi)**2 k, so k = D_eff/(2 pi)**2 is the exact overdamped hop rate; for
    Delta U/T -> infinity it tends to the Smoluchowski limit of
    :func:`kramers_rate_spatial_diffusion`. Validity: gamma >> omega (overdamped), any T;
    F = 0. Measurable directly as lim Var x(t)/(2t).
    """
    T, gamma, omega, _ = _kramers_args(D_a, gamma, omega)
    kappa = omega * omega / T
    # I_0(kappa)**2 = ive(0, kappa)**2 e^{2 kappa}; the exponent is applied last (underflow to 0 is exact enough)
    return float(T / gamma / _ive(0, kappa) ** 2 * math.exp(-2.0 * kappa))


def melnikov_meshkov_A(Delta: float) -> float:
    """The Mel'nikov-Meshkov depopulation factor A(Delta) (Mel'nikov & Meshkov 1986; HTB sec. VI).

        A(Delta) = exp[(1/pi) int_0^inf ln(1 - exp(-Delta (y**2 + 1/4))) dy/(y**2 + 1/4)]

    normalised so that A -> Delta for Delta -> 0 (the energy-diffusion limit) and A -> 1 for
    Delta -> infinity (the spatial-diffusion limit). Delta > 0, dimensionless. Quadrature
    (scipy.integrate.quad, relative accuracy ~1e-10); 1 exactly for Delta > 200.
    """
    from scipy.integrate import quad

    d = _positive("Delta", Delta, "the energy loss per branch in units of T")
    if d > 200.0:  # the integrand is below exp(-50)
        return 1.0

    def f(y: float) -> float:
        return math.log(-math.expm1(-d * (y * y + 0.25))) / (y * y + 0.25)

    # [0, 1] directly; y > 1 as y = e^u, cut where the integrand changes form (y ~ Delta**(-1/2));
    # beyond y = 20 Delta**(-1/2) + 20 the integrand is below exp(-400).
    tol = 1e-13 * (1.0 + abs(math.log(d)))
    total = quad(f, 0.0, 1.0, limit=200, epsabs=tol, epsrel=1e-10)[0]
    u_c = max(0.0, -0.5 * math.log(d))
    u_end = math.log(20.0 / math.sqrt(d) + 20.0)
    cuts = sorted({0.0, u_c, min(u_c + 1.0, u_end), u_end})
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        total += quad(lambda u: f(math.exp(u)) * math.exp(u), a, b, limit=200, epsabs=tol, epsrel=1e-10)[0]
    return float(math.exp(total / math.pi))


def kramers_rate_melnikov_meshkov(*, D_a: float, gamma: float, omega: float) -> float:
    """Turnover interpolation over ONE barrier: k = A(Delta) k_spatial (1/time).

    A from :func:`melnikov_meshkov_A`, Delta = 8 gamma omega/T from
    :func:`pendulum_energy_loss`, k_spatial from :func:`kramers_rate_spatial_diffusion`. It
    reduces to the energy-diffusion rate for Delta -> 0 and to Kramers' spatial-diffusion rate
    for Delta -> infinity (both checked in the tests). Accuracy: exact in the two limits; in
    the turnover (Delta ~ 1) Mel'nikov & Meshkov's theory is for a single metastable well, and
    Mel'nikov's treatment of periodic potentials (where a particle can cross several barriers
    in a row) differs; the per-barrier use here with the one-branch loss is an approximation
    whose turnover error is not established in this package. Validity: Delta U/T >= 5.
    """
    k = kramers_rate_spatial_diffusion(D_a=D_a, gamma=gamma, omega=omega)
    return melnikov_meshkov_A(pendulum_energy_loss(D_a=D_a, gamma=gamma, omega=omega)) * k


def kramers_regime(*, D_a: float, gamma: float, omega: float) -> str:
    """Which Kramers regime applies: ``"energy diffusion"``, ``"turnover"`` or ``"spatial diffusion"``.

    The regime is set by the energy loss per branch Delta = 8 gamma omega/T =
    4 (gamma/omega)(Delta U/T), i.e. by gamma/omega at a given barrier height:

    * Delta < REGIME_ENERGY_BELOW (0.01), i.e. gamma/omega < 0.0025 T/Delta U: energy diffusion;
    * Delta > REGIME_SPATIAL_ABOVE (5), i.e. gamma/omega > 1.25 T/Delta U: spatial diffusion
      (gamma/omega >> 1: its Smoluchowski limit);
    * between: turnover (use :func:`kramers_rate_melnikov_meshkov`).

    The thresholds are where the limiting formula is within about 10-15 % of the
    Mel'nikov-Meshkov interpolation.
    """
    d = pendulum_energy_loss(D_a=D_a, gamma=gamma, omega=omega)
    if d < REGIME_ENERGY_BELOW:
        return "energy diffusion"
    if d > REGIME_SPATIAL_ABOVE:
        return "spatial diffusion"
    return "turnover"


def pendulum_slip_rate(*, D_a: float, gamma: float, omega: float, regime: str = "auto") -> float:
    """Total rate of escape from a pendulum well, both directions: 2 k (1/time).

    ``regime``: ``"spatial diffusion"``, ``"energy diffusion"``, ``"turnover"`` (Mel'nikov-
    Meshkov) or ``"auto"`` (:func:`kramers_regime`; its turnover uses Mel'nikov-Meshkov). The
    two barriers x = +-pi are equivalent, so the total rate is twice the one-barrier rate; the
    mean time spent in a well is 1/(2 k). Validity as the chosen formula (Delta U/T >= 5).
    """
    choices = ("auto", "spatial diffusion", "energy diffusion", "turnover")
    if regime not in choices:
        _fail("regime", regime, f"one of {', '.join(repr(c) for c in choices)}")
    if regime == "auto":
        regime = kramers_regime(D_a=D_a, gamma=gamma, omega=omega)
    rate = {
        "spatial diffusion": kramers_rate_spatial_diffusion,
        "energy diffusion": kramers_rate_energy_diffusion,
        "turnover": kramers_rate_melnikov_meshkov,
    }[regime]
    return 2.0 * rate(D_a=D_a, gamma=gamma, omega=omega)


# ---------------------------------------------------------------------------------------------
# 4. Tilted washboard (pendulum with torque F)
# ---------------------------------------------------------------------------------------------


def running_velocity(*, F: float, gamma: float) -> float:
    """The running solution's mean velocity <Omega> -> F/gamma (1/time).

    The force balance gamma <Omega> = F - omega**2 <sin x> with <sin x> -> 0 on the running
    solution: exact at omega = 0 (any noise, :func:`free_particle_drift`), the limit of large
    torque F >> omega**2 (relative correction O(omega**4/F**2): on the noiseless running orbit
    gamma <Omega> = F - omega**4 gamma/(2 v (gamma**2 + v**2)), v = F/gamma, from second-order
    perturbation in omega**2), and the running branch at low noise. Below the locking torque
    (|F| < omega**2, :func:`locking_torque`) and above the retrapping torque the pendulum is
    bistable at weak noise; there <Omega> is between 0 and F/gamma. F any finite number,
    gamma > 0.
    """
    F = _finite("F", F, "the constant torque")
    gamma = _positive("gamma", gamma, _GAMMA)
    return F / gamma


def free_particle_drift(*, F: float, gamma: float) -> float:
    """omega = 0 (free Brownian particle with torque): <Omega> = F/gamma exactly, any additive noise (1/time)."""
    return running_velocity(F=F, gamma=gamma)


def free_particle_diffusion(*, D_a: float, gamma: float) -> float:
    """omega = 0, additive white noise: D_eff = lim Var x(t)/(2t) = T/gamma = D_a/(2 gamma**2) (1/time).

    Einstein relation: D_eff = int_0^inf <Omega(0) Omega(t)>_c dt = <Omega**2>_c/gamma with the
    OU velocity's variance T = D_a/(2 gamma); independent of F. gamma > 0, D_a > 0.
    """
    T = temperature(D_a=D_a, gamma=gamma)
    return T / float(gamma)


def locking_torque(*, omega: float) -> float:
    """Largest |F| with a locked (fixed-point) solution: F = omega**2 (the washboard keeps minima iff |F| <= omega**2)."""
    omega = _nonnegative("omega", omega, _OMEGA)
    return omega * omega


def retrapping_torque(*, gamma: float, omega: float) -> float:
    """Smallest F with a running solution, noiseless, small damping: F_r = (4/pi) gamma omega (1/time**2).

    Energy balance on the running orbit at the threshold, which is the separatrix E = omega**2
    at leading order in gamma/omega: the torque's work per period 2 pi F equals the friction
    loss gamma int Omega dx = gamma I_b = 8 gamma omega. Validity: gamma/omega << 1 (relative
    corrections O(gamma/omega); checked at gamma/omega = 0.02 to within 3 % by orbits in the
    tests); at larger damping F_r rises towards omega**2 and the hysteresis closes at gamma/omega
    of order one (not computed here). gamma >= 0, omega >= 0.
    """
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    return 4.0 * gamma * omega / math.pi


# ---------------------------------------------------------------------------------------------
# 5. Damped random-frequency oscillator: x'' + gamma x' + (omega**2 + xi) x = 0
# ---------------------------------------------------------------------------------------------


def random_frequency_moment_matrix(*, D: float, gamma: float, omega: float) -> NDArray[np.float64]:
    """The matrix M of d/dt (<x**2>, <x Omega>, <Omega**2>) = M (...), white multiplicative noise.

    Model: x'' + gamma x' + (omega**2 + xi) x = 0, <xi xi'> = D delta (package convention). The
    noise multiplies x in dOmega only, so Ito = Stratonovich; in Ito form
    dOmega = (-gamma Omega - omega**2 x) dt - x sqrt(D) dW, and Ito's formula gives

        d<x**2>/dt     = 2 <x Omega>
        d<x Omega>/dt  = <Omega**2> - omega**2 <x**2> - gamma <x Omega>
        d<Omega**2>/dt = -2 omega**2 <x Omega> - 2 gamma <Omega**2> + D <x**2>

    (closed: the equations are exact). M = [[0, 2, 0], [-omega**2, -gamma, 1],
    [D, -2 omega**2, -2 gamma]]. D >= 0, gamma >= 0, omega >= 0.
    """
    D = _nonnegative("D", D, _D)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    w2 = omega * omega
    return np.array([[0.0, 2.0, 0.0], [-w2, -gamma, 1.0], [D, -2.0 * w2, -2.0 * gamma]])


def _largest_real_root(coeffs: list[float]) -> float:
    roots = np.roots(coeffs)
    scale = max(1.0, float(np.max(np.abs(roots))))
    real = roots[np.abs(roots.imag) <= 1e-9 * scale].real
    return float(np.max(real))


def random_frequency_moment_growth_rate(*, D: float, gamma: float, omega: float) -> float:
    """Exponential rate of the second moments (and of <E>) of the damped random-frequency oscillator, white noise.

    The largest eigenvalue of :func:`random_frequency_moment_matrix`. Its characteristic
    polynomial is lambda**3 + 3 gamma lambda**2 + (2 gamma**2 + 4 omega**2) lambda
    + 4 gamma omega**2 - 2 D; with lambda = mu - gamma it becomes
    mu**3 + (4 omega**2 - gamma**2) mu - 2 D (the substitution x = e^{-gamma t/2} y maps the
    damped oscillator to an undamped one of frequency**2 omega**2 - gamma**2/4), whose real root
    mu* is unique for 4 omega**2 > gamma**2 and the largest otherwise, so

        lambda = mu* - gamma.

    The other two roots have real part -gamma - mu*/2 < lambda. Exact for any D >= 0
    (1/time); gamma = 0 gives :func:`stochpend.theory.harmonic_growth_rate` ('white').
    """
    D = _nonnegative("D", D, _D)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    mu = _largest_real_root([1.0, 0.0, 4.0 * omega * omega - gamma * gamma, -2.0 * D])
    return mu - gamma


def random_frequency_threshold(*, gamma: float, omega: float) -> float:
    """Exact threshold D_c = 2 gamma omega**2 above which the second moments grow (white noise).

    Derivation: <E> decays iff every eigenvalue of :func:`random_frequency_moment_matrix` has a
    negative real part. Routh-Hurwitz for lambda**3 + a2 lambda**2 + a1 lambda + a0 with
    a2 = 3 gamma, a1 = 2 gamma**2 + 4 omega**2, a0 = 4 gamma omega**2 - 2 D: a2 > 0 and
    a2 a1 = 6 gamma**3 + 12 gamma omega**2 > a0 always hold for gamma > 0, so stability is
    a0 > 0, D < 2 gamma omega**2 (at D = D_c, lambda = 0 is a root). Package convention
    <xi xi'> = D delta; with <xi xi'> = 2 D' delta it reads D'_c = gamma omega**2. In the
    classical form x'' + 2 zeta omega x' + omega**2 (1 + sigma w) x = 0, <w w'> = delta, it is
    sigma**2 omega < 4 zeta. The typical (almost-sure) threshold is higher:
    :func:`random_frequency_typical_threshold`. gamma >= 0, omega >= 0 (1/time**3).
    """
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    return 2.0 * gamma * omega * omega


def _hierarchy(D: float, tau: float, gamma: float, omega: float, levels: int) -> NDArray[np.float64]:
    w2 = omega * omega
    A0 = np.array([[0.0, 2.0, 0.0], [-w2, -gamma, 1.0], [0.0, -2.0 * w2, -2.0 * gamma]])
    B = np.array([[0.0, 0.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -2.0, 0.0]])
    s = math.sqrt(D / (2.0 * tau))
    n = 3 * (levels + 1)
    M = np.zeros((n, n))
    for k in range(levels + 1):
        i = 3 * k
        M[i : i + 3, i : i + 3] = A0 - (k / tau) * np.eye(3)
        if k < levels:
            M[i : i + 3, i + 3 : i + 6] = s * math.sqrt(k + 1) * B
        if k > 0:
            M[i : i + 3, i - 3 : i] = s * math.sqrt(k) * B
    return M


def _check_levels(levels: Any) -> int:
    if isinstance(levels, bool) or not isinstance(levels, (int, np.integer)) or not 4 <= levels <= 2000:
        _fail("levels", levels, "levels must be an integer in [4, 2000] (Hermite levels of the OU hierarchy)")
    return int(levels)


def random_frequency_ou_growth_rate(
    *, D: float, tau: float, gamma: float, omega: float, levels: int = 64
) -> float:
    """Rate of the second moments of x'' + gamma x' + (omega**2 + xi) x = 0 with OU noise xi (1/time).

    The second moments do NOT close for OU noise: d<x Omega>/dt contains <xi x**2>, whose
    equation contains <xi**2 x**2>, and so on (an infinite hierarchy). Projecting on the
    Hermite polynomials He_k(xi/s), s**2 = D/(2 tau) the stationary variance, which are the
    eigenfunctions of the OU generator (eigenvalue -k/tau), with xi He_k = s (He_{k+1} + k He_{k-1}),
    the vectors N_k = <He_k q>/sqrt(k!), q = (x**2, x Omega, Omega**2), obey

        dN_k/dt = (A0 - k/tau) N_k + s B (sqrt(k+1) N_{k+1} + sqrt(k) N_{k-1})

    with A0 the noiseless moment matrix and B q the xi-part (B = [[0,0,0],[-1,0,0],[0,-2,0]]).
    This block-tridiagonal system is exact; it is truncated at ``levels`` and its largest real
    eigenvalue returned. The truncation converges fast (the diagonal grows like k/tau, the
    coupling like sqrt(k), and B is nilpotent): with gamma = 0.1, omega = 1, 32 and 512 levels
    agree to 1e-9 for D tau**2/2 from 0.25 to 250 (the tests compare 64 with 128 levels); check
    with a larger ``levels`` beyond that. tau -> 0 recovers the white-noise
    rate (:func:`random_frequency_moment_growth_rate`, since (D/2) B**2 adds D <x**2> to
    d<Omega**2>/dt). Numerically exact, not a closed form. D >= 0, tau > 0, gamma >= 0,
    omega >= 0, levels an integer in [4, 2000].
    """
    D = _nonnegative("D", D, _D)
    tau = _positive("tau", tau, _TAU)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    levels = _check_levels(levels)
    return float(np.max(np.linalg.eigvals(_hierarchy(D, tau, gamma, omega, levels)).real))


def random_frequency_ou_threshold(*, tau: float, gamma: float, omega: float, levels: int = 64) -> float:
    """Threshold D_c(tau) of the second moments for OU noise: the root of :func:`random_frequency_ou_growth_rate` = 0.

    Numerically exact (bracketing root find on the truncated hierarchy, relative accuracy
    1e-12). Limits: :func:`random_frequency_ou_threshold_series` (tau -> 0) and
    :func:`random_frequency_ou_threshold_weak_noise` (gamma << omega). tau > 0, gamma > 0,
    omega > 0 (1/time**3).
    """
    from scipy.optimize import brentq

    tau = _positive("tau", tau, _TAU)
    gamma = _positive("gamma", gamma, _GAMMA + "; gamma = 0 has D_c = 0")
    omega = _positive("omega", omega, _OMEGA)
    levels = _check_levels(levels)

    def rate(D: float) -> float:
        return float(np.max(np.linalg.eigvals(_hierarchy(D, tau, gamma, omega, levels)).real))

    lo = 0.0
    hi = 2.0 * gamma * omega * omega
    while rate(hi) < 0:
        lo, hi = hi, 2.0 * hi
        if hi > 1e12 * gamma * omega * omega:
            raise ValueError(f"tau={tau!r} is not accepted: no threshold found below 1e12 gamma omega^2")
    return float(brentq(rate, lo, hi, xtol=1e-14 * hi, rtol=1e-12))


def random_frequency_ou_threshold_series(*, tau: float, gamma: float, omega: float) -> float:
    """Small-tau expansion of the OU threshold: D_c = 2 gamma omega**2 [1 - gamma tau + (2 gamma**2 + 4 omega**2) tau**2] + O(tau**3).

    Derivation (docs/theory.md): eliminating the levels k >= 1 of the hierarchy of
    :func:`random_frequency_ou_growth_rate` at lambda = 0 gives the continued fraction
    A_eff = A0 + s**2 B G_1 B, G_1 = (1/tau - A0 - 2 s**2 B G_2 B)**-1, G_2 = (2/tau - ...)**-1.
    Since B**3 = 0, to second order A_eff = A0 + (D/2)[B**2 + tau B A0 B + tau**2 B A0**2 B]:
    the white-noise term, an effective frequency omega**2 - D tau + D gamma tau**2 and a
    reduced noise. det A_eff = 0 is a_21 a_33 = a_31, i.e.
    D [1 + gamma tau - (gamma**2 + 4 omega**2) tau**2] = 2 gamma omega**2; expanded to
    O(tau**2). Checked against the numerically exact threshold: the tau**2 coefficient
    converges linearly in tau. Validity: gamma tau << 1, omega tau << 1 (the O(tau**3)
    remainder). tau >= 0 (tau = 0: white noise), gamma >= 0, omega >= 0.
    """
    tau = _nonnegative("tau", tau, _TAU)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    return 2.0 * gamma * omega**2 * (1.0 - gamma * tau + (2.0 * gamma**2 + 4.0 * omega**2) * tau**2)


def random_frequency_ou_threshold_weak_noise(*, tau: float, gamma: float, omega: float) -> float:
    """Weak-damping OU threshold: D_c = 2 gamma omega**2 (1 + 4 omega**2 tau**2), any omega tau.

    Energy-diffusion (averaging) result: at weak noise the energy of the harmonic oscillator
    with noise on x grows at the rate S(2 omega)/(2 omega**2) (the parametric resonance at twice
    the frequency; :func:`stochpend.theory.harmonic_growth_rate`), with the OU spectrum
    S(nu) = D/(1 + nu**2 tau**2); friction removes energy at the rate gamma. Equating gives
    D_c. Validity: leading order in gamma/omega, which also requires the noise to be weak: its
    variance at the threshold, D_c/(2 tau) = gamma omega**2 (1 + 4 omega**2 tau**2)/tau, must
    stay << omega**2 (against the hierarchy: 0.7 % off at gamma/omega = 0.01, omega tau = 0.3;
    29 % at omega tau = 3). Agrees with :func:`random_frequency_ou_threshold_series` to O(tau**2) at
    gamma -> 0. tau >= 0, gamma >= 0, omega >= 0.
    """
    tau = _nonnegative("tau", tau, _TAU)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    return 2.0 * gamma * omega**2 * (1.0 + 4.0 * omega**2 * tau**2)


def _lyapunov_undamped(D: float, w2: float) -> float:
    """Top Lyapunov exponent of y'' + (w2 + xi) y = 0, white xi of intensity D > 0, any real w2."""
    from scipy.integrate import quad

    # Exponent g(s) = -(2/D)(w2 s + s**3/12), shifted by its maximum (at s0 = 2 sqrt(-w2) for
    # w2 < 0, else at 0) so that nothing overflows; the integrands are cut into pieces on the
    # scale of the peak (width sqrt(D/s0)) or of the decay from s = 0 (D/(2 w2), (6 D)**(1/3)).
    s0 = 2.0 * math.sqrt(-w2) if w2 < 0 else 0.0
    lin = max(w2, 0.0)  # w2 + s0**2/4, exactly 0 for w2 < 0

    def expo(s: float) -> float:  # g(s) - g(s0) in powers of d = s - s0, free of cancellation
        d = s - s0
        return -(2.0 / D) * (d * lin + d * d * (0.25 * s0 + d / 12.0))

    if s0 > 0:
        width = min(math.sqrt(D / s0), s0)
    else:
        width = min(D / (2.0 * w2) if w2 > 0 else math.inf, (6.0 * D) ** (1.0 / 3.0))
    edges = {s0}
    for k in (0.5, 1.0, 2.0, 4.0, 8.0, 16.0):
        edges.add(s0 + k * width)
        if s0 - k * width > 0:
            edges.add(s0 - k * width)
    s_max = s0 + 16.0 * width
    while expo(s_max) > -100.0:
        s_max = s0 + 2.0 * (s_max - s0)
        edges.add(s_max)
    cuts = sorted(e for e in edges | {0.0} if 0.0 <= e <= s_max)
    # absolute tolerances: 1e-13 of the size of each integral (peak value times width)
    peak = max(s0, width)
    tol_num = 1e-13 * math.sqrt(peak) * width
    tol_den = 1e-13 * width / math.sqrt(peak)
    num = den = 0.0
    for a, b in zip(cuts[:-1], cuts[1:], strict=True):
        num += quad(lambda s: math.sqrt(s) * math.exp(expo(s)), a, b, limit=200, epsabs=tol_num, epsrel=1e-9)[0]
        # s**(-1/2): s = u**2 removes the endpoint singularity at 0
        den += quad(lambda u: 2.0 * math.exp(expo(u * u)), math.sqrt(a), math.sqrt(b), limit=200, epsabs=tol_den,
                    epsrel=1e-9)[0]
    return 0.5 * num / den


def random_frequency_lyapunov(*, D: float, gamma: float, omega: float) -> float:
    """Top Lyapunov exponent lambda of x'' + gamma x' + (omega**2 + xi) x = 0, white xi (1/time).

    lambda = lim ln|x(t)|/t almost surely; <ln E>/t -> 2 lambda ("typical" growth, as opposed to
    the mean-square rate :func:`random_frequency_moment_growth_rate`).

    Derivation: x = e^{-gamma t/2} y removes the damping exactly, y'' + (w1**2 + xi) y = 0 with
    w1**2 = omega**2 - gamma**2/4, so lambda = lambda_y - gamma/2. The Riccati variable
    z = y'/y obeys dz = -(w1**2 + z**2) dt - sqrt(D) dW, whose stationary law carries a constant
    flux (z -> -inf is re-injected at +inf); lambda_y = <z>. Writing the stationary density as
    P(z) ~ int_0^inf exp(Phi(z - s) - Phi(z)) ds, Phi = (2/D)(w1**2 z + z**3/3), and doing the
    (Gaussian) z integral first gives

        lambda_y = (1/2) int_0^inf s**(1/2) e^{-(2/D)(w1**2 s + s**3/12)} ds
                   / int_0^inf s**(-1/2) e^{-(2/D)(w1**2 s + s**3/12)} ds

    (the Rice/Riccati method of the random oscillator, e.g. Lifshits, Gredeskul & Pastur,
    Introduction to the theory of disordered systems, 1988). Limits: D << w1**3 gives
    D/(8 w1**2) (:func:`random_frequency_lyapunov_small_noise`); w1 = 0 gives
    (sqrt(pi)/(2 Gamma(1/6))) (6 D)**(1/3). Evaluated by quadrature (relative accuracy ~1e-10).
    D > 0, gamma >= 0, omega >= 0 (any sign of w1**2).
    """
    D = _positive("D", D, _D)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _nonnegative("omega", omega, _OMEGA)
    return _lyapunov_undamped(D, omega * omega - 0.25 * gamma * gamma) - 0.5 * gamma


def random_frequency_lyapunov_small_noise(*, D: float, gamma: float, omega: float) -> float:
    """Small-noise Lyapunov exponent: lambda = D/(8 (omega**2 - gamma**2/4)) - gamma/2 (1/time).

    Leading order in D/w1**3, w1**2 = omega**2 - gamma**2/4 > 0 (underdamped). Derivation:
    averaging (the energy of y obeys dE = A dt + sqrt(B) dW with B = D E**2/(2 w1**2),
    A = D E/(2 w1**2); Ito: d<ln E>/dt = A/E - B/(2 E**2) = D/(4 w1**2), and ln|y| ~ ln E/2), or
    the Laplace limit of :func:`random_frequency_lyapunov`. The same D/(8 omega**2) (sigma**2/(8
    omega**2) for unit-intensity noise) is the small-noise result of Arnold, Papanicolaou &
    Wihstutz (1986). D >= 0, gamma >= 0, omega > gamma/2.
    """
    D = _nonnegative("D", D, _D)
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _positive("omega", omega, _OMEGA + " > gamma/2 (underdamped)")
    w1sq = omega * omega - 0.25 * gamma * gamma
    if w1sq <= 0:
        _fail("omega", omega, f"omega must be > gamma/2 = {gamma / 2!r} (underdamped) for the small-noise law")
    return D / (8.0 * w1sq) - 0.5 * gamma


def random_frequency_typical_threshold(*, gamma: float, omega: float) -> float:
    """Noise intensity at which the Lyapunov exponent vanishes (typical, almost-sure threshold; 1/time**3).

    The root in D of :func:`random_frequency_lyapunov` = 0 (numerically exact, relative accuracy
    1e-10). Always above the mean-square threshold 2 gamma omega**2; at small gamma/omega it is
    4 gamma (omega**2 - gamma**2/4) (:func:`random_frequency_typical_threshold_small_noise`).
    gamma > 0, omega > 0.
    """
    from scipy.optimize import brentq

    gamma = _positive("gamma", gamma, _GAMMA + "; gamma = 0 has threshold 0")
    omega = _positive("omega", omega, _OMEGA + "; omega = 0 has threshold 0")
    w1sq = omega * omega - 0.25 * gamma * gamma

    def lam(D: float) -> float:
        return _lyapunov_undamped(D, w1sq) - 0.5 * gamma

    hi = max(4.0 * gamma * abs(w1sq), gamma**3)
    while lam(hi) < 0:
        hi *= 2.0
    lo = hi / 2.0
    while lam(lo) > 0:
        lo /= 2.0
    return float(brentq(lam, lo, hi, rtol=1e-12))


def random_frequency_typical_threshold_small_noise(*, gamma: float, omega: float) -> float:
    """Leading-order typical threshold: D_typ = 4 gamma (omega**2 - gamma**2/4), twice the mean-square one at gamma << omega.

    From :func:`random_frequency_lyapunov_small_noise` = 0. Validity: gamma/omega << 1 (then
    D_typ << omega**3 and the small-noise law holds). gamma >= 0, omega > gamma/2.
    """
    gamma = _nonnegative("gamma", gamma, _GAMMA)
    omega = _positive("omega", omega, _OMEGA)
    w1sq = omega * omega - 0.25 * gamma * gamma
    if w1sq <= 0:
        _fail("omega", omega, f"omega must be > gamma/2 = {gamma / 2!r} (underdamped) for the small-noise law")
    return 4.0 * gamma * w1sq


# ---------------------------------------------------------------------------------------------
# The table (``stochpend theory --family``)
# ---------------------------------------------------------------------------------------------

FAMILY_NOISES = ("white", "ou")


def family_predictions(
    *,
    noise: str = "white",
    D_a: float,
    gamma: float,
    omega: float = 1.0,
    D: float = 0.0,
    tau: float | None = None,
    F: float = 0.0,
) -> list[Prediction]:
    """The family's laws as table rows (the paper's :class:`stochpend.theory.Prediction`).

    Parameters
    ----------
    noise : {"white", "ou"}
        ``"white"``: the additive noise xi_a and the multiplicative noise xi are white
        (Boltzmann, Kramers, washboard and random-frequency rows); ``"ou"``: both are OU with
        correlation time ``tau`` (the harmonic oscillator with additive OU noise and the
        random-frequency oscillator with OU noise).
    D_a : float
        Additive noise intensity, > 0 (<xi_a xi_a'> = D_a delta; OU: S(0) = D_a).
    gamma : float
        Damping, > 0.
    omega : float
        Oscillator frequency, > 0.
    D : float
        Multiplicative noise intensity of the random-frequency rows, >= 0.
    tau : float, optional
        OU correlation time, > 0; required for ``noise="ou"``, ignored for white noise.
    F : float
        Constant torque of the washboard rows (any finite number).

    Returns
    -------
    list of Prediction
        One row per law with its regime, value, reference, validity and note. The laws are
        stationary values or rates: no time enters.
    """
    if not isinstance(noise, str) or noise.lower() not in FAMILY_NOISES:
        _fail("noise", noise, f"one of {', '.join(FAMILY_NOISES)}")
    noise = noise.lower()
    D_a = _positive("D_a", D_a, _DA)
    gamma = _positive("gamma", gamma, _GAMMA)
    omega = _positive("omega", omega, _OMEGA + "; the family table needs a well")
    D = _nonnegative("D", D, _D)
    F = _finite("F", F, "the constant torque")
    if noise == "ou":
        tau = _positive("tau", tau, _TAU)
        return _family_ou_rows(D_a=D_a, tau=tau, gamma=gamma, omega=omega, D=D)

    T = temperature(D_a=D_a, gamma=gamma)
    return (_boltzmann_rows(D_a=D_a, gamma=gamma, omega=omega)
            + _kramers_rows(D_a=D_a, gamma=gamma, omega=omega, T=T)
            + _washboard_rows(D_a=D_a, gamma=gamma, omega=omega, F=F)
            + _random_frequency_rows(D=D, gamma=gamma, omega=omega))


def _family_ou_rows(*, D_a: float, tau: float, gamma: float, omega: float, D: float) -> list[Prediction]:
    """OU noise: the harmonic oscillator with additive OU noise and the random-frequency
    oscillator with OU noise."""
    rows: list[Prediction] = []
    P = Prediction
    v = harmonic_ou_additive_variances(D_a=D_a, tau=tau, gamma=gamma, omega=omega)
    reg = "harmonic, additive OU noise, stationary"
    ref = "Lyapunov eq. (family.py)"
    valid = "t >> 1/gamma, tau; D = F = 0"
    N = "N = 1 + gamma tau + omega^2 tau^2"
    rows += [
        P(reg, "<x^2>", v.mean_x2, ref, valid, f"D_a (1 + gamma tau)/(2 gamma omega^2 N), {N}"),
        P(reg, "<x Omega>", v.mean_xOmega, ref, valid, "0 (stationarity)"),
        P(reg, "<Omega^2>", v.mean_Omega2, ref, valid, "D_a/(2 gamma N); tau -> 0: T"),
        P(reg, "<E>", harmonic_ou_additive_mean_E(D_a=D_a, tau=tau, gamma=gamma, omega=omega), ref, valid,
          "D_a (2 + gamma tau)/(4 gamma N)"),
    ]
    reg = "random frequency, OU noise D on x"
    valid = "F = D_a = 0; any D, tau"
    rows += [
        P(reg, "lambda_2", random_frequency_ou_growth_rate(D=D, tau=tau, gamma=gamma, omega=omega),
          "Hermite hierarchy (family.py)", valid,
          "rate of <E>; second moments do not close; numerically exact (64 levels)"),
        P(reg, "D_c", random_frequency_ou_threshold(tau=tau, gamma=gamma, omega=omega),
          "Hermite hierarchy (family.py)", valid, "<E> decays iff D < D_c"),
        P(reg, "D_c", random_frequency_ou_threshold_series(tau=tau, gamma=gamma, omega=omega),
          "small-tau series", "gamma tau, omega tau << 1",
          "2 gamma omega^2 [1 - gamma tau + (2 gamma^2 + 4 omega^2) tau^2] + O(tau^3)"),
        P(reg, "D_c", random_frequency_ou_threshold_weak_noise(tau=tau, gamma=gamma, omega=omega),
          "energy averaging", "gamma << omega, D_c/tau << omega^2",
          "2 gamma omega^2 (1 + 4 omega^2 tau^2)"),
        P(reg, "lambda", math.nan, "none", "-",
          "Lyapunov exponent for OU noise: not derived; measured only"),
    ]
    return rows



def _boltzmann_rows(*, D_a: float, gamma: float, omega: float) -> list[Prediction]:
    """Boltzmann's stationary law under additive white noise."""
    rows: list[Prediction] = []
    P = Prediction
    T = temperature(D_a=D_a, gamma=gamma)
    reg = "Boltzmann, additive white noise"
    ref = "FPE stationary law"
    valid = "D = F = 0, t >> 1/gamma"
    rows += [
        P(reg, "T", T, ref, valid, "D_a/(2 gamma): <xi_a xi_a'> = D_a delta"),
        P(reg, "<Omega^2>", boltzmann_mean_Omega2(D_a=D_a, gamma=gamma), ref, valid, "T, any potential"),
        P(reg, "<cos x>", boltzmann_pendulum_mean_cos(D_a=D_a, gamma=gamma, omega=omega), ref, valid,
          "pendulum: I1/I0(omega^2/T)"),
        P(reg, "<cos^2 x>", boltzmann_pendulum_mean_cos2(D_a=D_a, gamma=gamma, omega=omega), ref, valid,
          "pendulum: 1/2 + I2/(2 I0)"),
        P(reg, "<E>", boltzmann_pendulum_mean_E(D_a=D_a, gamma=gamma, omega=omega), ref, valid,
          "pendulum: T/2 - omega^2 <cos x>"),
        P(reg, "<x^2>", boltzmann_harmonic_mean_x2(D_a=D_a, gamma=gamma, omega=omega), ref, valid,
          "harmonic: T/omega^2"),
        P(reg, "<E>", boltzmann_harmonic_mean_E(D_a=D_a, gamma=gamma, omega=omega), ref, valid, "harmonic: T"),
    ]

    return rows


def _kramers_rows(*, D_a: float, gamma: float, omega: float, T: float) -> list[Prediction]:
    """The pendulum's escape rates over its barrier (Kramers, Mel'nikov-Meshkov, Lifson-Jackson)."""
    rows: list[Prediction] = []
    P = Prediction
    barrier = pendulum_barrier(omega=omega) / T
    delta = pendulum_energy_loss(D_a=D_a, gamma=gamma, omega=omega)
    regime = kramers_regime(D_a=D_a, gamma=gamma, omega=omega)
    low = f"outside validity: Delta U/T = {barrier:.3g} < {KRAMERS_MIN_BARRIER:g}; " if barrier < KRAMERS_MIN_BARRIER else ""
    reg = "Kramers, pendulum, additive white noise"
    rows += [
        P(reg, "Delta U/T", barrier, "Delta U = 2 omega^2", "-", f"{low}valid for >= {KRAMERS_MIN_BARRIER:g}"),
        P(reg, "Delta", delta, "HTB (1990) sec. IV", "-", f"8 gamma omega/T: loss per branch; regime: {regime}"),
        P(reg, "k", kramers_rate_spatial_diffusion(D_a=D_a, gamma=gamma, omega=omega), "Kramers (1940)",
          "Delta U/T >= 5, Delta > 5", f"{low}spatial diffusion, one barrier"),
        P(reg, "k", kramers_rate_energy_diffusion(D_a=D_a, gamma=gamma, omega=omega), "Kramers (1940)",
          "Delta U/T >= 5, Delta < 0.01", f"{low}energy diffusion, one barrier"),
        P(reg, "k", kramers_rate_energy_diffusion_mfpt(D_a=D_a, gamma=gamma, omega=omega),
          "energy-diffusion MFPT", "Delta < 0.01", "one barrier; no 2 T/Delta U error of the line above"),
        P(reg, "D_eff", smoluchowski_effective_diffusion(D_a=D_a, gamma=gamma, omega=omega),
          "Lifson-Jackson (1962)", "gamma >> omega, any T", "exact overdamped; hop rate D_eff/(2 pi)^2"),
        P(reg, "k", kramers_rate_melnikov_meshkov(D_a=D_a, gamma=gamma, omega=omega),
          "Mel'nikov-Meshkov (1986)", "Delta U/T >= 5", f"{low}A(Delta) k_spatial; turnover error not established"),
        P(reg, "2k", pendulum_slip_rate(D_a=D_a, gamma=gamma, omega=omega), "both barriers",
          "Delta U/T >= 5", f"{low}escape rate from a well, {regime} formula"),
    ]

    return rows


def _washboard_rows(*, D_a: float, gamma: float, omega: float, F: float) -> list[Prediction]:
    """The tilted washboard under a constant torque F."""
    rows: list[Prediction] = []
    P = Prediction
    reg = "tilted washboard (torque F)"
    rows += [
        P(reg, "<Omega>", running_velocity(F=F, gamma=gamma), "force balance", "F >> omega^2; running, low noise",
          "F/gamma; locked state (noiseless) for |F| <= omega^2"),
        P(reg, "F_lock", locking_torque(omega=omega), "fixed points", "noiseless", "omega^2"),
        P(reg, "F_r", retrapping_torque(gamma=gamma, omega=omega), "energy balance", "noiseless, gamma << omega",
          "(4/pi) gamma omega: running exists for F > F_r"),
        P(reg, "<Omega>", free_particle_drift(F=F, gamma=gamma), "exact", "omega = 0, any noise", "F/gamma"),
        P(reg, "D_eff", free_particle_diffusion(D_a=D_a, gamma=gamma), "Einstein relation", "omega = 0",
          "T/gamma = D_a/(2 gamma^2)"),
    ]

    return rows


def _random_frequency_rows(*, D: float, gamma: float, omega: float) -> list[Prediction]:
    """The random-frequency oscillator with white noise D on x: thresholds and rates."""
    rows: list[Prediction] = []
    P = Prediction
    reg = "random frequency, white noise D on x"
    valid = "F = D_a = 0; any D"
    rows += [
        P(reg, "D_c", random_frequency_threshold(gamma=gamma, omega=omega), "closed 2nd moments", valid,
          "2 gamma omega^2: <E> decays iff D < D_c (Ito = Stratonovich)"),
        P(reg, "lambda_2", random_frequency_moment_growth_rate(D=D, gamma=gamma, omega=omega),
          "closed 2nd moments", valid, "rate of <E>: mu - gamma, mu^3 + (4 omega^2 - gamma^2) mu = 2 D"),
    ]
    if D > 0:
        lam = random_frequency_lyapunov(D=D, gamma=gamma, omega=omega)
        rows.append(P(reg, "lambda", lam, "Riccati quadrature", valid, "ln|x|/t; <ln E>/t -> 2 lambda"))
        if 4.0 * omega * omega > gamma * gamma:
            rows.append(P(reg, "lambda", random_frequency_lyapunov_small_noise(D=D, gamma=gamma, omega=omega),
                          "APW (1986)", "D << (omega^2 - gamma^2/4)^(3/2)", "D/(8 (omega^2 - gamma^2/4)) - gamma/2"))
    rows.append(P(reg, "D_typ", random_frequency_typical_threshold(gamma=gamma, omega=omega), "Riccati quadrature",
                  valid, "lambda = 0: typical (a.s.) threshold > D_c"))
    if gamma < 2.0 * omega:
        rows.append(P(reg, "D_typ", random_frequency_typical_threshold_small_noise(gamma=gamma, omega=omega),
                      "APW (1986)", "gamma << omega", "4 gamma (omega^2 - gamma^2/4)"))
    return rows
