"""Bit-for-bit guard for restructuring (issue 22) and every change that promises "no simulated
number changes": the output times and statistics of seven small runs (pendulum with OU, white,
dichotomous and harmonic noise; the quartic with position coupling; the harmonic oscillator; a
fixed step), stored in tests/golden/stats.npz by tests/golden/make_golden.py, must come out
identical. The bias estimate's variables are left out: issue 19 changed them on purpose.
The same numbers must come from every way of running them: the API, the CLI's simulate, a
checkpointed run stopped and resumed, and a sweep (the CUDA backend: test_golden_cuda.py).

The bits are those of any x86-64 machine with AVX2 and FMA, whatever its vector width: the
kernels keep IEEE semantics and the host arithmetic avoids numpy's CPU-dispatched loops
(stochpend.numerics._hostmath). ``make test-baseline`` runs this file again with the kernels compiled for
x86-64-v3 and numpy held to AVX2, as an AVX2-only machine computes (docs/development.md, "What
is bit-identical, and where"). Another kind of machine (no FMA, another C library) computes its
own last bits: there the statistical tests check the numbers, and these are skipped, saying why.

Regenerate only for a change that is meant to alter numbers, and say so in its commit."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import stochpend
from stochpend import cli, io
from stochpend.model.settings import SimulationConfig
from stochpend.runs import checkpoint
from stochpend.sweep import sweep
from tests._machine import golden_machine

GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "stats.npz"

pytestmark = pytest.mark.skipif(golden_machine() is not None, reason=f"the golden bits are x86-64's with AVX2, "
                                f"FMA and glibc; {golden_machine()}: the statistical tests check its numbers")

CASES = {
    "ou_lanes": dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=600, t_max=50.0, n_times=6, seed=1),
    "white": dict(noise="white", D=1.0, omega=1.0, paths=600, t_max=50.0, n_times=6, seed=2),
    "dichotomous": dict(noise="dichotomous", D=1.0, tau=1.0, omega=1.0, paths=400, t_max=30.0, n_times=5, seed=3),
    "harmonic_noise": dict(noise="harmonic", D=1.0, tau=1.0, omega_noise=1.5, omega=1.0, paths=400, t_max=30.0,
                           n_times=5, seed=4),
    "quartic_position": dict(potential="power", power_n=2, coupling="position", noise="ou", D=1.0, tau=1.0,
                             omega=1.0, paths=400, t_max=30.0, n_times=5, seed=5),
    "harmonic_osc": dict(potential="harmonic", noise="white", D=1.0, omega=1.0, paths=400, t_max=30.0, n_times=5,
                         seed=6),
    "fixed_step": dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=400, t_max=20.0, n_times=5, seed=7,
                       step_c=0.0, h_max=0.01),
}


def _expected(name: str) -> dict[str, np.ndarray]:
    with np.load(GOLDEN) as golden:
        expected = {k.split("/", 1)[1]: golden[k] for k in golden.files if k.startswith(name + "/")}
    assert len(expected) > 20, name
    return expected


def _assert_golden(name: str, variables, *, times: bool = True) -> None:
    """``variables[v]``: the run's values of every variable the fixture holds for ``name``
    (and its output times under ``"time"``, unless ``times`` is False)."""
    for variable, values in _expected(name).items():
        if variable == "time" and not times:
            continue
        assert variable in variables, (name, variable)
        assert np.array_equal(np.asarray(variables[variable]), values, equal_nan=True), (name, variable)


def _of(ds) -> dict[str, np.ndarray]:
    return {"time": ds["time"].values, **{v: ds[v].values for v in ds.data_vars}}


@pytest.mark.parametrize("name", list(CASES))
def test_statistics_are_bit_identical_to_golden(name):
    ds = stochpend.simulate(**CASES[name], bias_paths=0)
    _assert_golden(name, _of(ds))


def _cli_args(params: dict) -> list[str]:
    """simulate's options for simulate()'s keywords (repr: floats written to the last bit)."""
    names = {"power_n": "n"}
    return [a for k, v in params.items()
            for a in (f"--{names.get(k, k).replace('_', '-')}", v if isinstance(v, str) else repr(v))]


@pytest.mark.parametrize("name", list(CASES))
def test_cli_simulate_is_bit_identical_to_golden(tmp_path, name):
    out = tmp_path / f"{name}.nc"
    result = CliRunner().invoke(cli.app, ["simulate", *_cli_args(CASES[name]), "--bias-paths", "0", "--quiet",
                                          "--out", str(out)])
    assert result.exit_code == 0, result.output
    ds = io.open_results(out)  # through the file: NetCDF's encoding must keep every bit
    _assert_golden(name, _of(ds))


class _StopMidRun(checkpoint.FileCheckpointer):
    """Saves and raises KeyboardInterrupt (as tests/unit/test_checkpoint.py's StopAfter does) at
    the first kernel boundary after the second chunk's second output time: the resumed run then
    restores finished chunks' sums, a chunk's partial sums and its paths' state."""

    def maybe_save(self, state):
        if state.b0 > 0 and state.j >= 2:
            self.save(state)
            raise KeyboardInterrupt


CHUNK = 200  # paths per chunk: 400 paths run in two chunks, 600 in four


@pytest.mark.parametrize("name", list(CASES))
def test_checkpointed_run_stopped_and_resumed_is_bit_identical_to_golden(tmp_path, name):
    config = SimulationConfig.build(**CASES[name])
    path = tmp_path / "run.ckpt"
    cp = _StopMidRun(path, None, config=config, chunk_paths=CHUNK)
    with pytest.raises(KeyboardInterrupt):
        checkpoint.run_checkpointed(config, checkpoint_path=path, every_s=None, checkpointer=cp, chunk_paths=CHUNK)
    state = checkpoint.read(path).state
    assert (state.b0, state.j) == (CHUNK // config.batch_size, 2)
    ds = checkpoint.resume(path, out=None)
    assert ds.attrs["resumed"] == 1
    _assert_golden(name, _of(ds))


# A sweep stacks its sets' variables, so each sweep's sets have the same number of output times;
# fixed_step's other t_max gives per-set times.
SWEEPS = [["ou_lanes", "white"], ["dichotomous", "harmonic_noise", "quartic_position", "harmonic_osc", "fixed_step"]]


@pytest.mark.parametrize("sets", SWEEPS, ids=lambda sets: "+".join(sets))
def test_sweep_sets_are_bit_identical_to_golden(sets):
    pytest.importorskip("dask", reason="the `dask` extra is not installed (pip install 'stochpend[dask]')")
    assert {name for names in SWEEPS for name in names} == set(CASES)
    # Dask's threads and two blocks a set: a set's sums come from blocks run concurrently.
    ds = sweep({"case": [CASES[name] for name in sets]}, scheduler="threads", workers=2, tasks_per_set=2)
    assert ds.attrs["sweep_tasks"] == 2 * len(sets)
    for i, name in enumerate(sets):
        _assert_golden(name, {v: ds[v].values[i] for v in ds.data_vars if ds[v].dims[:1] == ("case",)},
                       times="time" in ds.data_vars)


def test_result_names_the_target_its_kernels_were_compiled_for():
    """Run in both passes (``make test`` and ``make test-baseline``): the attribute says which."""
    ds = stochpend.simulate(**CASES["white"], bias_paths=0)
    if os.environ.get("STOCHPEND_CPU_TARGET") == "baseline":
        assert ds.attrs["cpu_target"] == "x86-64-v3 (baseline)"
    else:
        import llvmlite.binding as ll

        wide = ll.get_host_cpu_features().get("avx512f", False)  # stochpend.numerics._cputarget
        assert ds.attrs["cpu_target"] == f"{ll.get_host_cpu_name()} (host{', 512-bit vectors' if wide else ''})"
