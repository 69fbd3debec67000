"""Measured exponents (stochpend.exponents) and predicted ones (stochpend.theory.scaling).

The fit is checked on synthetic ensembles with a known law: per-path energies
E_i(t) = law(t) X_i(t), with X_i a mean-one log-Brownian martingale in log t, so that the
errors at different times are correlated as in a simulation. Tolerances are in standard
errors (Z_TOL) or derived from the number of replicates.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray as xr
from scipy.integrate import quad

import stochpend
from stochpend.exponents import ExponentFit, diagnose_growth, fit_exponent
from stochpend.theory.scaling import (
    NOISES,
    harmonic_growth_rate,
    predicted_exponent,
    spectral_density,
)
from tests.conftest import SEED, Z_TOL

TIMES = np.geomspace(1.0, 100.0, 20)


def _synthetic(law, times=TIMES, *, rng, n_batches=40, per_batch=25, sigma=0.3, nonfinite=None):
    """A Dataset shaped like simulate's output, E_i(t) = law(t) X_i(t) with E[X_i(t)] = 1."""
    s = np.log(times / times[0])
    steps = np.sqrt(np.diff(s, prepend=0.0))
    walk = np.cumsum(rng.standard_normal((n_batches, per_batch, times.size)) * steps, axis=-1)
    energies = law(times) * np.exp(sigma * walk - 0.5 * sigma**2 * s)
    batch_sum = energies.sum(axis=1)
    counts = np.full((n_batches, times.size), per_batch, dtype=np.int64)
    paths = n_batches * per_batch
    nonfinite = np.zeros(times.size, dtype=np.int64) if nonfinite is None else np.asarray(nonfinite)
    return xr.Dataset(
        {
            "mean_E": ("time", batch_sum.sum(axis=0) / paths),
            "n_finite_paths": ("time", counts.sum(axis=0) - nonfinite),
            "nonfinite_paths": ("time", nonfinite),
            "batch_sum_E": (("batch", "time"), batch_sum),
            "batch_n_finite": (("batch", "time"), counts),
        },
        coords={"time": times},
        attrs={"paths": paths, "noise": "synthetic"},
    )


# -- fit_exponent --------------------------------------------------------------------------


@pytest.mark.parametrize("nu", [0.5, 1.0, 1 / 3])
def test_fit_recovers_known_exponent(nu):
    ds = _synthetic(lambda t: 2.0 * t**nu, rng=np.random.default_rng(SEED))
    fit = fit_exponent(ds, 5.0, 100.0)
    assert isinstance(fit, ExponentFit)
    z = (fit.exponent - nu) / fit.se
    assert abs(z) < Z_TOL, f"fitted {fit.exponent:.4f} +- {fit.se:.4f} vs {nu}: z = {z:+.2f}"
    assert fit.n_times == int(np.sum((TIMES >= 5.0) & (TIMES <= 100.0)))
    assert fit.t_min >= 5.0 and fit.t_max == pytest.approx(100.0)
    assert (fit.paths, fit.nonfinite, fit.growth) == (1000, 0, "power")


def test_jackknife_se_has_the_right_size():
    """Over independent replicates the z-scores have unit spread, and the mean SE matches the
    replicates' scatter: the jackknife sees the correlation between times.

    200 replicates: the sample SD of 200 unit normals is within 1 +- 0.2 with probability
    1 - 6e-5 (SD of the SD ~ 0.05); with 40 batches z is t-like with SD ~ 1.03.
    """
    rng = np.random.default_rng(SEED + 1)
    nu = 0.5
    fits = [fit_exponent(_synthetic(lambda t: t**nu, rng=rng), 5.0, 100.0) for _ in range(200)]
    est = np.array([f.exponent for f in fits])
    se = np.array([f.se for f in fits])
    z = (est - nu) / se
    assert 0.8 < z.std(ddof=1) < 1.2, f"z spread {z.std(ddof=1):.3f}, expected ~1"
    assert abs(z.mean()) < Z_TOL / math.sqrt(z.size) * 1.1, f"z mean {z.mean():+.3f}: the fit is biased"
    ratio = se.mean() / est.std(ddof=1)
    assert 0.8 < ratio < 1.2, f"mean SE / scatter = {ratio:.3f}"


@pytest.mark.parametrize(
    ("t_min", "t_max", "starts"),
    [
        (0.0, 10.0, "t_min=0.0 is not accepted"),
        (-1.0, 10.0, "t_min=-1.0 is not accepted"),
        (float("nan"), 10.0, "t_min=nan is not accepted"),
        (5.0, float("inf"), "t_max=inf is not accepted"),
        (10.0, 5.0, "t_max=5.0 is not accepted"),
        (10.0, 10.0, "t_max=10.0 is not accepted"),
        (60.0, 70.0, "t_min=60.0 is not accepted"),  # one output time in the window
        (200.0, 300.0, "t_min=200.0 is not accepted"),  # none
    ],
)
def test_bad_windows_are_refused_in_one_line(t_min, t_max, starts):
    ds = _synthetic(lambda t: t, rng=np.random.default_rng(SEED))
    with pytest.raises(ValueError) as err:
        fit_exponent(ds, t_min, t_max)
    msg = str(err.value)
    assert msg.startswith(starts) and "\n" not in msg, msg


def test_window_with_nonpositive_energy_is_refused():
    """The pendulum's <E> starts near -omega^2 cos: log <E> is undefined there."""
    ds = _synthetic(lambda t: t - 3.0, rng=np.random.default_rng(SEED))
    with pytest.raises(ValueError, match=r"^t_min=1\.0 is not accepted: <E> = .* needs <E> > 0"):
        fit_exponent(ds, 1.0, 100.0)
    assert fit_exponent(ds, 10.0, 100.0).n_times >= 3  # later, fine


def test_dataset_without_batch_sums_is_refused():
    ds = _synthetic(lambda t: t, rng=np.random.default_rng(SEED)).drop_vars("batch_sum_E")
    with pytest.raises(ValueError, match="lacks batch_sum_E"):
        fit_exponent(ds, 5.0, 100.0)


def test_window_edges_equal_to_output_times_are_included():
    ds = _synthetic(lambda t: t, rng=np.random.default_rng(SEED))
    t = ds.time.values
    assert fit_exponent(ds, float(t[-3]) * (1 + 1e-12), float(t[-1]) * (1 - 1e-12)).n_times == 3


# -- diagnose_growth -----------------------------------------------------------------------


def test_power_law_is_diagnosed_as_power():
    ds = _synthetic(lambda t: t**0.5, rng=np.random.default_rng(SEED))
    assert diagnose_growth(ds) == "power"


def test_crossover_to_slower_power_law_is_power():
    """The OU pendulum's crossover (slope 1 -> 1/2) is not an exponential."""
    ds = _synthetic(lambda t: t / np.sqrt(1.0 + t / 5.0), rng=np.random.default_rng(SEED))
    assert diagnose_growth(ds) == "power"


def test_exponential_is_diagnosed():
    times = np.geomspace(0.1, 20.0, 20)
    ds = _synthetic(lambda t: np.exp(0.5 * t), times, rng=np.random.default_rng(SEED), sigma=0.1)
    out = diagnose_growth(ds, detail=True)
    assert out.split(":")[0] == "exponential", out
    # A power law on the same times is not mistaken for one.
    ds_pow = _synthetic(lambda t: t**2, times, rng=np.random.default_rng(SEED), sigma=0.1)
    assert diagnose_growth(ds_pow) == "power"


def test_blow_up_is_diagnosed_with_fraction_and_first_time():
    nonfinite = np.where(TIMES >= TIMES[12], 7, 0)
    ds = _synthetic(lambda t: t**2, rng=np.random.default_rng(SEED), nonfinite=nonfinite)
    out = diagnose_growth(ds, detail=True)
    assert out.startswith("finite-time blow-up: 7 of 1000 paths (0.7%)"), out
    assert f"first by output time t = {TIMES[12]:g}" in out, out
    assert diagnose_growth(ds) == "finite-time blow-up"
    fit = fit_exponent(ds, 5.0, 100.0)
    assert fit.nonfinite == 7 and fit.growth == "finite-time blow-up"


def test_too_few_times_is_unknown():
    times = np.geomspace(1.0, 10.0, 8)
    ds = _synthetic(lambda t: t, times, rng=np.random.default_rng(SEED))
    assert diagnose_growth(ds) == "unknown"


# -- a real simulation ----------------------------------------------------------------------


def test_white_noise_pendulum_exponent_is_one():
    """E ~ D t/4 (eq:scalEblanc): slope 1 on [50, 200] within Z_TOL jackknife errors."""
    ds = stochpend.simulate(noise="white", D=1.0, omega=1.0, paths=2000, t_max=200, n_times=20, seed=1)
    fit = fit_exponent(ds, 50.0, 200.0)
    z = (fit.exponent - 1.0) / fit.se
    assert abs(z) < Z_TOL, f"exponent {fit.exponent:.4f} +- {fit.se:.4f}: z = {z:+.2f}"
    assert 0.005 < fit.se < 0.2, f"jackknife SE {fit.se} out of the expected range for 2000 paths"
    assert fit.growth == "power" and fit.nonfinite == 0 and fit.paths == 2000
    pred = predicted_exponent("pendulum", "white")
    assert abs(fit.exponent - pred.exponent) < Z_TOL * fit.se


# -- predictions -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("args", "exponent"),
    [
        (("pendulum", "white"), 1.0),  # eq:scalEblanc
        (("pendulum", "ou"), 0.5),  # eq:scalEcolor
        (("pendulum", "dichotomous"), 0.5),  # same spectrum as OU
        (("pendulum", "harmonic"), 1 / 3),  # rotor, S ~ nu^-4
        (("power", "white", "position", 2), 2.0),
        (("power", "ou", "position", 2), 1.0),
        (("power", "harmonic", "position", 2), 2 / 3),
        (("power", "white", "position", 3), 1.5),
    ],
)
def test_power_law_predictions(args, exponent):
    pred = predicted_exponent(*args)
    assert pred.growth == "power"
    assert pred.exponent == pytest.approx(exponent, rel=1e-12)


def test_rotor_and_position_formulas():
    """Pendulum 2/(2 + alpha); power potential, position coupling, 2n/((n - 1)(2 + alpha)),
    whose n -> infinity limit is the pendulum's."""
    for noise, alpha in [("white", 0), ("ou", 2), ("harmonic", 4)]:
        assert predicted_exponent("pendulum", noise).exponent == pytest.approx(2 / (2 + alpha))
        for n in (2, 3, 5):
            got = predicted_exponent("power", noise, "position", n).exponent
            assert got == pytest.approx(2 * n / ((n - 1) * (2 + alpha)))


@pytest.mark.parametrize("noise", NOISES)
def test_harmonic_potential_grows_exponentially(noise):
    for args in (("harmonic", noise), ("harmonic", noise, "position"), ("power", noise, "force", 1)):
        pred = predicted_exponent(*args)
        assert (pred.exponent, pred.growth) == (None, "exponential")


def test_quartic_force_coupling_blows_up():
    assert predicted_exponent("power", "white", "force", 2).growth == "finite-time blow-up"
    assert predicted_exponent("power", "ou", "force", 2).growth == "finite-time blow-up"
    assert predicted_exponent("power", "harmonic", "force", 2).growth == "finite-time blow-up"
    assert predicted_exponent("power", "dichotomous", "force", 2).growth == "exponential"


@pytest.mark.parametrize(
    ("args", "starts"),
    [
        (("rigid", "white"), "potential='rigid' is not accepted"),
        (("pendulum", "pink"), "noise='pink' is not accepted"),
        (("pendulum", "white", "velocity"), "coupling='velocity' is not accepted"),
        (("pendulum", "white", "position"), "coupling='position' is not accepted"),
        (("power", "white", "force", 0), "power_n=0 is not accepted"),
        (("power", "white", "force", 2.5), "power_n=2.5 is not accepted"),
    ],
)
def test_prediction_refusals(args, starts):
    with pytest.raises(ValueError) as err:
        predicted_exponent(*args)
    assert str(err.value).startswith(starts) and "\n" not in str(err.value)


@pytest.mark.parametrize(("D", "omega"), [(1.0, 1.0), (0.1, 1.0), (2.0, 0.5), (1.0, 0.0)])
def test_white_harmonic_rate_is_the_moment_system_eigenvalue(D, omega):
    """d(<x^2>, <x Omega>, <Omega^2>)/dt = M (...): the growing eigenvalue of M (NOTES.md)."""
    M = np.array([[0.0, 2.0, 0.0], [-(omega**2), 0.0, 1.0], [D, -2.0 * omega**2, 0.0]])
    want = max(np.linalg.eigvals(M).real)
    assert harmonic_growth_rate("white", D=D, omega=omega) == pytest.approx(want, rel=1e-10)


def test_colored_harmonic_rate_tends_to_white_at_weak_noise():
    """S(2 omega)/(2 omega^2) -> D/(2 omega^2) as tau -> 0, the white rate at D << omega^3."""
    D, omega = 1e-3, 1.0
    white = harmonic_growth_rate("white", D=D, omega=omega)
    assert white == pytest.approx(D / (2 * omega**2), rel=1e-3)
    assert harmonic_growth_rate("ou", D=D, omega=omega, tau=1e-4) == pytest.approx(white, rel=2e-3)


@pytest.mark.parametrize("noise", ["ou", "dichotomous", "harmonic"])
def test_spectra_have_S0_D_and_variance_D_over_2tau(noise):
    D, tau = 1.3, 0.7
    assert spectral_density(noise, 0.0, D=D, tau=tau) == pytest.approx(D)
    var = quad(lambda nu: spectral_density(noise, nu, D=D, tau=tau), 0.0, np.inf)[0] / math.pi
    assert var == pytest.approx(D / (2 * tau), rel=1e-6)


def test_fit_rate_recovers_an_exponential_and_refuses_bad_windows():
    """<E> = exp(0.3 t) with independent 5 % batch noise at every time: the rate comes back
    within 4 jackknife SEs, and a rate off by 0.02 would be rejected (the SE is far smaller)."""
    from stochpend.exponents import fit_rate

    rng = np.random.default_rng(3)
    times = np.linspace(1.0, 20.0, 20)
    n_b, per = 50, 40
    counts = np.full((n_b, times.size), per)
    noise = 1.0 + 0.05 * rng.standard_normal((n_b, times.size))
    sums = per * np.exp(0.3 * times)[None, :] * noise
    ds = xr.Dataset(
        {"batch_sum_E": (("batch", "time"), sums), "batch_n_finite": (("batch", "time"), counts)},
        coords={"time": times}, attrs={"paths": n_b * per},
    )
    fit = fit_rate(ds, 5.0, 20.0)
    assert 0.0 < fit.se < 0.005
    assert abs(fit.exponent - 0.3) < Z_TOL * fit.se
    assert abs(fit.exponent - 0.32) > Z_TOL * fit.se
    with pytest.raises(ValueError, match=r"^t_min="):
        fit_rate(ds, 19.5, 20.0)


def test_quartic_position_heating_rate_matches_beta_functions():
    """A = (3/8)(D/tau^2) V_1/omega^2, V_1 = Var(x^2/2) on the orbit x^4/4 + Omega^2/2 = 1:
    with x = sqrt(2) u the time averages are Beta functions, <x^k> = 2^(k/2) B((k+1)/4, 1/2) /
    B(1/4, 1/2) -- independent of the quadrature in the code."""
    from scipy.special import beta

    from stochpend.theory.scaling import quartic_position_heating_rate

    m = {k: 2 ** (k / 2) * beta((k + 1) / 4, 0.5) / beta(0.25, 0.5) for k in (2, 4)}
    v1 = m[4] / 4 - m[2] ** 2 / 4
    for D, tau, omega in ((1.0, 1.0, 1.0), (0.3, 2.0, 1.7)):
        expected = 0.375 * D / tau**2 * v1 / omega**2
        got = quartic_position_heating_rate("ou", D=D, tau=tau, omega=omega)
        assert got == pytest.approx(expected, rel=1e-9)
    assert quartic_position_heating_rate("ou", D=1.0, tau=1.0, omega=1.0) == pytest.approx(0.0467, abs=5e-5)
    with pytest.raises(ValueError, match=r"^noise='white' is not accepted"):
        quartic_position_heating_rate("white", D=1.0, tau=1.0, omega=1.0)


def test_fit_slope_recovers_a_linear_law_with_an_offset():
    from stochpend.exponents import fit_slope

    rng = np.random.default_rng(5)
    times = np.geomspace(100.0, 1000.0, 9)
    n_b, per = 40, 25
    counts = np.full((n_b, times.size), per)
    sums = per * (5.0 + 0.05 * times)[None, :] * (1.0 + 0.03 * rng.standard_normal((n_b, times.size)))
    ds = xr.Dataset(
        {"batch_sum_E": (("batch", "time"), sums), "batch_n_finite": (("batch", "time"), counts)},
        coords={"time": times}, attrs={"paths": n_b * per},
    )
    fit = fit_slope(ds, 100.0, 1000.0)
    assert abs(fit.exponent - 0.05) < Z_TOL * fit.se and fit.se < 0.002
