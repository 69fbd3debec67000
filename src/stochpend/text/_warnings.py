"""The warning category of stochpend's statistical notes (``stochpend.StochpendWarning``).

The Python API says what the command line prints in yellow: a significant discretisation bias
(:func:`stochpend.bias.warnings_for`) and paths that went non-finite and were left out. Filter
them like any warning: ``warnings.simplefilter("ignore", stochpend.StochpendWarning)``.
"""

from __future__ import annotations

__all__ = ["StochpendWarning"]


class StochpendWarning(UserWarning):
    """Something about a result that its numbers alone do not say (a resolved bias, lost paths)."""
