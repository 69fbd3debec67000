"""The pieces of "pieces declare their parameters" (issue 22, item 2) that need no kernel: a
:class:`~stochpend.model.parameters.Parameter` checks its values and says what it accepts; a noise's
own parameters are resolved with their defaults, an unknown one refused in one line naming it;
plugins load only by name from the command line, and a bad one is one line; ``--param`` is
parsed NAME=VALUE. The whole path through the kernels is tests/unit/test_declared_parameters.py.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest
from typer.testing import CliRunner

from stochpend import cli, plugins
from stochpend.cli._common import parse_params
from stochpend.model.parameters import Parameter, describe, own, resolve

TAU1 = Parameter("tau1", 1.0, "correlation time of the first component", low=0.0, low_open=True)
WEIGHT = Parameter("weight", 0.5, "share of S(0) carried by the first component", low=0.0, high=1.0)
NOISE = SimpleNamespace(name="toy", parameters=("D", TAU1, WEIGHT))


def test_a_parameter_checks_its_range_and_names_itself():
    assert TAU1.check(0.25) == 0.25 and WEIGHT.check(1) == 1.0 and WEIGHT.check("0.5") == 0.5
    for bad in (0.0, -1.0, math.inf, math.nan, "x", None, True, 1j):
        with pytest.raises(ValueError, match=r"^tau1=.* is not accepted: a finite number in \(0, inf\) "
                                             r"\(correlation time of the first component\)$"):
            TAU1.check(bad)
    with pytest.raises(ValueError, match=r"weight=1.5 is not accepted: a finite number in \[0, 1\]"):
        WEIGHT.check(1.5)


@pytest.mark.parametrize("name", ["tau", "omega", "1x", "", "a-b", "paths"])
def test_a_parameter_may_not_take_a_run_setting_s_name(name):
    with pytest.raises(ValueError, match="is not accepted"):
        Parameter(name, 1.0, "x")


def test_a_declaration_whose_default_it_refuses_is_refused():
    with pytest.raises(ValueError, match="tau1=0.0 is not accepted"):
        Parameter("tau1", 0.0, "x", low=0.0, low_open=True)


def test_resolve_fills_defaults_sorts_and_refuses_unknown_names():
    assert own(NOISE) == (TAU1, WEIGHT)
    assert resolve(NOISE, None) == (("tau1", 1.0), ("weight", 0.5))
    assert resolve(NOISE, {"weight": "0.25"}) == (("tau1", 1.0), ("weight", 0.25))
    assert resolve(NOISE, [["tau1", 2.0]]) == (("tau1", 2.0), ("weight", 0.5))  # a checkpoint's JSON
    assert describe(resolve(NOISE, {"tau1": 0.5})) == "tau1=0.5, weight=0.5"
    with pytest.raises(ValueError, match=r"^tau2=3 is not accepted: not a parameter of noise 'toy' "
                                         r"\(its own parameters: tau1, weight\)$"):
        resolve(NOISE, {"tau2": 3})
    with pytest.raises(ValueError, match="noise_params=5 is not accepted"):
        resolve(NOISE, 5)
    assert resolve(SimpleNamespace(name="ou"), {}) == ()


def test_a_run_refuses_a_parameter_its_noise_does_not_declare():
    import stochpend

    with pytest.raises(ValueError, match=r"^tau1=0.5 is not accepted: not a parameter of noise 'ou' "
                                         r"\(its own parameters: none\)$"):
        stochpend.simulate(noise="ou", paths=10, t_max=1.0, n_times=2, tau1=0.5)


@pytest.mark.parametrize("values, expected", [(["a=1", "b = 2.5"], {"a": "1", "b": "2.5"}), (None, {})])
def test_param_options_are_name_value_pairs(values, expected):
    assert parse_params(values) == expected


@pytest.mark.parametrize("values, message", [(["a"], "NAME=VALUE"), (["=1"], "NAME=VALUE"), (["a="], "NAME=VALUE"),
                                             (["a=1", "a=2"], "a is given twice")])
def test_a_malformed_param_option_is_one_line(values, message):
    with pytest.raises(ValueError, match=message):
        parse_params(values)


@pytest.mark.parametrize("name, message", [
    ("no_such_module_xyz", "no installed stochpend plugin or module of that name"),
    ("os;rm", "an installed stochpend plugin or a module's dotted name"),
    ("raising_plugin_xyz", "importing it raised RuntimeError: this plugin refuses to load"),
])
def test_a_plugin_that_cannot_load_is_one_line(name, message, tmp_path, monkeypatch):
    (tmp_path / "raising_plugin_xyz.py").write_text("raise RuntimeError('this plugin\\nrefuses to load')\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(ValueError, match=message) as info:
        plugins.load(name)
    assert "\n" not in str(info.value) and name not in plugins.loaded()


def test_a_plugin_loads_once_and_is_remembered(tmp_path, monkeypatch):
    (tmp_path / "plugin_once.py").write_text("import builtins\nbuiltins.STOCHPEND_TEST_LOADS = "
                                             "getattr(builtins, 'STOCHPEND_TEST_LOADS', 0) + 1\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    # Forgotten after the test: a sweep's Dask workers load every plugin this process loaded, and
    # they cannot import this one from the test's temporary directory (a later test in this
    # process, on this xdist worker, would be refused).
    monkeypatch.setattr(plugins, "_LOADED", list(plugins.loaded()))
    import builtins

    plugins.load("plugin_once")
    plugins.load("plugin_once")
    assert builtins.STOCHPEND_TEST_LOADS == 1 and "plugin_once" in plugins.loaded()


def test_the_cli_refuses_a_bad_plugin_and_a_bad_param_in_one_line():
    runner = CliRunner()
    done = runner.invoke(cli.app, ["simulate", "--plugin", "no_such_module_xyz", "--paths", "10"])
    assert done.exit_code == 2 and "--plugin 'no_such_module_xyz' is not accepted" in done.output
    done = runner.invoke(cli.app, ["simulate", "--param", "tau1", "--paths", "10"])
    assert done.exit_code == 2 and "--param 'tau1' is not accepted: NAME=VALUE" in done.output
    done = runner.invoke(cli.app, ["simulate", "--param", "tau1=2", "--paths", "10"])
    assert done.exit_code == 2 and "not a parameter of noise 'ou'" in done.output
