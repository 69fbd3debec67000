"""The predictions table (stochpend.theory.table)."""

from __future__ import annotations

import dataclasses
import math

import pytest
from scipy.special import gamma

from stochpend.theory import Prediction, format_table, predictions, solve_bfpe


def _find(rows, regime_part: str, quantity: str) -> Prediction:
    hits = [r for r in rows if regime_part in r.regime and r.quantity == quantity]
    assert len(hits) == 1, (regime_part, quantity, [(r.regime, r.quantity) for r in rows])
    return hits[0]


def test_white_rows() -> None:
    D, t = 2.0, 3.0
    rows = predictions(noise="white", D=D, t=t, omega=1.0)
    assert [r.quantity for r in rows] == ["<E>", "<E^2>", "S", "F"]
    assert _find(rows, "white", "<E>").value == pytest.approx(D * t / 4, rel=1e-14)
    assert _find(rows, "white", "<E^2>").value == pytest.approx(3 * (D * t) ** 2 / 16, rel=1e-14)
    assert _find(rows, "white", "S").value == pytest.approx(5 / math.sqrt(3), rel=1e-12)
    assert _find(rows, "white", "F").value == pytest.approx(35 / 3, rel=1e-12)
    assert {r.equation for r in rows} == {"eq:scalEblanc", "eq:pdfEblanc", "eq:skewEblanc", "eq:flatEblanc"}
    assert all(r.validity.startswith("all t") for r in rows)


def test_ou_rows() -> None:
    D, tau, t = 1.0, 0.1, 1e4
    x = D * t / tau**2
    rows = predictions(noise="ou", D=D, tau=tau, t=t)
    tc = _find(rows, "crossover", "t_c")
    assert tc.value == pytest.approx(100.0, rel=1e-14) and tc.equation == "tpcross"
    short = _find(rows, "white-like", "<E>")
    assert short.value == pytest.approx(D * t / 4) and "t << t_c" in short.validity
    first = _find(rows, "first-order", "<E>")
    assert first.value == pytest.approx(math.sqrt(x / math.pi), rel=1e-12)
    assert "wrong" in first.note and first.equation == "diff1"
    assert _find(rows, "first-order", "<E^2>").value == pytest.approx(x / 2, rel=1e-12)
    second = _find(rows, "second-order", "<E>")
    assert second.value == pytest.approx(math.sqrt(2) * math.pi / gamma(0.25) ** 2 * math.sqrt(x), rel=1e-12)
    assert second.validity == "t >> t_c" and second.equation == "eq:scalEcolor"
    assert _find(rows, "second-order", "<E^2>").value == pytest.approx(x / 4, rel=1e-12)
    assert _find(rows, "second-order", "S").value == pytest.approx(2.027934720201854, rel=1e-10)
    assert _find(rows, "second-order", "F").value == pytest.approx(5.0, rel=1e-12)
    phi_inf = gamma(0.25) ** 4 / (8 * math.pi**2)
    cross = _find(rows, "constant flatness", "<E>")
    expected = (math.sqrt(D * tau**2 * phi_inf * t + 1) - 1) / (2 * tau**2 * phi_inf)
    assert cross.value == pytest.approx(expected, rel=1e-10)
    longtime = _find(rows, "long-time law", "<E>")
    assert longtime.value == pytest.approx(
        math.sqrt(2) * math.pi / gamma(0.25) ** 2 * math.sqrt(x) - 0.2551349670 / tau**2, rel=1e-9
    )
    assert not any("numerically" in r.regime for r in rows)


def test_ou_bfpe_rows() -> None:
    D, tau, t = 1.0, 0.1, 1e3
    rows = predictions(noise="ou", D=D, tau=tau, t=t, bfpe=True)
    ds = solve_bfpe(D=D, tau=tau, t_max=t, times=[t])
    assert _find(rows, "numerically", "<E>").value == pytest.approx(float(ds.mean_E[-1]), rel=1e-12)
    assert _find(rows, "numerically", "phi").value == pytest.approx(float(ds.phi[-1]), rel=1e-12)
    # between the white-like and the coloured law at t = 10 t_c
    assert _find(rows, "numerically", "<E>").value < _find(rows, "second-order", "<E>").value


def test_format_table() -> None:
    rows = predictions(noise="ou", D=1.0, tau=1.0, t=10.0)
    text = format_table(rows)
    lines = text.splitlines()
    assert len(lines) == len(rows) + 2
    assert lines[0].startswith("regime") and set(lines[1].replace(" ", "")) == {"-"}
    for r in rows:
        assert r.equation in text and r.regime in text
    assert "inf" in format_table(predictions(noise="ou", D=0.0, tau=1.0, t=1.0))


def test_prediction_is_frozen() -> None:
    row = predictions(noise="white", D=1.0, t=1.0)[0]
    with pytest.raises(dataclasses.FrozenInstanceError):
        row.value = 0.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kw", "param"),
    [
        ({"noise": "pink", "D": 1.0, "t": 1.0}, "noise"),
        ({"noise": "ou", "D": 1.0, "t": 1.0}, "tau"),
        ({"noise": "ou", "D": 1.0, "tau": -2.0, "t": 1.0}, "tau"),
        ({"noise": "white", "D": -1.0, "t": 1.0}, "D"),
        ({"noise": "white", "D": 1.0, "t": -1.0}, "t"),
        ({"noise": "white", "D": 1.0, "t": float("nan")}, "t"),
        ({"noise": "ou", "D": 1.0, "tau": 1.0, "t": 0.0, "bfpe": True}, "t"),
        ({"noise": "white", "D": 1.0, "t": 1.0, "omega": -1.0}, "omega"),
    ],
)
def test_bad_input(kw: dict, param: str) -> None:
    with pytest.raises(ValueError) as info:
        predictions(**kw)
    msg = str(info.value)
    assert msg.startswith(f"{param}=") and "is not accepted" in msg and "\n" not in msg
