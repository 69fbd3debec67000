"""Shared test settings: seeds live here, tolerances are stated in standard errors."""

from __future__ import annotations

import pytest

#: |z| bound for statistical assertions: a correct implementation fails one such assertion
#: with probability ~6e-5, a biased one of a few standard errors fails reliably.
Z_TOL = 4.0

SEED = 20040401


@pytest.fixture(scope="session")
def seed() -> int:
    return SEED
