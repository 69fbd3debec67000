"""Closed forms of stochpend.theory.laws against independent references.

References are computed here from scipy.special.gamma and plain arithmetic (or from the
paper's alternative closed forms), never by calling the function under test; densities are
checked by adaptive quadrature.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.special import gamma

from stochpend.theory import laws as L

G14 = gamma(0.25)


# --------------------------------------------------------------------------------------------
# Constants
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("value", "reference"),
    [
        (L.WHITE_MEAN_PREFACTOR, 0.25),
        (L.WHITE_MEAN_E2_PREFACTOR, 3.0 / 16.0),
        (L.WHITE_SKEWNESS, 5.0 / math.sqrt(3.0)),
        (L.WHITE_FLATNESS, 35.0 / 3.0),
        (L.OU1_MEAN_PREFACTOR, 1.0 / math.sqrt(math.pi)),
        (L.OU1_MEAN_E2_PREFACTOR, 0.5),
        # the paper's second form, sqrt(2) pi / Gamma(1/4)^2 (reflection formula), and its digits
        (L.OU2_MEAN_PREFACTOR, math.sqrt(2.0) * math.pi / G14**2),
        (L.OU2_MEAN_PREFACTOR, 0.33798912003364),
        (L.OU2_MEAN_E2_PREFACTOR, 0.25),
        (L.OU2_SKEWNESS, 6.0 * math.sqrt(2.0) * math.pi / G14**2),
        (L.OU2_SKEWNESS, 2.02793472020185),
        (L.OU2_FLATNESS, 5.0),
        # phi_inf = (1/4) / (sqrt(2) pi / Gamma(1/4)^2)^2 = Gamma(1/4)^4 / (8 pi^2)
        (L.PHI_INF, G14**4 / (8.0 * math.pi**2)),
        (L.BFPE_LONGTIME_MEAN_PREFACTOR, math.sqrt(2.0) * math.pi / G14**2),
    ],
)
def test_constants(value: float, reference: float) -> None:
    assert value == pytest.approx(reference, rel=1e-10, abs=0)


def test_constant_functions_return_the_constants() -> None:
    assert L.white_skewness() == pytest.approx(5.0 / math.sqrt(3.0), rel=1e-12)
    assert L.white_flatness() == pytest.approx(35.0 / 3.0, rel=1e-12)
    assert L.ou2_skewness() == pytest.approx(2.02793472020185, rel=1e-10)
    assert L.ou2_flatness() == pytest.approx(5.0, rel=1e-12)


def test_printed_skewness_formula_is_a_typo() -> None:
    """As printed, Gamma(7/4) Gamma(1/4) / Gamma(5/4)^{3/2} = 3.861, not the quoted 2.028."""
    printed = gamma(1.75) * gamma(0.25) / gamma(1.25) ** 1.5
    assert printed == pytest.approx(3.861, abs=1e-3)
    assert abs(printed - L.OU2_SKEWNESS) > 1.0


def test_bfpe_longtime_prefactor_from_quadrature() -> None:
    """<Omega^2>/2 of exp(-Omega^4/4) (units D t/tau^2 = 1) by quadrature."""
    num = quad(lambda w: w**2 * math.exp(-(w**4) / 4.0), 0, np.inf, epsabs=0, epsrel=1e-13)[0]
    den = quad(lambda w: math.exp(-(w**4) / 4.0), 0, np.inf, epsabs=0, epsrel=1e-13)[0]
    assert L.BFPE_LONGTIME_MEAN_PREFACTOR == pytest.approx(0.5 * num / den, rel=1e-10)


# --------------------------------------------------------------------------------------------
# Densities: normalisation and moments by quadrature
# --------------------------------------------------------------------------------------------

CASES = [
    ("white", L.white_pdf_E, L.white_moment_E, {"D": 1.0}),
    ("white", L.white_pdf_E, L.white_moment_E, {"D": 3.7, "omega": 1.0}),
    ("ou1", L.ou1_pdf_E, L.ou1_moment_E, {"D": 1.0, "tau": 0.1}),
    ("ou1", L.ou1_pdf_E, L.ou1_moment_E, {"D": 10.0, "tau": 2.0}),
    ("ou2", L.ou2_pdf_E, L.ou2_moment_E, {"D": 1.0, "tau": 0.1}),
    ("ou2", L.ou2_pdf_E, L.ou2_moment_E, {"D": 10.0, "tau": 2.0, "omega": 1.0}),
]


def _quad_moment(pdf, k: float, t: float, kw: dict) -> float:
    """<E^k> = int_0^inf pdf(E) E^k dE with E = u^2 (removes the E^{-1/2} singularity)."""

    def integrand(u: float) -> float:
        return float(pdf(u * u, t, **kw)) * u ** (2 * k) * 2.0 * u

    # split at the scale of u = sqrt(E) so that quad sees the bulk of the law
    E_scale = kw["D"] * t if "tau" not in kw else math.sqrt(kw["D"] * t) / kw["tau"]
    scale = math.sqrt(E_scale)
    pieces = [0.0, scale, 3 * scale, 10 * scale, np.inf]
    return sum(
        quad(integrand, a, b, epsabs=0, epsrel=1e-12, limit=200)[0]
        for a, b in zip(pieces[:-1], pieces[1:], strict=True)
    )


@pytest.mark.parametrize(("name", "pdf", "moment", "kw"), CASES)
@pytest.mark.parametrize("t", [0.7, 250.0])
def test_pdf_normalised_and_moments(name, pdf, moment, kw, t) -> None:
    assert _quad_moment(pdf, 0, t, kw) == pytest.approx(1.0, rel=1e-10)
    for k in (1, 2, 3, 4, 0.5, 2.5):
        assert _quad_moment(pdf, k, t, kw) == pytest.approx(float(moment(k, t, **kw)), rel=1e-8), k


def test_white_moments_closed_form() -> None:
    D, t = 2.0, 3.0
    assert L.white_mean_E(t, D=D) == pytest.approx(D * t / 4, rel=1e-14)
    assert L.white_mean_E2(t, D=D) == pytest.approx(3 * (D * t) ** 2 / 16, rel=1e-14)
    assert L.white_moment_E(3, t, D=D) == pytest.approx(15 * (D * t) ** 3 / 64, rel=1e-13)
    assert L.white_moment_E(0, t, D=D) == 1.0


def test_ou_moments_closed_form() -> None:
    D, tau, t = 2.0, 0.3, 5.0
    x = D * t / tau**2
    assert L.ou1_mean_E(t, D=D, tau=tau) == pytest.approx(math.sqrt(x / math.pi), rel=1e-13)
    assert L.ou1_mean_E2(t, D=D, tau=tau) == pytest.approx(x / 2, rel=1e-13)
    assert L.ou2_mean_E(t, D=D, tau=tau) == pytest.approx(gamma(0.75) / G14 * math.sqrt(x), rel=1e-13)
    assert L.ou2_mean_E2(t, D=D, tau=tau) == pytest.approx(x / 4, rel=1e-13)


@pytest.mark.parametrize(
    ("moment", "kw", "S", "F"),
    [
        (L.white_moment_E, {"D": 1.3}, 5.0 / math.sqrt(3.0), 35.0 / 3.0),
        (L.ou2_moment_E, {"D": 1.3, "tau": 0.4}, 6.0 * math.sqrt(2.0) * math.pi / G14**2, 5.0),
    ],
)
def test_skewness_flatness_from_moments(moment, kw, S, F) -> None:
    t = np.array([0.5, 20.0, 1e4])
    m2, m3, m4 = (moment(k, t, **kw) for k in (2, 3, 4))
    np.testing.assert_allclose(m3 / m2**1.5, S, rtol=1e-10)
    np.testing.assert_allclose(m4 / m2**2, F, rtol=1e-10)


def test_phi_inf_from_moments() -> None:
    t = 7.0
    m1 = L.ou2_mean_E(t, D=1.0, tau=0.2)
    m2 = L.ou2_mean_E2(t, D=1.0, tau=0.2)
    assert m2 / m1**2 == pytest.approx(L.PHI_INF, rel=1e-12)


def test_bfpe_longtime_law_is_eq_pdfEcolor() -> None:
    """P_E(E) = 2 P_Omega(sqrt(2E)) / sqrt(2E): the B.F.P.E. similarity law is eq:pdfEcolor."""
    E = np.array([1e-3, 0.5, 3.0, 20.0])
    for D, tau, t in [(1.0, 0.1, 1e4), (4.0, 1.0, 3.0)]:
        w = np.sqrt(2 * E)
        np.testing.assert_allclose(
            2 * L.bfpe_longtime_pdf_Omega(w, t, D=D, tau=tau) / w, L.ou2_pdf_E(E, t, D=D, tau=tau), rtol=1e-12
        )
        norm = quad(
            lambda x, t=t, D=D, tau=tau: float(L.bfpe_longtime_pdf_Omega(x, t, D=D, tau=tau)),
            -np.inf,
            np.inf,
            epsabs=0,
            epsrel=1e-12,
        )[0]
        assert norm == pytest.approx(1.0, rel=1e-10)


def test_white_Omega_law_maps_to_E_law() -> None:
    E = np.array([1e-3, 0.5, 3.0])
    w = np.sqrt(2 * E)
    np.testing.assert_allclose(
        2 * L.white_pdf_Omega(w, 2.0, D=1.5) / w, L.white_pdf_E(E, 2.0, D=1.5), rtol=1e-12
    )
    var = quad(lambda x: x * x * float(L.white_pdf_Omega(x, 2.0, D=1.5)), -np.inf, np.inf, epsrel=1e-12)[0]
    assert var == pytest.approx(1.5 * 2.0 / 2, rel=1e-10)


# --------------------------------------------------------------------------------------------
# Broadcasting, support, scalars
# --------------------------------------------------------------------------------------------


def test_broadcasting_and_scalars() -> None:
    t = np.array([[1.0], [2.0], [5.0]])
    E = np.linspace(0.1, 2.0, 4)
    for f, kw in [
        (L.white_pdf_E, {"D": 1.0}),
        (L.ou1_pdf_E, {"D": 1.0, "tau": 0.5}),
        (L.ou2_pdf_E, {"D": 1.0, "tau": 0.5}),
    ]:
        out = f(E, t, **kw)
        assert out.shape == (3, 4)
        assert isinstance(f(0.3, 2.0, **kw), float)
        np.testing.assert_allclose(out[1, 2], f(E[2], 2.0, **kw), rtol=1e-15)
    assert L.ou2_mean_E(np.ones((2, 3)), D=1.0, tau=1.0).shape == (2, 3)
    assert isinstance(L.ou2_mean_E(2.0, D=1.0, tau=1.0), float)


def test_support_without_warnings() -> None:
    E = np.array([-1.0, 0.0, 1.0])
    for f, kw in [(L.white_pdf_E, {"D": 1.0}), (L.ou2_pdf_E, {"D": 1.0, "tau": 0.5})]:
        out = f(E, 1.0, **kw)
        assert out[0] == 0.0 and np.isinf(out[1]) and np.isfinite(out[2])
    out = L.ou1_pdf_E(E, 1.0, D=1.0, tau=0.5)
    assert out[0] == 0.0 and out[1] == pytest.approx(2 * 0.5 / math.sqrt(math.pi), rel=1e-14)
    assert L.white_mean_E(0.0, D=1.0) == 0.0
    assert L.white_pdf_E(1e6, 1e-3, D=1.0) == 0.0


# --------------------------------------------------------------------------------------------
# Crossover and B.F.P.E. identity helpers
# --------------------------------------------------------------------------------------------


def test_crossover_time() -> None:
    assert L.crossover_time(D=1.0, tau=0.1) == pytest.approx(100.0, rel=1e-14)
    assert L.crossover_time(D=4.0, tau=0.5, omega=1.0) == pytest.approx(1.0, rel=1e-14)
    assert L.crossover_time(D=0.0, tau=1.0) == math.inf


def test_identity_helpers() -> None:
    assert L.bfpe_identity_lhs(2.0, 8.0, tau=0.5) == pytest.approx(0.25 * 0.25 * 8.0 + 1.0, rel=1e-15)
    assert L.bfpe_identity_rhs(10.0, D=2.0, t0=2.0) == pytest.approx(4.0, rel=1e-15)
    # a Gaussian of variance D t/2 at tau -> 0 satisfies (1/2)<Omega^2> = D t/4
    assert L.bfpe_identity_lhs(1.5, 3 * 1.5**2, tau=1e-9) == pytest.approx(
        L.bfpe_identity_rhs(3.0, D=1.0), rel=1e-12
    )


def test_phi_crossover_limits() -> None:
    D, tau = 1.0, 0.1
    tc = 1.0 / (D * tau**2)
    t_small = 1e-8 * tc
    assert L.phi_crossover_mean_E(t_small, D=D, tau=tau) / (D * t_small / 4) == pytest.approx(1.0, abs=1e-7)
    t_big = 1e14 * tc
    ratio = L.phi_crossover_mean_E(t_big, D=D, tau=tau) / math.sqrt(D * t_big / tau**2)
    assert ratio == pytest.approx(math.sqrt(2) * math.pi / G14**2, rel=1e-6)
    # the closed form as printed, (sqrt(D tau^2 phi t + 1) - 1)/(2 tau^2 phi), at moderate t
    phi, t = 2.5, 3.0 * tc
    printed = (math.sqrt(D * tau**2 * phi * t + 1) - 1) / (2 * tau**2 * phi)
    assert L.phi_crossover_mean_E(t, D=D, tau=tau, phi=phi) == pytest.approx(printed, rel=1e-12)
    # phi solves the identity: (tau^2/4) phi <Omega^2>^2 + <Omega^2>/2 = D t/4
    m2 = 2 * L.phi_crossover_mean_E(t, D=D, tau=tau, phi=phi)
    assert L.bfpe_identity_lhs(m2, phi * m2**2, tau=tau) == pytest.approx(D * t / 4, rel=1e-12)


# --------------------------------------------------------------------------------------------
# Bad input
# --------------------------------------------------------------------------------------------

BAD = [
    (L.white_mean_E, (1.0,), {"D": -1.0}, "D"),
    (L.white_mean_E, (1.0,), {"D": float("nan")}, "D"),
    (L.white_mean_E, (-1.0,), {"D": 1.0}, "t"),
    (L.white_mean_E, (np.array([1.0, np.inf]),), {"D": 1.0}, "t"),
    (L.white_pdf_E, (1.0, 0.0), {"D": 1.0}, "t"),
    (L.white_pdf_E, (np.nan, 1.0), {"D": 1.0}, "E"),
    (L.white_moment_E, (-1.0, 1.0), {"D": 1.0}, "k"),
    (L.ou2_mean_E, (1.0,), {"D": 1.0, "tau": 0.0}, "tau"),
    (L.ou2_mean_E, (1.0,), {"D": 1.0, "tau": -1.0}, "tau"),
    (L.ou2_mean_E, (1.0,), {"D": 1.0, "tau": None}, "tau"),
    (L.ou2_mean_E, (1.0,), {"D": 1.0, "tau": float("inf")}, "tau"),
    (L.ou1_mean_E, (1.0,), {"D": 1.0, "tau": 1.0, "omega": float("nan")}, "omega"),
    (L.ou2_pdf_E, (1.0, 1.0), {"D": 0.0, "tau": 1.0}, "D"),
    (L.ou2_moment_E, (2.0, float("nan")), {"D": 1.0, "tau": 1.0}, "t"),
    (L.phi_crossover_mean_E, (1.0,), {"D": 1.0, "tau": 1.0, "phi": 0.0}, "phi"),
    (L.bfpe_identity_lhs, (-1.0, 1.0), {"tau": 1.0}, "mean_Omega2"),
]


@pytest.mark.parametrize(("func", "args", "kw", "param"), BAD)
def test_bad_input_raises_one_line(func, args, kw, param) -> None:
    with pytest.raises(ValueError) as info:
        func(*args, **kw)
    msg = str(info.value)
    assert msg.startswith(f"{param}=")
    assert "is not accepted" in msg
    assert "\n" not in msg


def test_tau_message_matches_simulator_style() -> None:
    with pytest.raises(
        ValueError,
        match=r"^tau=-1\.0 is not accepted: tau must be a finite number > 0 \(the OU correlation time\)$",
    ):
        L.crossover_time(D=1.0, tau=-1.0)
