"""User-defined models (stochpend.models): same kernels, same numbers, same outputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

import stochpend
from stochpend import models
from stochpend.models import Model
from tests.unit._user_models import DOUBLE_WELL, USER_PENDULUM, register_all

register_all()

_KW = dict(D=1.0, tau=1.0, paths=400, t_max=20.0, n_times=4, seed=11, n_batches=8)


@pytest.mark.parametrize("noise", ["ou", "white", "dichotomous", "harmonic"])
def test_user_pendulum_is_the_builtin_pendulum_bit_for_bit(noise, monkeypatch):
    """The user's pendulum runs through the same integrator, noise and statistics code: every
    output is identical to the built-in pendulum's run with the same math (the C library's
    sin; only the names in attrs differ). By default the built-in pendulum with OU or white
    noise runs the branch-free fast-math sin in SIMD lanes, which the user's ``math.sin``
    cannot: there the two agree to rounding (relative 1e-9), not bit for bit."""
    default = stochpend.simulate(noise=noise, **_KW)
    from stochpend.engine import cpu
    from stochpend.engine.integrator import KernelSpec

    monkeypatch.setattr(cpu, "spec_for", lambda config, precision="float64":
                        KernelSpec.of(config, precision=precision))
    a = stochpend.simulate(noise=noise, **_KW)
    b = stochpend.simulate(noise=noise, potential=USER_PENDULUM.name, **_KW)
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.data_vars:
        np.testing.assert_array_equal(a[name].values, b[name].values, err_msg=name)
    assert b.attrs["potential"] == "user-pendulum"
    assert "user-defined" in b.attrs["model"]
    for name in ("mean_E", "mean_E2", "mean_cos_theta"):
        if name in default:
            np.testing.assert_allclose(default[name].values, b[name].values, rtol=1e-9,
                                       atol=1e-12, err_msg=name)
    assert a.attrs["kernel"].endswith("/libm")
    simd = noise in ("ou", "white")
    assert default.attrs["kernel"].endswith("/fast" if simd else "/libm")


def test_double_well_conserves_energy_without_noise():
    """D = 0: Stormer-Verlet keeps the double well's energy to O(h**2) (here 1e-4 relative)."""
    theta0, Omega0 = 0.3, 1.2
    E0 = 0.5 * Omega0**2 + DOUBLE_WELL.potential(theta0)
    ds = stochpend.simulate(noise="white", D=0.0, potential="double-well", theta0=theta0,
                            Omega0=Omega0, paths=2, t_max=200.0, n_times=5, seed=1, n_batches=2,
                            h_max=0.01, step_c=0.0)
    assert np.all(np.abs(ds.mean_E.values - E0) < 1e-4 * abs(E0))
    # ... and the histogram's lower edge is the well's bottom, omega**2 min U = -1/4.
    assert ds.E_bin_edges.values[0, 0] == pytest.approx(-0.25, rel=1e-6)


def test_double_well_with_position_noise_heats_up():
    """With the noise on x the double well heats (<E> grows) and no path escapes."""
    ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, potential="double-well",
                            coupling="position", paths=2000, t_max=50.0, times=[5.0, 50.0],
                            seed=3)
    E, se = ds.mean_E.values, ds.mean_E_stderr.values
    assert (E[1] - E[0]) / math.hypot(se[0], se[1]) > 4
    assert int(ds.nonfinite_paths[-1]) == 0


def test_unregistered_and_bad_models_are_refused_in_one_line():
    with pytest.raises(ValueError, match=r"^potential='nope' is not accepted"):
        stochpend.simulate(potential="nope", paths=10, t_max=1.0)
    with pytest.raises(ValueError, match=r"^name='pendulum' is not accepted"):
        Model(name="pendulum", potential=math.cos, force=math.sin)
    with pytest.raises(ValueError, match=r"^force is not accepted"):
        Model(name="bad", potential=math.cos, force=lambda x: 1.0 / (x - 0.5))
    with pytest.raises(ValueError, match=r"^precision='float32' is not accepted"):
        stochpend.simulate(potential="double-well", paths=10, t_max=1.0, precision="float32")
    with pytest.raises(ValueError, match=r"^coupling='position' is not accepted"):
        stochpend.simulate(potential="user-pendulum", coupling="position", paths=10, t_max=1.0)


def test_registry_round_trip():
    m = Model(name="tmp-harmonic", potential=lambda x: 0.5 * x * x, force=lambda x: x)
    models.register(m)
    try:
        assert models.get("tmp-harmonic") is m and "tmp-harmonic" in models.names()
        # Fixed steps: the built-in harmonic oscillator's step control uses its orbit, a user
        # model's the instantaneous state (docs/models.md).
        ds = stochpend.simulate(noise="ou", potential="tmp-harmonic", paths=50, t_max=2.0,
                                n_times=2, seed=1, n_batches=2, step_c=0.0)
        ref = stochpend.simulate(noise="ou", potential="harmonic", paths=50, t_max=2.0,
                                 n_times=2, seed=1, n_batches=2, step_c=0.0)
        np.testing.assert_array_equal(ds.mean_E.values, ref.mean_E.values)
    finally:
        models.unregister("tmp-harmonic")
    assert models.get("tmp-harmonic") is None


def test_the_docs_example_runs_as_written(capsys):
    """docs/models.md's user-model example, executed verbatim: it must run and print a finite,
    growing <E> with no escaped path (the noise is on x, so the double well cannot blow up)."""
    import re
    from pathlib import Path

    text = (Path(__file__).parents[2] / "docs" / "models.md").read_text(encoding="utf-8")
    block = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    try:
        exec(compile(block, "docs/models.md", "exec"), {})
    finally:
        models.unregister("double-well")
        register_all()
    out = capsys.readouterr().out
    assert out.strip().endswith(" 0")
    numbers = [float(v) for v in re.findall(r"[-+]?\d+\.\d+(?:e[-+]?\d+)?", out)]
    means = numbers[:4]
    assert all(math.isfinite(v) for v in means) and means[-1] > means[0]


def test_each_model_gets_its_own_functions_even_when_ids_are_reused():
    """Built functions are cached per oscillator object: a model created after another was
    dropped (its id free for reuse) never gets the dropped model's functions."""
    import gc

    # Late in a session the heap holds millions of objects (compiled kernels): 59 full
    # collections of it took ~55 s. Frozen, they are skipped; only the objects made here (each
    # model and its cycles) are examined, and freed as before.
    gc.freeze()
    try:
        for c in range(1, 60):
            m = Model(name=f"tmp-linear-{c}", potential=lambda x, c=c: c * x * x, force=lambda x, c=c: 2 * c * x)
            assert m.oscillator.functions.potential(1.0, (0.0,)) == c
            del m
            gc.collect()
    finally:
        gc.unfreeze()
