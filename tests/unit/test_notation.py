"""The one v(e) notation of every table (stochpend.text._notation.ve; issue 19, item 5)."""

from __future__ import annotations

import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from stochpend.text._notation import ve

PATTERN = re.compile(r"^(-?\d+(?:\.(\d+))?)\((\d+)\)(?:e(-?\d+))?$")


@pytest.mark.parametrize(("value", "error", "text"), [
    (16.656, 0.1003, "16.66(10)"),
    (-0.003, 0.26, "0.00(26)"),           # no negative zero
    (177000.0, 11193.0, "1.77(11)e5"),    # large: scientific, exponent after the error
    (7.6722e-05, 1.9e-05, "7.7(19)e-5"),  # small: scientific
    (0.003, 0.024, "0.003(24)"),
    (0.33799, 0.0021, "0.3380(21)"),
    (10.48, 0.11, "10.48(11)"),
    (239.0, 4.9, "239.0(49)"),
    (0.2, 0.0996, "0.20(10)"),            # 99.6 rounds to 100: one place higher
    (2345.6, 120.0, "2.35(12)e3"),        # an error of 100 or more: scientific
    (1.23456789e6, 3.0, "1.2345679(30)e6"),
    (5.0, 0.0, "5"),                      # no error: five significant digits
    (5.0, None, "5"),
    (float("nan"), 1.0, "nan"),
    (1.0, float("inf"), "1"),
])
def test_examples(value, error, text):
    assert ve(value, error) == text


def _parse(text: str) -> tuple[float, float, int]:
    m = PATTERN.match(text)
    assert m, text
    mantissa, decimals, digits, exponent = m.groups()
    scale = 10.0 ** int(exponent or 0)
    unit = 10.0 ** -len(decimals or "") * scale
    return float(mantissa) * scale, int(digits) * unit, len(digits)


@given(st.floats(min_value=-1e12, max_value=1e12, allow_nan=False),
       st.floats(min_value=1e-12, max_value=1e11))
def test_rule_holds_for_any_value_and_error(value, error):
    """Two digits of error, rounded; the value rounded to the error's last place; parsing the
    text gives back the value and the error to within half of that place."""
    text = ve(value, error)
    v, e, n_digits = _parse(text)
    assert n_digits == 2
    unit = e / int(PATTERN.match(text).group(3))
    assert abs(e - error) <= 0.5 * unit * (1 + 1e-9) + 1e-12 * error
    assert abs(v - value) <= 0.5 * unit * (1 + 1e-9) + 1e-12 * abs(value)
    assert not text.startswith("-0") or re.search(r"[1-9]", text.split("(")[0])


def test_every_table_uses_it():
    """The simulate/show table and the figures' rows format through ve (no second formatter)."""
    from stochpend.cli import _common as _cli_common
    from stochpend.paper.figures import _common

    for v, e in ((0.00012, 3.1e-5), (177000.0, 11193.0), (-0.004, 0.3)):
        assert _cli_common._fmt(v, e) == _common.fmt_se(v, e) == ve(v, e)
    assert "±" not in _cli_common._fmt(7.6722e-05, 1.9e-05)
