"""Closed-form results of Mallick & Marcq (2004), one function per equation.

Every function cites the paper's equation label (the ``\\label`` in the LaTeX source,
``/work/shared/paper/mallick-marcq-2004-stochastic-pendulum.tex``). Conventions:

* ``D`` is the noise amplitude, ``<xi(t) xi(t')> = D delta(t - t')`` for white noise
  (``defbruitblanc``) and the amplitude of the white noise driving the OU process for coloured
  noise (``eqOU``), so that ``<xi(t) xi(t')> = D/(2 tau) exp(-|t - t'|/tau)``
  (``correlationOU``). Units: ``Omega`` is 1/time, ``xi`` is 1/time^2, so ``D`` is 1/time^3,
  ``E`` and ``D t`` are 1/time^2 and ``D t/tau^2`` is [E]^2.
* ``tau`` is the OU correlation time (units of time), ``omega`` the pendulum frequency.
* ``t`` is time; ``E`` is the energy ``Omega^2/2 - omega^2 cos(theta)`` (``defenergie``),
  which for ``omega = 0`` is ``Omega^2/2``.
* The asymptotic laws do not depend on ``omega``; functions that accept ``omega`` only
  validate it (it is a keyword argument so that a simulation's parameter set can be passed
  through unchanged).
* All functions broadcast over ``t`` (and ``E``, ``Omega``) with NumPy rules; all-scalar
  inputs give a Python ``float``.
* Skewness and flatness are the paper's RAW-moment ratios ``S = <E^3>/<E^2>^{3/2}``,
  ``F = <E^4>/<E^2>^2``, not central-moment statistics.

Bad inputs raise a one-line :class:`ValueError` naming the parameter, the value received and
what is accepted.
"""

from __future__ import annotations

import functools
import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import gamma as _gamma
from scipy.special import gammaln as _gammaln

__all__ = [
    "BFPE_LONGTIME_MEAN_PREFACTOR",
    "OU1_MEAN_E2_PREFACTOR",
    "OU1_MEAN_PREFACTOR",
    "OU2_FLATNESS",
    "OU2_MEAN_E2_PREFACTOR",
    "OU2_MEAN_PREFACTOR",
    "OU2_SKEWNESS",
    "PHI_INF",
    "WHITE_FLATNESS",
    "WHITE_MEAN_E2_PREFACTOR",
    "WHITE_MEAN_PREFACTOR",
    "WHITE_SKEWNESS",
    "bfpe_identity_lhs",
    "bfpe_identity_rhs",
    "bfpe_longtime_correction",
    "bfpe_longtime_mean_E",
    "bfpe_longtime_pdf_Omega",
    "crossover_time",
    "ou1_mean_E",
    "ou1_mean_E2",
    "ou1_moment_E",
    "ou1_pdf_E",
    "ou2_flatness",
    "ou2_mean_E",
    "ou2_mean_E2",
    "ou2_moment_E",
    "ou2_pdf_E",
    "ou2_skewness",
    "phi_crossover_mean_E",
    "white_flatness",
    "white_mean_E",
    "white_mean_E2",
    "white_moment_E",
    "white_pdf_E",
    "white_pdf_Omega",
    "white_skewness",
]

# ---------------------------------------------------------------------------------------------
# Constants (computed from Gamma functions, never typed in)
# ---------------------------------------------------------------------------------------------

#: White noise, Eq. `eq:scalEblanc`: <E> = (1/4) D t.
WHITE_MEAN_PREFACTOR: float = 0.25
#: White noise, from Eq. `eq:pdfEblanc`: <E^2> = (3/16) (D t)^2.
WHITE_MEAN_E2_PREFACTOR: float = float(0.25 * _gamma(2.5) / _gamma(0.5))
#: White noise skewness, Eq. `eq:skewEblanc`: Gamma(7/2) Gamma(1/2)^{1/2} / Gamma(5/2)^{3/2} = 5/sqrt(3).
WHITE_SKEWNESS: float = float(_gamma(3.5) * _gamma(0.5) ** 0.5 / _gamma(2.5) ** 1.5)
#: White noise flatness, Eq. `eq:flatEblanc`: Gamma(9/2) Gamma(1/2) / Gamma(5/2)^2 = 35/3.
WHITE_FLATNESS: float = float(_gamma(4.5) * _gamma(0.5) / _gamma(2.5) ** 2)

#: First-order averaging, Eq. `diff1`: <E> = (1/sqrt(pi)) (D t / tau^2)^{1/2} (known-wrong prefactor).
OU1_MEAN_PREFACTOR: float = float(1.0 / math.sqrt(math.pi))
#: First-order averaging, Eq. `quad1`: <E^2> = (1/2) D t / tau^2 (known-wrong prefactor).
OU1_MEAN_E2_PREFACTOR: float = float(_gamma(1.5) / _gamma(0.5))

#: Second-order averaging, Eq. `eq:scalEcolor`: <E> = Gamma(3/4)/Gamma(1/4) (D t/tau^2)^{1/2}
#: = sqrt(2) pi / Gamma(1/4)^2 (D t/tau^2)^{1/2} ~ 0.337989.
OU2_MEAN_PREFACTOR: float = float(_gamma(0.75) / _gamma(0.25))
#: Second-order averaging, Eq. `eq:scalE2color`: <E^2> = Gamma(5/4)/Gamma(1/4) D t/tau^2 = D t/(4 tau^2).
OU2_MEAN_E2_PREFACTOR: float = float(_gamma(1.25) / _gamma(0.25))
#: Second-order averaging skewness, Eq. `eq:skewEcolor` with the printed typo corrected:
#: Gamma(7/4) Gamma(1/4)^{1/2} / Gamma(5/4)^{3/2} = 6 sqrt(2) pi / Gamma(1/4)^2 ~ 2.027935.
OU2_SKEWNESS: float = float(_gamma(1.75) * _gamma(0.25) ** 0.5 / _gamma(1.25) ** 1.5)
#: Second-order averaging flatness, Eq. `eq:flatEcolor`: Gamma(9/4) Gamma(1/4) / Gamma(5/4)^2 = 5.
OU2_FLATNESS: float = float(_gamma(2.25) * _gamma(0.25) / _gamma(1.25) ** 2)

#: Long-time flatness of Omega implied by second-order averaging (Eq. `deflatness` with
#: omega = 0, E = Omega^2/2): phi_inf = <Omega^4>/<Omega^2>^2 = <E^2>/<E>^2
#: = (1/4) / (Gamma(3/4)/Gamma(1/4))^2 ~ 2.1884.
PHI_INF: float = float(OU2_MEAN_E2_PREFACTOR / OU2_MEAN_PREFACTOR**2)

#: Long-time prefactor c of <E> = c (D t/tau^2)^{1/2} for the averaged B.F.P.E. (`avbfpe`).
#: At large Omega the equation reduces to dP/dt = (D/(4 tau^2)) d/dOmega(Omega^-2 dP/dOmega),
#: whose similarity solution is P ~ exp(-tau^2 Omega^4/(4 D t)); in E = Omega^2/2 this is
#: exactly Eq. `eq:pdfEcolor`, so c = Gamma(3/4)/Gamma(1/4), identical to the second-order
#: averaging prefactor (see docs/theory.md). Computed from the similarity law, not copied.
BFPE_LONGTIME_MEAN_PREFACTOR: float = float(
    # <Omega^2>/2 for P(Omega) = C exp(-b Omega^4) with b = 1/4 (units D t/tau^2 = 1):
    # <Omega^2> = b^{-1/2} Gamma(3/4)/Gamma(1/4)
    0.5 * 0.25**-0.5 * _gamma(0.75) / _gamma(0.25)
)


# ---------------------------------------------------------------------------------------------
# Validation helpers
# ---------------------------------------------------------------------------------------------


def _fail(name: str, value: Any, accepted: str) -> None:
    raise ValueError(f"{name}={value!r} is not accepted: {accepted}")


def _scalar(name: str, value: Any, accepted: str) -> float:
    if isinstance(value, bool):
        _fail(name, value, accepted)
    try:
        v = float(value)
    except (TypeError, ValueError):
        _fail(name, value, accepted)
    if not math.isfinite(v):
        _fail(name, value, accepted)
    return v


def _check_D(D: Any, *, positive: bool = False) -> float:
    if positive:
        msg = "D must be a finite number > 0 (the noise amplitude)"
    else:
        msg = "D must be a finite number >= 0 (the noise amplitude)"
    v = _scalar("D", D, msg)
    if v < 0 or (positive and v == 0):
        _fail("D", D, msg)
    return v


def _check_tau(tau: Any) -> float:
    msg = "tau must be a finite number > 0 (the OU correlation time)"
    if tau is None:
        _fail("tau", tau, msg)
    v = _scalar("tau", tau, msg)
    if v <= 0:
        _fail("tau", tau, msg)
    return v


def _check_omega(omega: Any) -> float:
    msg = "omega must be a finite number >= 0 (the pendulum frequency; it does not enter this law)"
    v = _scalar("omega", omega, msg)
    if v < 0:
        _fail("omega", omega, msg)
    return v


def _array(
    name: str, value: Any, accepted: str, *, minimum: float | None, strict: bool
) -> NDArray[np.float64]:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        _fail(name, value, accepted)
    if not np.all(np.isfinite(a)):
        _fail(name, _show(value), accepted)
    if minimum is not None:
        bad = a <= minimum if strict else a < minimum
        if np.any(bad):
            _fail(name, _show(value), accepted)
    return a


def _show(value: Any) -> Any:
    """A short representation of a possibly large array for error messages."""
    a = np.asarray(value)
    if a.ndim == 0:
        return a.item()
    if a.size <= 6:
        return a.tolist()
    finite = a[np.isfinite(a)]
    lo, hi = (finite.min(), finite.max()) if finite.size else (np.nan, np.nan)
    return f"array(shape={a.shape}, finite min={lo!r}, finite max={hi!r}, non-finite={a.size - finite.size})"


def _check_t(t: Any, *, positive: bool = False) -> NDArray[np.float64]:
    if positive:
        return _array(
            "t", t, "t must be finite and > 0 (a law at t = 0 is a Dirac mass)", minimum=0.0, strict=True
        )
    return _array("t", t, "t must be finite and >= 0 (time since the start)", minimum=0.0, strict=False)


def _check_E(E: Any) -> NDArray[np.float64]:
    return _array(
        "E", E, "E must be finite (energies; the density is 0 for E < 0)", minimum=None, strict=False
    )


def _check_k(k: Any) -> float:
    msg = "k must be a finite real number >= 0 (the order of the raw moment <E^k>)"
    v = _scalar("k", k, msg)
    if v < 0:
        _fail("k", k, msg)
    return v


def _out(a: NDArray[np.float64]) -> NDArray[np.float64] | float:
    return float(a) if a.ndim == 0 else a


def _power_law_pdf(
    E: NDArray[np.float64], norm: NDArray[np.float64], expo: NDArray[np.float64]
) -> NDArray[np.float64]:
    """norm * E^{-1/2} * exp(-expo) on E > 0, +inf at E = 0, 0 for E < 0 (no warnings)."""
    E, norm, expo = np.broadcast_arrays(E, norm, expo)
    out = np.zeros(E.shape, dtype=np.float64)
    pos = E > 0
    out[pos] = norm[pos] / np.sqrt(E[pos]) * np.exp(-expo[pos])
    out[E == 0] = np.inf
    return out


# ---------------------------------------------------------------------------------------------
# White noise (section `sec:white`)
# ---------------------------------------------------------------------------------------------


def white_pdf_Omega(
    Omega: ArrayLike, t: ArrayLike, *, D: float, tau: float | None = None, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Gaussian law of the angular velocity for white noise, Eq. `eq:pdfOmegablanc`.

    ``P_t(Omega) = (pi D t)^{-1/2} exp(-Omega^2/(D t))``, the solution of the averaged
    Fokker-Planck equation `moyblanc` started at ``Omega = 0``: ``<Omega^2> = D t/2``.

    Parameters
    ----------
    Omega : array_like
        Angular velocity (units 1/time).
    t : array_like
        Time, > 0. Broadcast against ``Omega``.
    D : float
        White-noise amplitude, > 0.
    tau, omega : optional
        Accepted for a uniform signature; ``tau`` is ignored, ``omega`` does not enter.

    Returns
    -------
    ndarray or float
        Density in units of 1/[Omega], shape ``broadcast(Omega, t)``.
    """
    D = _check_D(D, positive=True)
    _check_omega(omega)
    t = _check_t(t, positive=True)
    Om = _array("Omega", Omega, "Omega must be finite (angular velocities)", minimum=None, strict=False)
    Om, t = np.broadcast_arrays(Om, t)
    return _out(np.exp(-(Om**2) / (D * t)) / np.sqrt(np.pi * D * t))


def white_pdf_E(
    E: ArrayLike, t: ArrayLike, *, D: float, tau: float | None = None, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Energy law for white noise, Eq. `eq:pdfEblanc`.

    ``P_t(E) = sqrt(2/(pi D t)) E^{-1/2} exp(-2E/(D t))`` for ``E > 0``: ``E`` is
    Gamma-distributed with shape 1/2 and scale ``D t/2`` (``E = Omega^2/2`` with ``Omega``
    Gaussian of variance ``D t/2``, Eq. `eq:pdfOmegablanc`).

    Parameters
    ----------
    E : array_like
        Energy. The density is 0 for ``E < 0`` and ``+inf`` at ``E = 0`` (integrable
        ``E^{-1/2}`` singularity).
    t : array_like
        Time, > 0, broadcast against ``E``.
    D : float
        White-noise amplitude, > 0.
    tau, omega : optional
        Accepted for a uniform signature; they do not enter this law.

    Returns
    -------
    ndarray or float
        Density in units of 1/[E], shape ``broadcast(E, t)``.
    """
    D = _check_D(D, positive=True)
    _check_omega(omega)
    t = _check_t(t, positive=True)
    E = _check_E(E)
    norm = np.sqrt(2.0 / (np.pi * D * t))
    scale = D * t / 2.0
    E_b, scale_b = np.broadcast_arrays(E, scale)
    with np.errstate(over="ignore", under="ignore"):
        expo = np.where(E_b > 0, E_b / scale_b, 0.0)
    return _out(_power_law_pdf(E, norm, expo))


def white_moment_E(
    k: float, t: ArrayLike, *, D: float, tau: float | None = None, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Raw moment ``<E^k>`` for white noise, from Eq. `eq:pdfEblanc`.

    ``<E^k> = (D t/2)^k Gamma(k + 1/2)/Gamma(1/2)`` (Gamma law of shape 1/2, scale ``D t/2``).
    ``k = 1`` gives Eq. `eq:scalEblanc`, ``<E> = D t/4``; ``k = 2`` gives ``3 (D t)^2/16``.

    Parameters
    ----------
    k : float
        Order, any real ``k >= 0``.
    t : array_like
        Time, >= 0.
    D : float
        White-noise amplitude, >= 0.
    tau, omega : optional
        Accepted for a uniform signature; they do not enter.

    Returns
    -------
    ndarray or float
        ``<E^k>`` in units of [E]^k, shape of ``t``.
    """
    k = _check_k(k)
    D = _check_D(D)
    _check_omega(omega)
    t = _check_t(t)
    coef = math.exp(_gammaln(k + 0.5) - _gammaln(0.5))
    return _out(coef * (D * t / 2.0) ** k)


def white_mean_E(
    t: ArrayLike, *, D: float, tau: float | None = None, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Mean energy for white noise, Eq. `eq:scalEblanc`: ``<E> = D t/4``.

    Parameters
    ----------
    t : array_like
        Time, >= 0.
    D : float
        White-noise amplitude, >= 0.
    tau, omega : optional
        Accepted for a uniform signature; they do not enter.

    Returns
    -------
    ndarray or float
        ``<E>``, shape of ``t``.
    """
    D = _check_D(D)
    _check_omega(omega)
    t = _check_t(t)
    return _out(WHITE_MEAN_PREFACTOR * D * t)


def white_mean_E2(
    t: ArrayLike, *, D: float, tau: float | None = None, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Second moment for white noise, from Eq. `eq:pdfEblanc`: ``<E^2> = 3 (D t)^2/16``."""
    return white_moment_E(2.0, t, D=D, tau=tau, omega=omega)


def white_skewness() -> float:
    """Raw-moment skewness ``<E^3>/<E^2>^{3/2}`` for white noise, Eq. `eq:skewEblanc`: ``5/sqrt(3)``."""
    return WHITE_SKEWNESS


def white_flatness() -> float:
    """Raw-moment flatness ``<E^4>/<E^2>^2`` for white noise, Eq. `eq:flatEblanc`: ``35/3``."""
    return WHITE_FLATNESS


# ---------------------------------------------------------------------------------------------
# OU noise, first-order averaging (section `sec:1staveraging`)
# ---------------------------------------------------------------------------------------------


def ou1_pdf_E(
    E: ArrayLike, t: ArrayLike, *, D: float, tau: float, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Half-Gaussian energy law of first-order averaging, Eq. `PDFav1`.

    ``P_t(E) = 2 tau/sqrt(pi D t) exp(-tau^2 E^2/(D t))`` for ``E >= 0`` (Wiener process
    `average1` on the half line). The paper states that its prefactors disagree with
    simulations; it is kept as a reference.

    Parameters
    ----------
    E : array_like
        Energy; density 0 for ``E < 0``.
    t : array_like
        Time, > 0.
    D, tau : float
        OU amplitude (> 0) and correlation time (> 0).
    omega : float, optional
        Accepted and validated; does not enter.

    Returns
    -------
    ndarray or float
        Density, shape ``broadcast(E, t)``.
    """
    D = _check_D(D, positive=True)
    tau = _check_tau(tau)
    _check_omega(omega)
    t = _check_t(t, positive=True)
    E = _check_E(E)
    E, t = np.broadcast_arrays(E, t)
    out = np.zeros(E.shape, dtype=np.float64)
    pos = E >= 0
    out[pos] = 2.0 * tau / np.sqrt(np.pi * D * t[pos]) * np.exp(-(tau**2) * E[pos] ** 2 / (D * t[pos]))
    return _out(out)


def ou1_moment_E(
    k: float, t: ArrayLike, *, D: float, tau: float, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Raw moment ``<E^k>`` of the first-order law, Eq. `PDFav1`.

    ``<E^k> = Gamma((k+1)/2)/sqrt(pi) (D t/tau^2)^{k/2}``; ``k = 1`` is Eq. `diff1`,
    ``k = 2`` is Eq. `quad1`. Valid (with wrong prefactors) for ``t >> t_c``.

    Parameters
    ----------
    k : float
        Order, real ``k >= 0``.
    t : array_like
        Time, >= 0.
    D, tau : float
        OU amplitude (>= 0) and correlation time (> 0).
    omega : float, optional
        Accepted; does not enter.

    Returns
    -------
    ndarray or float
        ``<E^k>``, shape of ``t``.
    """
    k = _check_k(k)
    D = _check_D(D)
    tau = _check_tau(tau)
    _check_omega(omega)
    t = _check_t(t)
    coef = math.exp(_gammaln((k + 1.0) / 2.0) - _gammaln(0.5))
    return _out(coef * (D * t / tau**2) ** (k / 2.0))


def ou1_mean_E(t: ArrayLike, *, D: float, tau: float, omega: float = 0.0) -> NDArray[np.float64] | float:
    """First-order averaging mean energy, Eq. `diff1`: ``(1/sqrt(pi)) (D t/tau^2)^{1/2}``.

    The prefactor is known to be wrong (the paper's own remark); kept as a reference.
    """
    return ou1_moment_E(1.0, t, D=D, tau=tau, omega=omega)


def ou1_mean_E2(t: ArrayLike, *, D: float, tau: float, omega: float = 0.0) -> NDArray[np.float64] | float:
    """First-order averaging second moment, Eq. `quad1`: ``(1/2) D t/tau^2`` (wrong prefactor)."""
    return ou1_moment_E(2.0, t, D=D, tau=tau, omega=omega)


# ---------------------------------------------------------------------------------------------
# OU noise, second-order averaging
# ---------------------------------------------------------------------------------------------


def ou2_pdf_E(
    E: ArrayLike, t: ArrayLike, *, D: float, tau: float, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Asymptotic energy law of second-order averaging, Eq. `eq:pdfEcolor`.

    ``P_t(E) = 2 sqrt(tau)/(Gamma(1/4) (D t)^{1/4}) E^{-1/2} exp(-tau^2 E^2/(D t))`` for
    ``E > 0``: the law of the Bessel process of dimension 1/2, Eq. `average2eta`, reflected
    at ``E = 0``. Valid for ``t >> t_c = 1/(D tau^2)`` and any ``omega``.

    Parameters
    ----------
    E : array_like
        Energy; density 0 for ``E < 0``, ``+inf`` at ``E = 0``.
    t : array_like
        Time, > 0.
    D, tau : float
        OU amplitude (> 0) and correlation time (> 0).
    omega : float, optional
        Accepted; does not enter (the asymptotic law is omega-independent).

    Returns
    -------
    ndarray or float
        Density, shape ``broadcast(E, t)``.
    """
    D = _check_D(D, positive=True)
    tau = _check_tau(tau)
    _check_omega(omega)
    t = _check_t(t, positive=True)
    E = _check_E(E)
    norm = 2.0 * math.sqrt(tau) / (_gamma(0.25) * (D * t) ** 0.25)
    E_b, t_b = np.broadcast_arrays(E, t)
    with np.errstate(over="ignore", under="ignore"):
        expo = np.where(E_b > 0, tau**2 * E_b**2 / (D * t_b), 0.0)
    return _out(_power_law_pdf(E, norm, expo))


def ou2_moment_E(
    k: float, t: ArrayLike, *, D: float, tau: float, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Raw moment ``<E^k>`` of Eq. `eq:pdfEcolor`, any real order ``k >= 0``.

    ``<E^k> = Gamma(k/2 + 1/4)/Gamma(1/4) (D t/tau^2)^{k/2}``; ``k = 1`` is Eq.
    `eq:scalEcolor`, ``k = 2`` is Eq. `eq:scalE2color`. Valid for ``t >> t_c``.

    Parameters
    ----------
    k : float
        Order, real ``k >= 0``.
    t : array_like
        Time, >= 0.
    D, tau : float
        OU amplitude (>= 0) and correlation time (> 0).
    omega : float, optional
        Accepted; does not enter.

    Returns
    -------
    ndarray or float
        ``<E^k>``, shape of ``t``.
    """
    k = _check_k(k)
    D = _check_D(D)
    tau = _check_tau(tau)
    _check_omega(omega)
    t = _check_t(t)
    coef = math.exp(_gammaln(k / 2.0 + 0.25) - _gammaln(0.25))
    return _out(coef * (D * t / tau**2) ** (k / 2.0))


def ou2_mean_E(t: ArrayLike, *, D: float, tau: float, omega: float = 0.0) -> NDArray[np.float64] | float:
    """Second-order averaging mean energy, Eq. `eq:scalEcolor`.

    ``<E> = Gamma(3/4)/Gamma(1/4) (D t/tau^2)^{1/2} ~ 0.337989 (D t/tau^2)^{1/2}``, ``t >> t_c``.
    """
    return ou2_moment_E(1.0, t, D=D, tau=tau, omega=omega)


def ou2_mean_E2(t: ArrayLike, *, D: float, tau: float, omega: float = 0.0) -> NDArray[np.float64] | float:
    """Second-order averaging second moment, Eq. `eq:scalE2color`: ``D t/(4 tau^2)``."""
    return ou2_moment_E(2.0, t, D=D, tau=tau, omega=omega)


def ou2_skewness() -> float:
    """Raw-moment skewness of Eq. `eq:pdfEcolor`, Eq. `eq:skewEcolor` (typo corrected).

    ``Gamma(7/4) Gamma(1/4)^{1/2} / Gamma(5/4)^{3/2} = 6 sqrt(2) pi / Gamma(1/4)^2 ~ 2.027935``
    (the paper prints ``Gamma(1/4)`` without the power 1/2, which evaluates to 3.861).
    """
    return OU2_SKEWNESS


def ou2_flatness() -> float:
    """Raw-moment flatness of Eq. `eq:pdfEcolor`, Eq. `eq:flatEcolor`: ``5``."""
    return OU2_FLATNESS


# ---------------------------------------------------------------------------------------------
# Crossover and the B.F.P.E. (section "Best Effective Fokker-Planck equation")
# ---------------------------------------------------------------------------------------------


def crossover_time(*, D: float, tau: float, omega: float = 0.0) -> float:
    """Crossover time between the white-like and coloured regimes, Eq. `tpcross`.

    ``t_c = 1/(D tau^2)``. The paper derives it as an ORDER OF MAGNITUDE
    (``t_c ~ (D tau^2)^{-1}``, from ``Omega^{-1} ~ tau``): ``<E> ~ D t/4`` for ``t << t_c``
    and ``<E> ~ 0.338 (D t/tau^2)^{1/2}`` for ``t >> t_c``; the actual bend is spread over
    decades around ``t_c``.

    Parameters
    ----------
    D : float
        OU amplitude, >= 0 (``D = 0`` gives ``inf``).
    tau : float
        Correlation time, > 0.
    omega : float, optional
        Accepted; does not enter.

    Returns
    -------
    float
        ``t_c`` in units of time.
    """
    D = _check_D(D)
    tau = _check_tau(tau)
    _check_omega(omega)
    if D == 0.0:
        return math.inf
    return 1.0 / (D * tau**2)


def bfpe_identity_lhs(
    mean_Omega2: ArrayLike, mean_Omega4: ArrayLike, *, tau: float
) -> NDArray[np.float64] | float:
    """Left side of the B.F.P.E. identity, Eq. `idquadr`.

    ``(tau^2/4) <Omega^4> + (1/2) <Omega^2>``. The averaged B.F.P.E. (`avbfpe`, omega = 0)
    implies that it grows exactly by ``D t/4`` (:func:`bfpe_identity_rhs`): it equals ``D t/4``
    for a start at ``Omega = 0``, and in general ``lhs(t) - lhs(t0) = D (t - t0)/4``.

    Parameters
    ----------
    mean_Omega2, mean_Omega4 : array_like
        ``<Omega^2>`` and ``<Omega^4>`` (finite, >= 0), broadcast together.
    tau : float
        Correlation time, > 0.

    Returns
    -------
    ndarray or float
        The left side, in units of [E].
    """
    tau = _check_tau(tau)
    m2 = _array("mean_Omega2", mean_Omega2, "mean_Omega2 must be finite and >= 0", minimum=0.0, strict=False)
    m4 = _array("mean_Omega4", mean_Omega4, "mean_Omega4 must be finite and >= 0", minimum=0.0, strict=False)
    return _out(np.asarray(0.25 * tau**2 * m4 + 0.5 * m2, dtype=np.float64))


def bfpe_identity_rhs(t: ArrayLike, *, D: float, t0: float = 0.0) -> NDArray[np.float64] | float:
    """Right side of Eq. `idquadr`: the growth ``D (t - t0)/4`` of :func:`bfpe_identity_lhs`.

    Parameters
    ----------
    t : array_like
        Time, >= t0.
    D : float
        OU amplitude, >= 0.
    t0 : float, optional
        Start time (0: the paper's start at ``Omega = 0``).

    Returns
    -------
    ndarray or float
        ``D (t - t0)/4``.
    """
    D = _check_D(D)
    t0 = _scalar("t0", t0, "t0 must be a finite number >= 0")
    if t0 < 0:
        _fail("t0", t0, "t0 must be a finite number >= 0")
    t = _array("t", t, f"t must be finite and >= t0 = {t0}", minimum=t0, strict=False)
    return _out(0.25 * D * (t - t0))


def phi_crossover_mean_E(
    t: ArrayLike, *, D: float, tau: float, phi: float = PHI_INF, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Crossover function of the B.F.P.E. with constant flatness, Eqs. `idquadr` + `deflatness`.

    ``<E> = (sqrt(D tau^2 phi t + 1) - 1)/(2 tau^2 phi)``, from ``<Omega^4> = phi <Omega^2>^2``
    with ``phi`` held constant. It reduces to ``D t/4`` for ``t << t_c`` and to
    ``(D t/tau^2)^{1/2}/(2 sqrt(phi))`` for ``t >> t_c``; with ``phi = PHI_INF`` the latter is
    exactly Eq. `eq:scalEcolor`. Evaluated in a cancellation-free form,
    ``D t/2 / (sqrt(D tau^2 phi t + 1) + 1)``.

    Parameters
    ----------
    t : array_like
        Time, >= 0.
    D, tau : float
        OU amplitude (>= 0) and correlation time (> 0).
    phi : float, optional
        Flatness ``<Omega^4>/<Omega^2>^2`` (finite, > 0). Default ``PHI_INF ~ 2.188``, the
        long-time value implied by second-order averaging (a Gaussian would give 3).
    omega : float, optional
        Accepted; the B.F.P.E. is derived for omega = 0.

    Returns
    -------
    ndarray or float
        ``<E>``, shape of ``t``.
    """
    D = _check_D(D)
    tau = _check_tau(tau)
    _check_omega(omega)
    phi = _scalar("phi", phi, "phi must be a finite number > 0 (the flatness <Omega^4>/<Omega^2>^2)")
    if phi <= 0:
        _fail("phi", phi, "phi must be a finite number > 0 (the flatness <Omega^4>/<Omega^2>^2)")
    t = _check_t(t)
    return _out(0.5 * D * t / (np.sqrt(D * tau**2 * phi * t + 1.0) + 1.0))


def bfpe_longtime_pdf_Omega(
    Omega: ArrayLike, t: ArrayLike, *, D: float, tau: float, omega: float = 0.0
) -> NDArray[np.float64] | float:
    """Long-time similarity solution of the averaged B.F.P.E. (`avbfpe`), derived here.

    For ``|Omega| >> 1/tau`` Eq. `avbfpe` becomes ``dP/dt = (D/(4 tau^2)) d/dOmega (Omega^-2
    dP/dOmega)``, whose symmetric, mass-conserving similarity solution is

    ``P_t(Omega) = sqrt(2) tau^{1/2} / (Gamma(1/4) (D t)^{1/4}) exp(-tau^2 Omega^4/(4 D t))``.

    With ``E = Omega^2/2`` this is exactly Eq. `eq:pdfEcolor`. Valid for ``t >> t_c``.

    Parameters
    ----------
    Omega : array_like
        Angular velocity.
    t : array_like
        Time, > 0.
    D, tau : float
        OU amplitude (> 0) and correlation time (> 0).
    omega : float, optional
        Accepted (the B.F.P.E. is for omega = 0).

    Returns
    -------
    ndarray or float
        Density in 1/[Omega], shape ``broadcast(Omega, t)``.
    """
    D = _check_D(D, positive=True)
    tau = _check_tau(tau)
    _check_omega(omega)
    t = _check_t(t, positive=True)
    Om = _array("Omega", Omega, "Omega must be finite (angular velocities)", minimum=None, strict=False)
    Om, t = np.broadcast_arrays(Om, t)
    norm = math.sqrt(2.0 * tau) / (_gamma(0.25) * (D * t) ** 0.25)
    with np.errstate(under="ignore"):
        return _out(norm * np.exp(-(tau**2) * Om**4 / (4.0 * D * t)))


@functools.cache
def bfpe_longtime_correction() -> float:
    """Coefficient ``a`` of the first correction to the B.F.P.E. long-time law (derived here).

    For a start at ``Omega = 0``, the averaged B.F.P.E. (`avbfpe`) gives, for ``t >> t_c``,

    ``<E> = c (D t/tau^2)^{1/2} - a/tau^2 + O((t/t_c)^{-1/2}/tau^2)``, i.e.
    ``<E>/(D t/tau^2)^{1/2} = c - a (t/t_c)^{-1/2} + O(t_c/t)``,

    with ``c = Gamma(3/4)/Gamma(1/4)`` and ``a ~ 0.255135`` -- no ``ln t`` term. In the scaled
    variables ``y = tau Omega (t/t_c)^{-1/4}``, ``P = (t/t_c)^{-1/4} [F0(y) + (t/t_c)^{-1/2} F1(y)
    + ...]``, with ``F0 = sqrt(2)/Gamma(1/4) exp(-y^4/4)`` and ``F1 = Phi'`` where ``Phi``
    solves the linear problem obtained from the ``-x^-4`` term of ``(1 + x^2)^-1``:

    ``Phi'' + y^3 Phi' + 2 y^2 Phi = -y F0``, ``Phi(0) = 0``, ``Phi`` decaying like ``F0``,

    and ``a = -(1/2) int y^2 F1 dy`` (over the whole line). Solved here by linear shooting
    (:func:`scipy.integrate.solve_ivp`) on ``[0, 7]``. Checks: ``int_0^inf y^3 Phi dy = c/2``
    (implied by Eq. `idquadr`), and the finite-volume solver's deficit (tests/theory). See
    docs/theory.md.

    Returns
    -------
    float
        ``a`` (dimensionless).
    """
    from scipy.integrate import solve_ivp

    c0 = math.sqrt(2.0) / float(_gamma(0.25))
    y_end = 7.0

    # state (Phi, F1 = Phi', m = int_0^y s^2 F1(s) ds); the problem is linear, so the
    # admissible solution is particular + alpha * homogeneous, both started at Phi(0) = 0.
    def particular(y: float, u: NDArray[np.float64]) -> list[float]:
        f0 = c0 * math.exp(-(y**4) / 4.0)
        return [u[1], -y * f0 - y**3 * u[1] - 2.0 * y**2 * u[0], y * y * u[1]]

    def homogeneous(y: float, u: NDArray[np.float64]) -> list[float]:
        return [u[1], -(y**3) * u[1] - 2.0 * y**2 * u[0], y * y * u[1]]

    opts = {"rtol": 1e-12, "atol": 1e-15, "method": "DOP853"}
    p = solve_ivp(particular, (0.0, y_end), [0.0, 0.0, 0.0], **opts).y[:, -1]
    h = solve_ivp(homogeneous, (0.0, y_end), [0.0, 1.0, 0.0], **opts).y[:, -1]
    # both homogeneous solutions decay; the admissible one is ~F0, not ~y^-2: Phi(y_end) = 0
    alpha = -p[0] / h[0]
    second_moment = 2.0 * (p[2] + alpha * h[2])  # int over the whole line of y^2 F1
    return -0.5 * second_moment


def bfpe_longtime_mean_E(
    t: ArrayLike, *, D: float, tau: float, omega: float = 0.0, corrected: bool = False
) -> NDArray[np.float64] | float:
    """Long-time mean energy of the averaged B.F.P.E. (`avbfpe`), derived here.

    ``<E> = c (D t/tau^2)^{1/2}`` with ``c = BFPE_LONGTIME_MEAN_PREFACTOR = Gamma(3/4)/Gamma(1/4)``,
    the same value as Eq. `eq:scalEcolor`. With ``corrected=True`` the first correction
    ``- a/tau^2`` (:func:`bfpe_longtime_correction`, ``a ~ 0.2551``) is included, i.e.
    ``<E>/(D t/tau^2)^{1/2} = c - a (t/t_c)^{-1/2}``: the B.F.P.E. approaches the limit from
    below, with a relative deficit ``0.755 (t/t_c)^{-1/2}``.

    Parameters
    ----------
    t : array_like
        Time, >= 0 (the law is asymptotic: t >> t_c).
    D, tau : float
        OU amplitude (>= 0) and correlation time (> 0).
    omega : float, optional
        Accepted (the B.F.P.E. is for omega = 0).
    corrected : bool, optional
        Include the ``-a/tau^2`` correction.

    Returns
    -------
    ndarray or float
        ``<E>``, shape of ``t``.
    """
    D = _check_D(D)
    tau = _check_tau(tau)
    _check_omega(omega)
    t = _check_t(t)
    out = BFPE_LONGTIME_MEAN_PREFACTOR * np.sqrt(D * t / tau**2)
    if corrected:
        out = out - bfpe_longtime_correction() / tau**2
    return _out(out)
