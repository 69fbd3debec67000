"""The family's terms as a table (issue 33, item 4): each entry's parameters and step bound.

The tests walk the table, so a new term's parameters are checked against the family's
declaration and record, its bound against its rate, and the engine outside the step is checked
to hold no code of its own for any term. The kicks are still written in the step (the lanes'
vectorization, stochpend.terms): the step's kick is pinned to today's order of operations.
"""

from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import numpy as np
import pytest

from stochpend import terms
from stochpend.engine import integrator
from stochpend.model import dynamics

SRC = Path(integrator.__file__).parents[1]  # the package root


def _record(values: dict[str, float]) -> tuple[float, ...]:
    return tuple(float(values[name]) for name in dynamics.RECORD)


def test_the_family_declares_the_tables_parameters_first_and_reads_them_by_name():
    table_names = tuple(p.name for term in terms.TABLE for p in term.parameters)
    assert dynamics.names()[:len(table_names)] == table_names
    assert dynamics.RECORD[:len(table_names)] == table_names
    assert all(dynamics.RECORD[dynamics.POSITION[name]] == name for name in dynamics.RECORD)
    assert {term.name: term.switch for term in terms.TABLE}.items() <= dynamics.TERMS.items()
    assert {term.name for term in terms.TABLE if term.moves_rest} <= dynamics.MOVES_REST
    assert all(term.coupling in terms.COUPLINGS for term in terms.TABLE)


def test_the_bounds_are_the_terms_rates_and_a_term_off_bounds_nothing():
    rng = np.random.default_rng(5)
    for _ in range(20):
        on = tuple(term for term in terms.TABLE if rng.random() < 0.6)
        values = {name: float(rng.uniform(0.1, 20.0)) for name in dynamics.RECORD}
        h_max, c = 0.5, float(rng.uniform(0.05, 1.0))
        expected = min([h_max, *(c / values[term.rate] for term in on if term.rate is not None)])
        h = integrator._term_bounds(on)(h_max, c, _record(values))
        assert h == pytest.approx(expected, rel=1e-15)


def test_the_steps_kick_keeps_its_order_of_operations_bit_for_bit():
    """The step with every term on against its kick written out in today's order (the force,
    the noise times G, the modulation times G, minus the torque, minus the drive), its record
    read by name: each operation and their order kept, so the numbers are those of before."""
    on = frozenset({*(term.name for term in terms.TABLE), "additive"})
    step = integrator.build(integrator.spec("white", "harmonic", "force", adaptive=False, terms=on)).family_step
    rng = np.random.default_rng(11)
    for _ in range(50):
        values = {name: float(rng.uniform(0.1, 3.0)) for name in dynamics.RECORD}
        d = _record(values)
        x, Om, h, I, t0, za = (float(v) for v in rng.uniform(-2.0, 2.0, 6))
        h = abs(h) / 10
        x_half = x + 0.5 * h * Om
        kick = 1.0 * h * x_half
        kick += I * x_half
        nu_p = values["parametric_frequency"]
        kick += (2.0 * values["parametric_amplitude"] / nu_p * math.cos(nu_p * (t0 + 0.5 * h))
                 * math.sin(0.5 * nu_p * h)) * x_half
        kick -= values["torque"] * h
        nu = values["drive_frequency"]
        kick -= (2.0 * values["drive_amplitude"] / nu * math.cos(nu * (t0 + 0.5 * h) + values["drive_phase"])
                 * math.sin(0.5 * nu * h))
        m = math.expm1(-values["gamma"] * h)
        Omega_mid = (1.0 + m) * (Om - 0.5 * kick) + values["sigma_a"] * math.sqrt(-m * (2.0 + m)) * za
        Omega_new = Omega_mid - 0.5 * kick
        assert step(x, Om, h, 1.0, I, (0.0,), t0, h, za, d) == (x_half + 0.5 * h * Omega_new, Omega_new)


def _engine_words(path: Path) -> set[str]:
    """The identifiers, attribute names and string constants of ``path`` (docstrings left out),
    lowercased."""
    tree = ast.parse(path.read_text())
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.FunctionDef, ast.ClassDef)) and node.body
                  and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}
    words = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            words.add(node.id)
        elif isinstance(node, ast.Attribute):
            words.add(node.attr)
        elif isinstance(node, ast.arg):
            words.add(node.arg)
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            words.add(node.value)
    return {w.lower() for w in words}


#: The engine outside the step: its loops' drivers, the backends, the settings' checks (the step,
#: integrator.py, writes the kicks: stochpend.terms says why).
ENGINE = ("model/settings.py", "engine/runner.py", "runs/bias.py", "runs/multilevel.py", "engine/cpu.py",
          "engine/cuda.py", "engine/layout.py")
#: The damping is the step's Ornstein-Uhlenbeck flow, which the step writes (terms/damping.py).
O_FLOW = {"damping", "gamma"}


@pytest.mark.parametrize("module", ENGINE)
def test_the_engine_holds_no_code_of_a_table_term(module):
    words = _engine_words(SRC / module)
    parameters = {p.name for term in terms.TABLE for p in term.parameters} - O_FLOW
    found = sorted({(name, w) for name in parameters for w in words if name in w}
                   | {(term.name, w) for term in terms.TABLE if term.name not in O_FLOW for w in words
                      if term.name in re.findall(r"[a-z0-9]+", w)})
    assert found == [], f"{module}: a term's code belongs in stochpend/model/terms/ (its entry of terms.TABLE)"
