"""The family's terms as a table (issue 33, item 4): each entry's kick, bound and parameters.

A new term is its file in ``stochpend/terms/``, its entry in ``terms.TABLE`` and its test: the
tests here walk the table, so its kick is checked against the exact integral of its integrand
over a step (scipy's quad), its bound against its rate and its parameters against the family's
declaration, and the engine is checked to hold no code of its own for any term.
"""

from __future__ import annotations

import ast
import math
import re
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import quad

from stochpend import dynamics, integrator, terms
from stochpend.mathlib import LIBM

KICKING = [term for term in terms.TABLE if term.kick is not None]
SRC = Path(integrator.__file__).parent


def _values(term, rng) -> dict[str, float]:
    """Every parameter of the record at its default, ``term``'s own drawn in [0.3, 3]."""
    values = {name: p.default for name, p in ((p.name, p) for p in dynamics.FAMILY.parameters)}
    values.update({p.name: float(rng.uniform(0.3, 3.0)) for p in term.parameters})
    values["sigma_a"] = 0.0
    return values


def _record(values: dict[str, float]) -> tuple[float, ...]:
    return tuple(float(values[name]) for name in dynamics.RECORD)


def test_the_family_declares_the_tables_parameters_first_and_reads_them_by_name():
    table_names = tuple(p.name for term in terms.TABLE for p in term.parameters)
    assert dynamics.names()[:len(table_names)] == table_names
    assert dynamics.RECORD[:len(table_names)] == table_names
    assert all(dynamics.RECORD[dynamics.POSITION[name]] == name for name in dynamics.RECORD)
    assert {term.name: term.switch for term in terms.TABLE}.items() <= dynamics.TERMS.items()
    assert {term.name for term in terms.TABLE if term.moves_rest} <= dynamics.MOVES_REST


def _integral(term, values: dict[str, float], t0: float, h: float) -> float:
    """The integrand's integral over [t0, t0 + h], by quadrature over s = t - t0 in [0, h] (so
    that the step's length is h, not fl(t0 + h) - t0)."""
    return quad(lambda s: term.integrand(t0 + s, values), 0.0, h, epsabs=1e-14 * h, epsrel=1e-12)[0]


@pytest.mark.parametrize("term", KICKING, ids=lambda term: term.name)
def test_each_kick_is_the_exact_integral_of_its_integrand_over_the_step(term):
    rng = np.random.default_rng(33)
    kick = term.kick(np.float64, LIBM, dynamics.POSITION)
    for _ in range(20):
        values = _values(term, rng)
        t0, h = float(rng.uniform(-50.0, 50.0)), float(rng.choice([1e-6, 1e-3, 0.05, 0.7]))
        exact = _integral(term, values, t0, h)
        got = kick(0.3, t0, h, _record(values))
        assert got == pytest.approx(exact, rel=1e-10, abs=1e-12 * h), (term.name, values, t0, h)


@pytest.mark.parametrize("term", KICKING, ids=lambda term: term.name)
def test_each_kick_compiles_to_its_own_numbers(term):
    import numba

    kick = term.kick(np.float64, LIBM, dynamics.POSITION)
    compiled = numba.njit(kick)
    values = _values(term, np.random.default_rng(7))
    d = _record(values)
    for t0, h in ((0.0, 0.1), (12.5, 1e-4), (-3.0, 0.9)):
        assert compiled(0.0, t0, h, d) == pytest.approx(kick(0.0, t0, h, d), rel=1e-14)


def test_the_bounds_are_the_terms_rates_and_a_term_off_bounds_nothing():
    rng = np.random.default_rng(5)
    for _ in range(20):
        on = tuple(term for term in terms.TABLE if rng.random() < 0.6)
        values = {name: float(rng.uniform(0.1, 20.0)) for name in dynamics.RECORD}
        h_max, c = 0.5, float(rng.uniform(0.05, 1.0))
        expected = min([h_max, *(c / values[term.rate] for term in on if term.rate is not None)])
        h = integrator._term_bounds(on)(h_max, c, _record(values))
        assert h == pytest.approx(expected, rel=1e-15)


def test_the_step_composes_the_kicks_as_it_always_did_bit_for_bit():
    """The step with every term on against its kick written out in today's order (the force,
    the noise times G, the modulation times G, minus the torque, minus the drive): the table's
    composition keeps each operation and their order, so the numbers are those of before."""
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


#: The engine: the step and its loops, the backends, the settings' checks.
ENGINE = ("integrator.py", "params.py", "runner.py", "bias.py", "multilevel.py", "_backends/cpu.py",
          "_backends/cuda.py", "_backends/layout.py")
#: The damping is the step's Ornstein-Uhlenbeck flow, which the step writes (terms/damping.py).
O_FLOW = {"damping", "gamma"}


@pytest.mark.parametrize("module", ENGINE)
def test_the_engine_holds_no_code_of_a_table_term(module):
    words = _engine_words(SRC / module)
    parameters = {p.name for term in terms.TABLE for p in term.parameters} - O_FLOW
    found = sorted({(name, w) for name in parameters for w in words if name in w}
                   | {(term.name, w) for term in terms.TABLE if term.name not in O_FLOW for w in words
                      if term.name in re.findall(r"[a-z0-9]+", w)})
    assert found == [], f"{module}: a term's code belongs in stochpend/terms/ (its entry of terms.TABLE)"
