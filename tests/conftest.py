"""Shared test settings: seeds live here, tolerances are stated in standard errors."""

from __future__ import annotations

import signal

import pytest

# A suite started in the background ('make test &' in a non-interactive shell) inherits SIGINT
# ignored, and stochpend keeps an ignored SIGINT ignored (tests/unit/test_checkpoint.py): the
# Ctrl-C tests need it delivered, in this process and in the runs it starts.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

#: |z| bound for statistical assertions: a correct implementation fails one such assertion
#: with probability ~6e-5, a biased one of a few standard errors fails reliably.
Z_TOL = 4.0

SEED = 20040401


@pytest.fixture(scope="session")
def seed() -> int:
    return SEED
