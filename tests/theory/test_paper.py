"""The paper's equation numbers (stochpend.paper) against its LaTeX source."""

from __future__ import annotations

from pathlib import Path

import pytest

from stochpend import paper

#: The paper's folder, beside the repository (CI's clone has shared/ beside it).
SOURCE = (Path(__file__).resolve().parents[2].parent / "shared" / "paper"
          / "mallick-marcq-2004-stochastic-pendulum.tex")


@pytest.mark.skipif(not SOURCE.is_file(), reason=f"the paper's source is not at {SOURCE}")
def test_table_is_the_numbering_of_the_source():
    assert paper.EQUATIONS == paper.number_equations(SOURCE.read_text(encoding="utf-8"))


def test_numbering_rules_of_revtex():
    """One number per equation and per eqnarray row without \\nonumber, comments not typeset,
    A1, A2, ... after \\appendix."""
    tex = r"""
    \begin{equation} a \label{one} \end{equation}
    % \begin{equation} commented out \label{ghost} \end{equation}
    \begin{eqnarray} b &=& c \nonumber \\ d &=& e \label{two} \\ f &=& g \label{three}
    \end{eqnarray}
    \appendix
    \begin{equation} h \label{app} \end{equation}
    """
    assert paper.number_equations(tex) == {"one": "1", "two": "2", "three": "3", "app": "A1"}


@pytest.mark.parametrize(("text", "expected"), [
    ("(Eqs. eq:scalEblanc–eq:flatEblanc)", "(Eqs. (9)–(11))"),
    ("pendulum (Eqs. dynOmega, dyntheta, defbruitblanc), with", "pendulum (Eqs. (1), (2), (4)), with"),
    ("white noise, eq:scalEblanc (1/4)", "white noise, Eq. (9) (1/4)"),
    ("the OU skewness (eq:skewEcolor)", "the OU skewness (Eq. (56))"),  # "OU" is a word here
    ("Eq. `tpcross`", "Eq. (58)"),
    ("idquadr and deflatness", "Eq. (65) and (67)"),
    ("no label: eq:unknown, avbfpex", "no label: eq:unknown, avbfpex"),
])
def test_labels_become_printed_numbers(text, expected):
    assert paper.with_numbers(text) == expected
    assert paper.cite("avbfpe") == "Eq. (64) [avbfpe]"
