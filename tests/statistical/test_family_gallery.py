"""The family's gallery (issue 23 item 5): ``stochpend reproduce family-*``.

Each figure is run once at a tiny quick size (a few hundred paths, short times): its table has
rows of the common layout with finite values, errors and theory columns, and it draws. Each
figure's theory values are the functions of stochpend.theory.family (computed here again from
the runs' attributes). A FigureRun without the family's fields keeps the keyword arguments (so
the cache key) of the paper's figures, and ``all`` does not run the gallery.
"""

from __future__ import annotations

import math

import pytest

from stochpend.paper import reproduce as rep
from stochpend.paper.figures import CASES, COLUMNS, FIGURES, GALLERY, FigureRun
from stochpend.paper.figures import family_boltzmann as fb
from stochpend.paper.figures import family_kramers as fk
from stochpend.paper.figures import family_random_frequency as frf
from stochpend.paper.figures import family_washboard as fw
from stochpend.theory import family as fam

NAMES = ("family-boltzmann", "family-kramers", "family-washboard", "family-random-frequency")


@pytest.fixture(scope="module")
def result(tmp_path_factory: pytest.TempPathFactory) -> rep.ReproduceResult:
    return rep.reproduce("family", quick=True, paths=200, out=tmp_path_factory.mktemp("gallery"), threads=1)


def _datasets(result: rep.ReproduceResult, name: str) -> dict:
    import xarray as xr

    from stochpend import io

    out: dict[str, xr.Dataset] = {}
    for r in result.figures[name].runs:
        out[r.key] = io.open_results(r.path)
    return out


def test_names_and_all() -> None:
    assert tuple(GALLERY) == NAMES
    assert rep._figure_names("family") == list(NAMES)
    assert not set(rep._figure_names("all")) & set(NAMES)
    assert not set(GALLERY) & (set(FIGURES) | set(CASES))


def test_paper_runspec_kwargs_unchanged() -> None:
    s = FigureRun(key="k", label="l", noise="white", D=1.0, tau=None, omega=1.0, t_max=10.0, seed=1, paths=10)
    kw = s.simulate_kwargs()
    assert "dyn_params" not in kw and "observables" not in kw
    assert kw["theta0"] == "uniform" and kw["Omega0"] == 0.0
    fam_spec = FigureRun(key="k", label="l", noise="white", D=0.0, tau=None, omega=1.0, t_max=10.0, seed=1,
                       paths=10, params=(("additive_D", 1.0), ("gamma", 0.5)), observables=("displacement",))
    assert fam_spec.cache_key("v") != s.cache_key("v")
    assert fam_spec.simulate_kwargs()["dyn_params"] == {"additive_D": 1.0, "gamma": 0.5}


@pytest.mark.parametrize("name", NAMES)
def test_table_structure(result: rep.ReproduceResult, name: str) -> None:
    f = result.figures[name]
    assert f.png.is_file() and f.pdf.is_file() and f.table_csv.is_file()
    assert f.rows, name
    for row in f.rows:
        assert len(row.cells()) == len(COLUMNS)
        assert math.isfinite(row.prediction), (name, row.run, row.theory)
        assert math.isfinite(row.value), (name, row.run, row.quantity)
        assert math.isfinite(row.stderr) and row.stderr > 0, (name, row.run, row.quantity)
    assert "seed" in f.caption


def test_boltzmann_theory_is_family(result: rep.ReproduceResult) -> None:
    ds_all = _datasets(result, "family-boltzmann")
    th = fb.theory(ds_all)
    for key, ds in ds_all.items():
        D_a, g, w = float(ds.attrs["additive_D"]), float(ds.attrs["gamma"]), float(ds.attrs["omega"])
        assert th[key]["Omega2"] == fam.boltzmann_mean_Omega2(D_a=D_a, gamma=g)
        assert th[key]["E"] == fam.boltzmann_pendulum_mean_E(D_a=D_a, gamma=g, omega=w)
        assert th[key]["T"] == pytest.approx(D_a / (2 * g))


def test_kramers_theory_is_family(result: rep.ReproduceResult) -> None:
    ds_all = _datasets(result, "family-kramers")
    th = fk.theory(ds_all)
    for key, ds in ds_all.items():
        a = {"D_a": float(ds.attrs["additive_D"]), "gamma": float(ds.attrs["gamma"]), "omega": float(ds.attrs["omega"])}
        assert th[key]["kramers"] == fam.kramers_rate_spatial_diffusion(**a)
        assert th[key]["melnikov_meshkov"] == fam.kramers_rate_melnikov_meshkov(**a)
        assert th[key]["regime"] == fam.kramers_regime(**a) == "spatial diffusion"


def test_washboard_theory_is_family(result: rep.ReproduceResult) -> None:
    ds_all = _datasets(result, "family-washboard")
    th = fw.theory(ds_all)
    g, w = fw.CONFIG["gamma"], fw.CONFIG["omega"]
    assert th["locking"] == fam.locking_torque(omega=w)
    assert th["retrapping"] == fam.retrapping_torque(gamma=g, omega=w)
    assert fw.tilted_barrier(0.0, w) == fam.pendulum_barrier(omega=w)
    assert fw.tilted_barrier(fam.locking_torque(omega=w), w) == 0.0
    for F, v in th["F/gamma"].items():
        assert v == fam.running_velocity(F=F, gamma=g)
        # The noiseless orbit: 0 below the retrapping torque, then close to F/gamma (second-order
        # perturbation: gamma v = F - omega^4 gamma/(2 v (gamma^2 + v^2))).
        if F < th["retrapping"]:
            assert th["orbit"][F] == 0.0
        elif F >= 0.3:
            u = F / g
            assert th["orbit"][F] == pytest.approx(u - w**4 / (2 * u * (g * g + u * u)), rel=2e-3)


def test_random_frequency_theory_is_family(result: rep.ReproduceResult) -> None:
    ds_all = _datasets(result, "family-random-frequency")
    th = frf.theory(ds_all)
    g, w = frf.CONFIG["gamma"], frf.CONFIG["omega"]
    assert th["D_c"] == fam.random_frequency_threshold(gamma=g, omega=w) == 2 * g * w * w
    assert th["D_typ"] == fam.random_frequency_typical_threshold(gamma=g, omega=w) > th["D_c"]
    for D in frf.CONFIG["D"]:
        assert th["moment"][D] == fam.random_frequency_moment_growth_rate(D=D, gamma=g, omega=w)
        assert th["typical"][D] == 2 * fam.random_frequency_lyapunov(D=D, gamma=g, omega=w)
