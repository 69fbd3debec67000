"""The paper's theory as code: closed forms (:mod:`.laws`), the averaged B.F.P.E. solver
(:mod:`.bfpe`), the table of predictions (:mod:`.table`), the long-time growth laws of the
other oscillators and noises (:mod:`.scaling`, docs/scaling.md), and the laws of the damped,
driven family (:mod:`.family`: Boltzmann, Kramers, washboard, random-frequency oscillator).

Equation labels in the docstrings are the ``\\label`` names of Mallick & Marcq (2004); see
``docs/theory.md`` for the map from each equation to its function. :func:`solve_bfpe` (and its
xarray and scipy.linalg) is imported on first use.
"""

from typing import Any

from stochpend.theory.laws import (
    BFPE_LONGTIME_MEAN_PREFACTOR,
    OU1_MEAN_E2_PREFACTOR,
    OU1_MEAN_PREFACTOR,
    OU2_FLATNESS,
    OU2_MEAN_E2_PREFACTOR,
    OU2_MEAN_PREFACTOR,
    OU2_SKEWNESS,
    PHI_INF,
    WHITE_FLATNESS,
    WHITE_MEAN_E2_PREFACTOR,
    WHITE_MEAN_PREFACTOR,
    WHITE_SKEWNESS,
    bfpe_identity_lhs,
    bfpe_identity_rhs,
    bfpe_longtime_correction,
    bfpe_longtime_mean_E,
    bfpe_longtime_pdf_Omega,
    crossover_time,
    ou1_mean_E,
    ou1_mean_E2,
    ou1_moment_E,
    ou1_pdf_E,
    ou2_flatness,
    ou2_mean_E,
    ou2_mean_E2,
    ou2_moment_E,
    ou2_pdf_E,
    ou2_skewness,
    phi_crossover_mean_E,
    white_flatness,
    white_mean_E,
    white_mean_E2,
    white_moment_E,
    white_pdf_E,
    white_pdf_Omega,
    white_skewness,
)
from stochpend.theory.scaling import (
    ScalingPrediction,
    harmonic_growth_rate,
    predicted_exponent,
    spectral_density,
)
from stochpend.theory.table import Prediction, format_table, predictions

__all__ = [
    "ScalingPrediction",
    "harmonic_growth_rate",
    "predicted_exponent",
    "spectral_density",
    "BFPE_LONGTIME_MEAN_PREFACTOR",
    "OU1_MEAN_E2_PREFACTOR",
    "OU1_MEAN_PREFACTOR",
    "OU2_FLATNESS",
    "OU2_MEAN_E2_PREFACTOR",
    "OU2_MEAN_PREFACTOR",
    "OU2_SKEWNESS",
    "PHI_INF",
    "WHITE_FLATNESS",
    "WHITE_MEAN_E2_PREFACTOR",
    "WHITE_MEAN_PREFACTOR",
    "WHITE_SKEWNESS",
    "Prediction",
    "bfpe_identity_lhs",
    "bfpe_identity_rhs",
    "bfpe_longtime_correction",
    "bfpe_longtime_mean_E",
    "bfpe_longtime_pdf_Omega",
    "crossover_time",
    "format_table",
    "ou1_mean_E",
    "ou1_mean_E2",
    "ou1_moment_E",
    "ou1_pdf_E",
    "ou2_flatness",
    "ou2_mean_E",
    "ou2_mean_E2",
    "ou2_moment_E",
    "ou2_pdf_E",
    "ou2_skewness",
    "phi_crossover_mean_E",
    "predictions",
    "solve_bfpe",
    "white_flatness",
    "white_mean_E",
    "white_mean_E2",
    "white_moment_E",
    "white_pdf_E",
    "white_pdf_Omega",
    "white_skewness",
]


def __getattr__(name: str) -> Any:
    """:func:`solve_bfpe` on first use: its module imports xarray and scipy.linalg (about half a
    second), which ``stochpend theory`` and the closed forms never need."""
    if name == "solve_bfpe":
        from stochpend.theory.bfpe import solve_bfpe

        globals()["solve_bfpe"] = solve_bfpe
        return solve_bfpe
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
