r"""Long-time growth laws of the mean energy: <E> ~ t**nu, exponential, or finite-time blow-up.

The oscillator is dx/dt = Omega, dOmega/dt = -omega**2 U'(x) - xi(t) G(x) (see
:mod:`stochpend.oscillators`). The noise enters as a Hamiltonian perturbation xi(t) V(x) with
V' = G: V = U for ``coupling="force"``, V = x**2/2 for ``coupling="position"``. Averaging
over the fast angle of the orbit of energy E gives an energy diffusion (derived, with every
case, in ``docs/scaling.md``)

    dE = A(E) dt + sqrt(B(E)) dW,
    B(E) = sum_k S(k nu(E)) |g_k(E)|**2,     A(E) = (1/(2 T)) d(T B)/dE,

where nu = 2 pi / T is the orbit frequency, g_k the Fourier coefficients of G(x) Omega along
the orbit, and S the noise spectrum (S(0) = D for every noise here). When, at large E,
B ~ E**beta and T ~ E**(-mu), the Lamperti variable Y ~ E**q, q = (2 - beta)/2, is a Bessel
process of dimension delta = (1 - mu)/q. So

* beta < 2: <E> ~ t**(1/(2 - beta)) (power law);
* beta = 2: log E is a drifted Brownian motion, <E> grows exponentially;
* beta > 2: E = infinity is Y = 0, which a Bessel process of dimension < 2 reaches in
  finite time (Feller): finite-time blow-up.

With S(nu) ~ nu**(-alpha) at high frequency (white 0, OU and dichotomous 2, harmonic noise 4)
this gives the table of :func:`predicted_exponent`. The pendulum's white and OU results are
the paper's (Eqs. `eq:scalEblanc`, `eq:scalEcolor`); the rest are derived in
``docs/scaling.md`` and checked there against short simulations.
"""

from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction

import numpy as np
from numpy.typing import ArrayLike, NDArray

from stochpend.text._docs import documented
from stochpend.theory.laws import _check_D, _check_tau, _fail, _scalar

__all__ = [
    "COUPLINGS",
    "GROWTHS",
    "NOISES",
    "POTENTIALS",
    "SPECTRUM_DECAY",
    "ScalingPrediction",
    "harmonic_growth_rate",
    "predicted_exponent",
    "quartic_position_heating_rate",
    "spectral_density",
]

POTENTIALS = ("pendulum", "harmonic", "power")
NOISES = ("white", "ou", "dichotomous", "harmonic")
COUPLINGS = ("force", "position")
GROWTHS = ("power", "exponential", "finite-time blow-up", "unknown")

#: alpha in S(nu) ~ nu**(-alpha) at nu -> infinity: the only property of the noise that sets
#: a power-law exponent (the orbit frequency of a growing energy runs to high frequencies).
SPECTRUM_DECAY = {"white": 0, "ou": 2, "dichotomous": 2, "harmonic": 4}

_PAPER = "Mallick & Marcq (2004)"
_HERE = "derived in docs/scaling.md"


@dataclass(frozen=True)
class ScalingPrediction:
    """The predicted long-time growth of <E>.

    Attributes
    ----------
    exponent : float or None
        nu in <E> ~ t**nu; None unless ``growth == "power"``.
    growth : str
        ``"power"``, ``"exponential"``, ``"finite-time blow-up"`` or ``"unknown"``.
    regime : str
        Where the law holds (time window, approximations) and, for the other growths, the
        rate or the transient law; one line.
    source : str
        The paper's equation label, or ``"derived in docs/scaling.md"``.
    """

    exponent: float | None
    growth: str
    regime: str
    source: str


def _bessel(beta: float, mu: float) -> tuple[float, float]:
    """(q, delta): Y ~ E**q is a Bessel process of dimension delta (docs/scaling.md, sec. 1)."""
    q = (2.0 - beta) / 2.0
    return q, (1.0 - mu) / q


def _fmt(x: float) -> str:
    """A short exact-looking form of a rational exponent, e.g. 0.5 -> '1/2'."""
    f = Fraction(x).limit_denominator(64)
    return str(f.numerator) if f.denominator == 1 else f"{f.numerator}/{f.denominator}"


@documented  # help() shows the signature's defaults and the paper's equation numbers
def predicted_exponent(
    potential: str, noise: str, coupling: str = "force", power_n: int = 2
) -> ScalingPrediction:
    r"""The long-time law of <E(t)> for one (oscillator, coupling, noise).

    Parameters
    ----------
    potential : {"pendulum", "harmonic", "power"}
        U = -cos x, x**2/2 or x**(2n)/(2n) (``power`` with ``power_n = 1`` is the harmonic one).
    noise : {"white", "ou", "dichotomous", "harmonic"}
        All with the same integrated intensity, S(0) = D.
    coupling : {"force", "position"}
        G = U'(x) (the paper's pendulum) or G = x (random-frequency oscillator). For the
        harmonic potential the two coincide; the pendulum is defined with force coupling only.
    power_n : int
        n >= 1 for ``potential="power"`` (ignored otherwise).

    Returns
    -------
    ScalingPrediction
        exponent nu of <E> ~ t**nu (None unless the growth is a power law), growth, regime,
        source. Power laws: pendulum (rotor) 2/(2 + alpha); power potential, position
        coupling, 2n/((n - 1)(2 + alpha)), alpha the high-frequency decay of the spectrum.

    Raises
    ------
    ValueError
        One line naming the argument, for an unknown name or a refused combination.

    References
    ----------
    Mallick & Marcq (2004), Eqs. `eq:scalEblanc` (white: <E> = D t/4), `eq:scalEcolor`
    (OU: <E> ~ (D t/tau**2)**(1/2)), `defalpha` (the scaling argument, made with dichotomous
    noise). Every other entry: ``docs/scaling.md``.
    """
    if potential not in POTENTIALS:
        _fail("potential", potential, f"one of {', '.join(POTENTIALS)}")
    if noise not in NOISES:
        _fail("noise", noise, f"one of {', '.join(NOISES)}")
    if coupling not in COUPLINGS:
        _fail("coupling", coupling, f"one of {', '.join(COUPLINGS)}")
    if isinstance(power_n, bool) or not isinstance(power_n, (int, np.integer)) or power_n < 1:
        _fail("power_n", power_n, "power_n must be an integer >= 1 (U = x^(2n)/(2n))")
    if potential == "pendulum" and coupling == "position":
        _fail("coupling", coupling, "the pendulum is defined with its force coupling only (coupling='force')")
    alpha = SPECTRUM_DECAY[noise]
    if potential == "pendulum":
        return _pendulum(noise, alpha)
    if potential == "harmonic" or power_n == 1:
        return _harmonic(noise)
    n = int(power_n)
    if coupling == "position":
        return _power_position(noise, alpha, n)
    return _power_force(noise, alpha, n)


def _pendulum(noise: str, alpha: int) -> ScalingPrediction:
    # Rotor: nu(E) = Omega ~ E^(1/2), V = -cos x bounded: B ~ S(Omega) Omega^2 ~ E^(1 - alpha/2).
    beta, mu = 1.0 - alpha / 2.0, 0.5
    q, delta = _bessel(beta, mu)
    nu = 1.0 / (2.0 - beta)  # = 2/(2 + alpha)
    lam = f"Bessel dimension {_fmt(delta)} in Y ~ E^({_fmt(q)})"
    if noise == "white":
        return ScalingPrediction(
            nu, "power", f"rotor, t >> omega^2/D: <E> = D t/4 exactly in the limit ({lam})",
            f"{_PAPER}, Eq. eq:scalEblanc",
        )
    if noise == "ou":
        return ScalingPrediction(
            nu, "power",
            f"rotor, t >> t_c ~ 1/(D tau^2) (tpcross): <E> = Gamma(3/4)/Gamma(1/4) (D t/tau^2)^(1/2) ({lam})",
            f"{_PAPER}, Eqs. eq:scalEcolor, average2eta",
        )
    if noise == "dichotomous":
        return ScalingPrediction(
            nu, "power",
            f"rotor, t >> t_c ~ 1/(D tau^2): same spectrum as OU, B = D/(2 tau^2) ({lam})",
            f"{_PAPER}, scaling argument Eq. defalpha (dichotomous noise); {_HERE}",
        )
    return ScalingPrediction(
        nu, "power",
        f"rotor with Omega >> W (t >> W^2/D, W = omega_noise): S ~ D W^4/nu^4, B = D W^4/(4E) ({lam})",
        _HERE,
    )


def _harmonic(noise: str) -> ScalingPrediction:
    if noise == "white":
        regime = (
            "t >> 1/lambda: <E> ~ exp(lambda t), lambda the real root of "
            "lambda^3 + 4 omega^2 lambda = 2 D (exact second moments; ~ D/(2 omega^2) for D << omega^3)"
        )
    else:
        regime = (
            "weak noise (rate << omega): <E> ~ exp(lambda t), lambda = S(2 omega)/(2 omega^2) "
            "(parametric resonance at twice the frequency); see harmonic_growth_rate"
        )
    return ScalingPrediction(None, "exponential", regime, _HERE)


def _power_position(noise: str, alpha: int, n: int) -> ScalingPrediction:
    # nu(E) ~ E^((n-1)/(2n)), V = x^2/2 ~ E^(1/n): B ~ nu^(2 - alpha) V^2.
    mu = (n - 1) / (2.0 * n)
    beta = (2.0 - alpha) * mu + 2.0 / n
    q, delta = _bessel(beta, mu)
    nu = 1.0 / (2.0 - beta)  # = 2n/((n - 1)(2 + alpha))
    lam = f"Bessel dimension {_fmt(delta)} in Y ~ E^({_fmt(q)})"
    if noise == "white":
        window = "once <E> >> its initial value (d<E>/dt = (D/2)<x^2> exactly)"
    elif noise == "harmonic":
        window = "once the orbit frequency nu(E) >> W = omega_noise (white-noise law t^(n/(n-1)) before)"
    else:
        window = "once the orbit frequency nu(E) >> 1/tau, t >> ~1/(D tau^2) (white-noise law t^(n/(n-1)) before)"
    return ScalingPrediction(nu, "power", f"{window} ({lam})", _HERE)


def _power_force(noise: str, alpha: int, n: int) -> ScalingPrediction:
    # nu(E) ~ E^((n-1)/(2n)), V = U ~ E: beta = 2 + (2 - alpha)(n - 1)/(2n).
    mu = (n - 1) / (2.0 * n)
    beta = 2.0 + (2.0 - alpha) * mu
    if noise == "white":
        q, delta = _bessel(beta, mu)
        return ScalingPrediction(
            None, "finite-time blow-up",
            f"every D > 0: Y ~ E^({_fmt(q)}) is a Bessel process of dimension {_fmt(delta)} < 2 and "
            "reaches 0 (E = infinity) in finite time; d<E>/dt = (D/2)<x^(4n-2)> is superlinear",
            _HERE,
        )
    inversion = (
        "Gaussian xi drops below -omega^2 at a positive rate and the inverted potential "
        "(omega^2 + xi) x^(2n)/(2n) throws the path to infinity in a finite time"
    )
    if noise == "harmonic":
        transient = 2.0 * n / ((n - 1) * (alpha - 2.0))
        return ScalingPrediction(
            None, "finite-time blow-up",
            f"{inversion}; before that the averaged law is <E> ~ t^({_fmt(transient)})",
            _HERE,
        )
    if noise == "ou":
        return ScalingPrediction(
            None, "finite-time blow-up",
            f"{inversion}; before that the averaged law is exponential, "
            "rate D/(9 tau^2 omega^4) for n = 2 (B = (D/tau^2) Var_E(U))",
            _HERE,
        )
    # Dichotomous, bounded: the potential stays confining iff a = sqrt(D/(2 tau)) < omega^2.
    return ScalingPrediction(
        None, "exponential",
        "a = sqrt(D/(2 tau)) < omega^2 (potential never inverted), nu(E) tau >> 1: "
        "<E> ~ exp(lambda t), lambda = D/(9 tau^2 omega^4) for n = 2 and weak noise; "
        "a > omega^2: finite-time blow-up",
        _HERE,
    )


def spectral_density(
    noise: str,
    nu: ArrayLike,
    *,
    D: float,
    tau: float | None = None,
    omega_noise: float | None = None,
) -> NDArray[np.float64] | float:
    r"""The noise spectrum S(nu) = int <xi(0) xi(t)> e^{i nu t} dt, normalised to S(0) = D.

    * white: S = D;
    * ou and dichotomous (same correlation D/(2 tau) e^{-|t|/tau}): S = D/(1 + nu^2 tau^2);
    * harmonic: S = D W^4/((W^2 - nu^2)^2 + gamma^2 nu^2), W = ``omega_noise`` (default
      2/tau, critical damping), gamma = W^2 tau.

    Parameters
    ----------
    noise : {"white", "ou", "dichotomous", "harmonic"}
    nu : array_like
        Angular frequency, 1/time.
    D : float
        Integrated intensity S(0), >= 0.
    tau : float, optional
        Correlation time > 0 (colored noises).
    omega_noise : float, optional
        W > 0 of the harmonic noise.

    Returns
    -------
    ndarray or float
        S(nu), same shape as ``nu``, units of D.
    """
    if noise not in NOISES:
        _fail("noise", noise, f"one of {', '.join(NOISES)}")
    D = _check_D(D)
    nu_a = np.asarray(nu, dtype=float)
    if noise == "white":
        out = np.full_like(nu_a, D)
    else:
        tau = _check_tau(tau)
        if noise in ("ou", "dichotomous"):
            out = D / (1.0 + (nu_a * tau) ** 2)
        else:
            W = 2.0 / tau if omega_noise is None else _scalar(
                "omega_noise", omega_noise, "omega_noise must be a finite number > 0 (W of the harmonic noise)"
            )
            if W <= 0:
                _fail("omega_noise", omega_noise, "omega_noise must be a finite number > 0 (W of the harmonic noise)")
            gamma = W * W * tau
            out = D * W**4 / ((W * W - nu_a**2) ** 2 + (gamma * nu_a) ** 2)
    return float(out) if out.ndim == 0 else out


def harmonic_growth_rate(
    noise: str,
    *,
    D: float,
    omega: float,
    tau: float | None = None,
    omega_noise: float | None = None,
) -> float:
    r"""lambda in <E> ~ e^{lambda t} for the harmonic oscillator U = x^2/2 (either coupling).

    * white: the real root of lambda^3 + 4 omega^2 lambda - 2 D = 0, the growing eigenvalue
      of the closed second-moment system d<x^2>/dt = 2<x Omega>, d<x Omega>/dt =
      <Omega^2> - omega^2 <x^2>, d<Omega^2>/dt = -2 omega^2 <x Omega> + D <x^2>
      (exact; ~ D/(2 omega^2) for D << omega^3; (2 D)^(1/3) at omega = 0);
    * colored: lambda = S(2 omega)/(2 omega^2), the energy-diffusion result at leading order
      in the noise (valid for lambda << omega; needs omega > 0).

    Returns
    -------
    float
        The rate, 1/time.
    """
    if noise not in NOISES:
        _fail("noise", noise, f"one of {', '.join(NOISES)}")
    D = _check_D(D)
    msg = "omega must be a finite number >= 0 (the oscillator frequency)"
    w = _scalar("omega", omega, msg)
    if w < 0:
        _fail("omega", omega, msg)
    if noise == "white":
        roots = np.roots([1.0, 0.0, 4.0 * w * w, -2.0 * D])
        real = roots[np.abs(roots.imag) <= 1e-9 * max(1.0, float(np.max(np.abs(roots))))].real
        return float(np.max(real))
    if w == 0:
        _fail("omega", omega, "omega must be > 0 for a colored noise (the rate S(2 omega)/(2 omega^2) needs an orbit)")
    return float(spectral_density(noise, 2.0 * w, D=D, tau=tau, omega_noise=omega_noise)) / (2.0 * w * w)



def quartic_position_heating_rate(noise: str, *, D: float, tau: float, omega: float) -> float:
    r"""d<E>/dt of the quartic U = x^4/4 with the noise on x, for OU or dichotomous noise.

    Averaging (docs/scaling.md, sec. 8): once the orbit frequency nu(E) >> 1/tau,
    B(E) = (D/tau^2) Var_E(x^2/2) = (D/tau^2) (E/omega^2) V_1 and T ~ E^(-1/4), so
    A = (1/(2T)) d(T B)/dE = (3/8) (D/tau^2) V_1/omega^2 is constant: <E> grows linearly (the
    exponent 1 is reached only when t >> <E(0)>/A). V_1 = Var(x^2/2) over the orbit of energy 1
    of x^4/4 (time average), computed here by quadrature: 0.124533..., so A = 0.046700 D/(tau^2
    omega^2).

    Returns
    -------
    float
        A, energy per unit time.
    """
    from scipy.integrate import quad

    if noise not in ("ou", "dichotomous"):
        _fail("noise", noise, "'ou' or 'dichotomous' (the law is derived for a Lorentzian spectrum)")
    D = _check_D(D)
    tau = _check_tau(tau)
    msg = "omega must be a finite number > 0 (the oscillator frequency)"
    w = _scalar("omega", omega, msg)
    if w <= 0:
        _fail("omega", omega, msg)
    x_max = 2.0**0.5  # x^4/4 = 1

    def weight(x: float) -> float:  # dt = dx/|Omega| on the orbit of energy 1
        return 1.0 / np.sqrt(2.0 * (1.0 - x**4 / 4.0))

    z = quad(weight, 0.0, x_max)[0]
    m2 = quad(lambda x: x * x * weight(x), 0.0, x_max)[0] / z
    m4 = quad(lambda x: x**4 * weight(x), 0.0, x_max)[0] / z
    v1 = m4 / 4.0 - m2 * m2 / 4.0
    return 0.375 * D / tau**2 * v1 / (w * w)
