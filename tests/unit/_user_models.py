"""User-defined models shared by the tests and the CUDA-simulator subprocess
(``_cudasim_check.py``), which must register them again in its own process."""

from __future__ import annotations

import math

from stochpend.models import Model, register


def user_pendulum_potential(x):
    return -math.cos(x)


def user_pendulum_force(x):
    return math.sin(x)


def double_well_potential(x):
    """U = x**4/4 - x**2/2: two wells at x = +-1, barrier U = 0, minimum -1/4."""
    return 0.25 * x**4 - 0.5 * x * x


def double_well_force(x):
    return x * x * x - x


def double_well_curvature(x):
    return abs(3.0 * x * x - 1.0)


USER_PENDULUM = Model(name="user-pendulum", potential=user_pendulum_potential,
                      force=user_pendulum_force, periodic=True, E_min=-1.0,
                      description="the built-in pendulum, written as a user model")
DOUBLE_WELL = Model(name="double-well", potential=double_well_potential,
                    force=double_well_force, curvature=double_well_curvature,
                    description="quartic double well U = x^4/4 - x^2/2")


def register_all() -> None:
    register(USER_PENDULUM)
    register(DOUBLE_WELL)
