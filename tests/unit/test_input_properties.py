"""Property-based validation tests (hypothesis): whatever the input, the answer is a valid
configuration or one ``ValueError`` line naming a parameter -- never another exception.

Deterministic (``derandomize=True``) and bounded, so that CI sees the same examples every run.
"""

from __future__ import annotations

import math
import os
import re
from unittest import mock

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from typer.testing import CliRunner

from stochpend.cli import app
from stochpend.model.settings import SimulationConfig
from stochpend.runs import resources

#: 200 examples each (a few seconds); STOCHPEND_HYPOTHESIS_EXAMPLES=5000 for a deeper search.
SETTINGS = settings(max_examples=int(os.environ.get("STOCHPEND_HYPOTHESIS_EXAMPLES", "200")), deadline=None,
                    derandomize=True, database=None, suppress_health_check=[HealthCheck.too_slow])

BUILD_PARAMS = (
    "noise", "D", "tau", "omega", "paths", "t_max", "times", "n_times", "seed", "theta0", "Omega0",
    "xi0", "h_max", "step_c", "hist_bins", "hist_E_max", "n_batches", "potential", "power_n",
    "coupling", "omega_noise",
)

# -- values ------------------------------------------------------------------------------------
absurd_numbers = st.sampled_from([
    0, -1, 1, 2, 0.0, -0.0, -1.5, 0.5, 1e-310, 5e-324, 1e-300, 1e300, 1.7e308, -1e308,
    math.nan, math.inf, -math.inf, 2**63, 2**64, -(2**64), 10**30, 10**400, 1e15, 3.5,
    np.float32("nan"), np.float64(2.0), np.int64(-3), np.int64(7), np.float32(1e38), np.uint64(2**63),
])
wrong_types = st.sampled_from([
    None, True, False, "", "abc", "1e3", "nan", "inf", "1,2", "uniform", "stationary", "ou", b"12",
    [], [1.0, 2.0], [[1.0]], [2.0, 1.0], {"a": 1}, (1, 2), 1 + 2j, np.complex128(1 + 1j),
    np.arange(3.0), np.array([]), np.array(5.0), np.array([[1.0, 2.0]]), object(), {1, 2},
    float, "pendulum", "power", "harmonic", "position", "force", "white", "dichotomous",
])
floats = st.floats(allow_nan=True, allow_infinity=True)
integers = st.integers(min_value=-(2**70), max_value=2**70)
sensible = {
    "noise": st.sampled_from(["ou", "white", "dichotomous", "harmonic"]),
    "paths": st.integers(1, 10**6),
    "t_max": st.floats(1e-3, 1e4),
    "n_times": st.integers(1, 50),
    "times": st.lists(st.floats(0.0, 1e3), min_size=1, max_size=5).map(sorted),
    "seed": st.integers(0, 2**64 - 1),
    "potential": st.sampled_from(["pendulum", "harmonic", "power"]),
    "coupling": st.sampled_from(["force", "position"]),
    "power_n": st.integers(1, 5),
    "theta0": st.one_of(st.just("uniform"), st.floats(-4.0, 4.0)),
    "xi0": st.one_of(st.just("stationary"), st.floats(-3.0, 3.0)),
    "hist_bins": st.integers(1, 1000),
    "n_batches": st.integers(2, 200),
}


def value_for(name: str) -> st.SearchStrategy:
    options = [absurd_numbers, wrong_types, floats, integers]
    if name in sensible:
        options = [sensible[name], sensible[name], *options]
    else:
        options = [st.floats(0.01, 10.0), *options]
    return st.one_of(*options)


@st.composite
def build_kwargs(draw: st.DrawFn) -> dict:
    names = draw(st.lists(st.sampled_from(BUILD_PARAMS), max_size=6, unique=True))
    return {name: draw(value_for(name)) for name in names}


ONE_LINE = re.compile(r"^(?P<name>[A-Za-z_][A-Za-z0-9_]*)=.* is not accepted: .+$")


def assert_refusal(exc: ValueError, names: tuple[str, ...]) -> None:
    message = str(exc)
    assert "\n" not in message, f"not one line: {message!r}"
    m = ONE_LINE.match(message)
    assert m is not None, f"not 'name=value is not accepted: ...': {message!r}"
    assert m.group("name") in names, f"names no parameter: {message!r}"


@SETTINGS
@given(build_kwargs())
def test_build_accepts_or_refuses_in_one_line(kwargs):
    try:
        config = SimulationConfig.build(**kwargs)
    except ValueError as exc:
        assert_refusal(exc, BUILD_PARAMS)
        return
    assert isinstance(config, SimulationConfig)
    assert config.paths >= 1 and config.n_batches >= 1 and len(config.times) >= 1
    assert all(math.isfinite(e) for e in config.hist_E_max)
    # The resource check reads any valid configuration: an estimate or a one-line refusal.
    try:
        est = resources.check(config)
    except ValueError as exc:
        assert_refusal(exc, ("paths", "t_max", "h_max", "hist_bins", "n_times", "n_batches", "chunk_paths"))
    else:
        assert est.memory_bytes > 0 and est.min_path_steps > 0


# -- the command line --------------------------------------------------------------------------
#: simulate's options and the names its refusals may use (API names and option names).
CLI_OPTIONS = {
    "--noise": "noise", "--D": "D", "--tau": "tau", "--omega-noise": "omega_noise", "--omega": "omega",
    "--potential": "potential", "--n": "power_n", "--coupling": "coupling", "--paths": "paths",
    "--t-max": "t_max", "--n-times": "n_times", "--times": "times", "--seed": "seed", "--theta0": "theta0",
    "--Omega0": "Omega0", "--h-max": "h_max", "--step-c": "step_c", "--hist-bins": "hist_bins",
    "--backend": "backend", "--precision": "precision", "--threads": "threads",
    "--checkpoint-every": "checkpoint_every", "--max-path-steps": "max_path_steps",
}
CLI_NAMES = (*CLI_OPTIONS.values(), "n", "n_batches", "chunk_paths")

cli_text = st.one_of(
    st.sampled_from([
        "0", "1", "-1", "2", "10", "100", "0.5", "-0.0", "1e15", "1e15.5", "1.5", "1e3", "2e0", "1E2",
        "nan", "inf", "-inf", "NaN", "1e400", "-1e400", "1e-400", "5e-324", "abc", "", " ", "1,2",
        "10,100", "2,1", "1,,2", "uniform", "stationary", "ou", "white", "harmonic", "dichotomous",
        "pendulum", "power", "position", "force", "cpu", "auto", "float64", "float32", "5m", "0s",
        "9" * 30, "0x10", "1_000", "+5", "--paths", "1e308", "99999999999999999999",
    ]),
    st.text(alphabet="0123456789.e-+,naifx ", max_size=8),
    st.integers(-(2**70), 2**70).map(str),
    st.floats().map(repr),
)


@st.composite
def cli_args(draw: st.DrawFn) -> list[str]:
    opts = draw(st.lists(st.sampled_from(sorted(CLI_OPTIONS)), max_size=5, unique=True))
    args = ["simulate", "--paths", "10", "--t-max", "1", "--quiet"]
    for opt in opts:
        args += [opt, draw(cli_text)]
    return args


class _Accepted(Exception):
    """Raised instead of running: validation accepted the input."""


def _accept(*args, **kwargs):
    raise _Accepted


@pytest.fixture(scope="module")
def runner():
    return CliRunner()


@SETTINGS
@given(args=cli_args())
def test_cli_simulate_accepts_or_refuses_in_one_line(runner, args):
    with mock.patch("stochpend.runs.lifecycle.execute", _accept), \
            mock.patch("stochpend.cli._scale.simulate_with_checkpoint", _accept):
        result = runner.invoke(app, args)
    if isinstance(result.exception, _Accepted):
        return
    assert result.exit_code == 2, (args, result.output, result.exception)
    assert "Traceback" not in result.output
    lines = [ln for ln in result.output.splitlines() if ln.strip()]
    assert len(lines) == 1, (args, result.output)
    line = lines[0]
    assert line.startswith("error: "), (args, line)
    named = re.match(r"error: (?:--)?([A-Za-z_][A-Za-z0-9_-]*)", line)
    assert named is not None and named.group(1).replace("-", "_") in CLI_NAMES, (args, line)
