"""One notation for a value and its error in every table: v(e), e.g. ``16.66(10)``.

The rule, the same everywhere (the simulate and show tables, the bias column, theory and
scaling tables, the figures' rows and the report):

* the error is rounded to two significant digits, written in parentheses in units of the last
  digits of the value, and the value is rounded to the same decimal place:
  0.3482 +- 0.00217 -> ``0.3482(22)``; an error that rounds up to three digits moves the place
  (0.0996 -> ``(10)`` one place higher);
* scientific form, with the exponent after the parentheses, when the larger of |value| and the
  error is at least 1e5 or below 1e-2, or when the error is 100 or more:
  ``1.77(11)e5``, ``7.7(19)e-5``, ``2.35(12)e3``;
* a value that rounds to zero has no sign (``0.00(26)``, not ``-0.00(26)``);
* no error (or a non-positive one): five significant digits; a non-finite value: ``nan``.
"""

from __future__ import annotations

import math

__all__ = ["ve"]


def _fixed(value: float, decimals: int) -> str:
    text = f"{value:.{max(decimals, 0)}f}"
    if text.lstrip("-").strip("0.") == "":  # rounds to zero: no sign
        text = text.lstrip("-")
    return text


def ve(value: float | None, error: float | None = None) -> str:
    """``value`` with its standard ``error`` in v(e) notation (module docstring)."""
    if value is None or not math.isfinite(value):
        return "nan"
    if error is None or not math.isfinite(error) or error <= 0:
        return f"{value:.5g}"
    place = math.floor(math.log10(error)) - 1  # decimal place of the error's second digit
    digits = round(error / 10.0**place)
    if digits >= 100:  # 99.6 -> 100: two digits one place higher
        place += 1
        digits = round(error / 10.0**place)
    top = math.floor(math.log10(max(abs(value), digits * 10.0**place)))
    if top >= 5 or top <= -3 or place > 0:
        mantissa = value / 10.0**top
        return f"{_fixed(mantissa, top - place)}({digits})e{top}"
    return f"{_fixed(value, -place)}({digits})"
