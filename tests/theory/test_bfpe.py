"""The averaged B.F.P.E. solver (stochpend.theory.bfpe) against exact properties.

Exact statements checked: conservation of mass, the identity `idquadr` (which the scheme
satisfies exactly up to the outer-wall flux), the short-time expansion of the B.F.P.E.
(derived from the moment equations in docs/theory.md), the long-time similarity limit
(prefactor Gamma(3/4)/Gamma(1/4), phi -> PHI_INF), scale invariance in t/t_c, and grid and
time-step convergence.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from scipy.special import gamma

from stochpend.theory import laws as L
from stochpend.theory import solve_bfpe

D, TAU = 1.0, 0.1
TC = 1.0 / (D * TAU**2)
S_OUT = np.geomspace(1e-3, 1e4, 29)  # t/t_c, includes 1e-3, 10, 100, 1000, 1e4
C_INF = math.sqrt(2.0) * math.pi / gamma(0.25) ** 2  # derived long-time prefactor
PHI_INF = gamma(0.25) ** 4 / (8.0 * math.pi**2)


@pytest.fixture(scope="module")
def ds() -> xr.Dataset:
    times = TC * S_OUT
    return solve_bfpe(D=D, tau=TAU, t_max=times[-1], times=times)


def _at(ds: xr.Dataset, name: str, s: float) -> float:
    i = int(np.argmin(np.abs(S_OUT - s)))
    assert S_OUT[i] == pytest.approx(s, rel=1e-12)
    return float(ds[name].values[i])


def test_dataset_layout(ds: xr.Dataset) -> None:
    for name in (
        "mean_E",
        "mean_E2",
        "mean_E3",
        "mean_E4",
        "skewness",
        "flatness",
        "mean_Omega2",
        "mean_Omega4",
        "phi",
        "mass",
        "identity_residual",
        "identity_lhs",
        "P_Omega",
    ):
        assert name in ds
    assert ds.mean_E.dims == ("time",)
    assert ds.P_Omega.dims == ("time", "u")
    assert ds.Omega.dims == ("time", "u")
    np.testing.assert_allclose(ds.time.values, TC * S_OUT, rtol=1e-15)
    for key in ("D", "tau", "omega", "t0", "t_c", "n_cells", "steps_per_decade", "x_max", "scheme"):
        assert key in ds.attrs
    np.testing.assert_allclose(ds.mean_E, ds.mean_Omega2 / 2, rtol=1e-15)
    np.testing.assert_allclose(ds.mean_E2, ds.mean_Omega4 / 4, rtol=1e-15)
    np.testing.assert_allclose(ds.phi, ds.mean_Omega4 / ds.mean_Omega2**2, rtol=1e-14)
    np.testing.assert_allclose(ds.skewness, ds.mean_E3 / ds.mean_E2**1.5, rtol=1e-14)
    np.testing.assert_allclose(ds.flatness, ds.mean_E4 / ds.mean_E2**2, rtol=1e-14)


def test_mass_conserved(ds: xr.Dataset) -> None:
    assert np.max(np.abs(ds.mass.values - 1.0)) < 1e-10


def test_identity_idquadr(ds: xr.Dataset) -> None:
    """(tau^2/4)<Omega^4> + <Omega^2>/2 grows by exactly D (t - t0)/4."""
    assert np.max(np.abs(ds.identity_residual.values)) < 1e-6
    # independently, from the returned moments, between every pair of output times
    lhs = L.bfpe_identity_lhs(ds.mean_Omega2.values, ds.mean_Omega4.values, tau=TAU)
    t = ds.time.values
    np.testing.assert_allclose(lhs[1:] - lhs[0], D * (t[1:] - t[0]) / 4, rtol=1e-6)
    assert np.max(ds.boundary_flux.values) < 1e-20


def test_short_time_white_law(ds: xr.Dataset) -> None:
    """<E>/(D t/4) -> 1; the B.F.P.E. moment equations give 1 - 3s/4 + 13 s^2/8 + O(s^3)."""
    s = 1e-3
    ratio = _at(ds, "mean_E", s) / (D * s * TC / 4)
    assert abs(ratio - 1.0) < 1e-3
    assert ratio == pytest.approx(1 - 0.75 * s + 13 / 8 * s**2, abs=1e-7)
    # flatness of Omega: Gaussian 3 at s -> 0, phi = 3 - 2 s + O(s^2)
    assert _at(ds, "phi", s) == pytest.approx(3 - 2 * s, abs=1e-3)
    # the energy law is then the white law: S, F close to 5/sqrt(3), 35/3
    assert _at(ds, "skewness", s) == pytest.approx(5 / math.sqrt(3), rel=2e-3)
    assert _at(ds, "flatness", s) == pytest.approx(35 / 3, rel=5e-3)


def _extrapolate(ds: xr.Dataset, name: str, scale: np.ndarray | float = 1.0) -> float:
    """Remove the (t/t_c)^{-1/2} correction using s = 1e3 and 1e4 (error O(1/s))."""
    v3 = _at(ds, name, 1e3) / (scale if np.isscalar(scale) else scale[0])
    v4 = _at(ds, name, 1e4) / (scale if np.isscalar(scale) else scale[1])
    r = math.sqrt(10.0)
    return (r * v4 - v3) / (r - 1)


def test_long_time_prefactor(ds: xr.Dataset) -> None:
    """<E>/(D t/tau^2)^{1/2} -> Gamma(3/4)/Gamma(1/4) = 0.337989 (derived similarity solution)."""
    scale = np.sqrt(D * TC * np.array([1e3, 1e4]) / TAU**2)
    c3 = _at(ds, "mean_E", 1e3) / scale[0]
    c4 = _at(ds, "mean_E", 1e4) / scale[1]
    # model-free: remove the (t/t_c)^{-1/2} term by Richardson extrapolation
    assert _extrapolate(ds, "mean_E", scale) == pytest.approx(C_INF, rel=5e-4)
    # approach from below as c_inf - a (t/t_c)^{-1/2} + b t_c/t, a from the perturbation ODE
    a = L.bfpe_longtime_correction()
    assert a == pytest.approx(0.255135, abs=1e-6)
    assert 0.24 < (C_INF - c4) * math.sqrt(1e4) < 0.26
    assert 0.24 < (C_INF - c3) * math.sqrt(1e3) < 0.26
    corrected = L.bfpe_longtime_mean_E(1e4 * TC, D=D, tau=TAU, corrected=True)
    assert _at(ds, "mean_E", 1e4) == pytest.approx(corrected, rel=5e-5)
    # idquadr in the paper's form: for a start at Omega = 0, tau^2 <E^2> + <E> = D t/4, i.e.
    # <E^2>/(D t/tau^2) = 1/4 - <E>/(D t): <E^2> approaches (1/4) D t/tau^2 from below
    t = ds.time.values
    np.testing.assert_allclose(TAU**2 * ds.mean_E2.values + ds.mean_E.values, D * t / 4, rtol=2e-6)
    late = S_OUT >= 1.0
    np.testing.assert_allclose(
        (ds.mean_E2.values / (D * t / TAU**2))[late], (0.25 - ds.mean_E.values / (D * t))[late], rtol=1e-6
    )


def test_correction_coefficient_matches_fine_solve() -> None:
    """a from the perturbation ODE vs the finite-volume deficit (c_inf - c) sqrt(t/t_c).

    The deficit is a - b (t/t_c)^{-1/2}; eliminating b between t = 1e3 t_c and 1e4 t_c needs
    <E> to ~1e-6 relative, hence the finer grid (4000 cells, 200 steps per decade).
    """
    s = np.array([1e3, 1e4])
    d = solve_bfpe(D=1.0, tau=1.0, t_max=s[-1], times=s, n_cells=4000, steps_per_decade=200)
    deficit = (C_INF - d.mean_E.values / np.sqrt(s)) * np.sqrt(s)
    r = np.sqrt(s)
    a_solver = (r[1] * deficit[1] - r[0] * deficit[0]) / (r[1] - r[0])
    assert a_solver == pytest.approx(L.bfpe_longtime_correction(), abs=3e-4)
    # phi - phi_inf = phi_inf (2 a/c - 4 c) (t/t_c)^{-1/2} + O(t_c/t)
    slope = PHI_INF * (2 * L.bfpe_longtime_correction() / C_INF - 4 * C_INF)
    assert (d.phi.values[-1] - PHI_INF) * r[-1] == pytest.approx(slope, rel=2e-2)


def test_phi_and_energy_shape_limits(ds: xr.Dataset) -> None:
    phi = ds.phi.values
    assert np.all(np.diff(phi) < 0)  # decreases monotonically from 3 to phi_inf
    assert np.all(phi > PHI_INF)
    assert _extrapolate(ds, "phi") == pytest.approx(PHI_INF, abs=1e-3)
    assert _extrapolate(ds, "skewness") == pytest.approx(
        6 * math.sqrt(2) * math.pi / gamma(0.25) ** 2, abs=2e-3
    )
    assert _extrapolate(ds, "flatness") == pytest.approx(5.0, abs=1e-2)


def test_law_output(ds: xr.Dataset) -> None:
    P = ds.P_Omega.values
    Om = ds.Omega.values
    norms = np.trapezoid(P, Om, axis=1)
    np.testing.assert_allclose(norms, 1.0, atol=2e-3)  # +-5 sigma window, trapezoid on 201 points
    np.testing.assert_allclose(P, P[:, ::-1], rtol=1e-15)  # symmetric
    # earliest time: the white Gaussian of variance D t/2
    t0 = float(ds.time.values[0])
    gauss = L.white_pdf_Omega(Om[0], t0, D=D)
    assert np.max(np.abs(P[0] - gauss)) < 2e-3 * np.max(gauss)
    # latest time: the similarity law exp(-tau^2 Omega^4/(4 D t)) (same <Omega^2>-scaled shape
    # up to the (t/t_c)^{-1/2} correction)
    t1 = float(ds.time.values[-1])
    sim = L.bfpe_longtime_pdf_Omega(Om[-1], t1, D=D, tau=TAU)
    assert np.max(np.abs(P[-1] - sim)) < 2e-2 * np.max(sim)


def test_scale_invariance() -> None:
    """Only t/t_c matters: tau^2 <E> at equal t/t_c is the same for (D, tau) = (1, 0.1), (4, 0.05)."""
    out = []
    for D_, tau_ in [(1.0, 0.1), (4.0, 0.05)]:
        tc = 1.0 / (D_ * tau_**2)
        times = tc * np.array([1e-2, 1.0, 30.0])
        d = solve_bfpe(D=D_, tau=tau_, t_max=times[-1], times=times, n_cells=300)
        out.append(d.mean_E.values * tau_**2)
    np.testing.assert_allclose(out[0], out[1], rtol=1e-9)


def test_grid_and_step_refinement() -> None:
    """Halving n_cells changes <E>(1e4 t_c) by < 2e-4 relative; halving the steps by < 3e-5."""
    times = TC * np.array([1.0, 1e4])
    ref = solve_bfpe(D=D, tau=TAU, t_max=times[-1], times=times).mean_E.values[-1]
    coarse = solve_bfpe(D=D, tau=TAU, t_max=times[-1], times=times, n_cells=500).mean_E.values[-1]
    few_steps = solve_bfpe(D=D, tau=TAU, t_max=times[-1], times=times, steps_per_decade=50).mean_E.values[-1]
    assert abs(coarse / ref - 1) < 2e-4
    assert abs(few_steps / ref - 1) < 3e-5


def test_conservation_over_fourteen_decades() -> None:
    s = np.geomspace(1e-3, 1e8, 12)
    d = solve_bfpe(D=1.0, tau=1.0, t_max=s[-1], times=s, t0=1e-6, n_cells=1500)
    assert np.max(np.abs(d.mass.values - 1.0)) < 1e-10
    assert np.max(np.abs(d.identity_residual.values)) < 1e-6
    c = d.mean_E.values[-1] / math.sqrt(s[-1])
    assert c == pytest.approx(C_INF, rel=1e-4)  # t = 1e8 t_c: correction 0.255e-4 / 0.338


def test_default_times_and_t0() -> None:
    d = solve_bfpe(D=2.0, tau=0.5, t_max=50.0, n_times=5, n_cells=200)
    np.testing.assert_allclose(d.time.values, np.geomspace(0.05, 50.0, 5), rtol=1e-14)
    assert d.attrs["t0"] == pytest.approx(min(1e-6 * d.attrs["t_c"], 1e-3 * 0.05))


@pytest.mark.parametrize(
    ("kw", "param"),
    [
        ({"D": 1.0, "tau": 0.1, "t_max": 10.0, "omega": 1.0}, "omega"),
        ({"D": -1.0, "tau": 0.1, "t_max": 10.0}, "D"),
        ({"D": 0.0, "tau": 0.1, "t_max": 10.0}, "D"),
        ({"D": 1.0, "tau": 0.0, "t_max": 10.0}, "tau"),
        ({"D": 1.0, "tau": 0.1, "t_max": -1.0}, "t_max"),
        ({"D": 1.0, "tau": 0.1, "t_max": 10.0, "times": [1.0, 20.0]}, "times"),
        ({"D": 1.0, "tau": 0.1, "t_max": 10.0, "times": [0.0, 1.0]}, "times"),
        ({"D": 1.0, "tau": 0.1, "t_max": 10.0, "times": [2.0, 1.0]}, "times"),
        ({"D": 1.0, "tau": 0.1, "t_max": 10.0, "times": [1.0], "t0": 1.0}, "t0"),
        ({"D": 1.0, "tau": 0.1, "t_max": 10.0, "n_cells": 5}, "n_cells"),
    ],
)
def test_bad_input(kw: dict, param: str) -> None:
    with pytest.raises(ValueError) as info:
        solve_bfpe(**kw)
    msg = str(info.value)
    assert msg.startswith(f"{param}=") and "is not accepted" in msg and "\n" not in msg
