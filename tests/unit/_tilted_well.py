"""A test-only oscillator with a parameter of its own, defined in this one file: the tilted
(asymmetric) quartic double well

    U(x) = x**4/4 - x**2/2 + a x,   U'(x) = x**3 - x + a,   |U''(x)| = |3 x**2 - 1|,

whose tilt ``a`` the package has never heard of. The model declares it (a
:class:`stochpend.model.parameters.Parameter`: default 0, range [-1, 1]); its functions take it after
x; the kernels receive it in the oscillator's record ``q = (a,)``. At a = 0 it is the double
well of ``tests/unit/_user_models.py``, term for term (plus 0.0).

Registering it (importing this module: ``--plugin tests.unit._tilted_well`` on the command
line) makes ``potential="tilted-well"`` and ``a=...`` (``--param a=...``) work everywhere
(tests/unit/test_oscillator_parameters.py).
"""

from __future__ import annotations

from stochpend.model.parameters import Parameter
from stochpend.models import Model, register

NAME = "tilted-well"
TILT = Parameter("a", 0.0, "the tilt: U = x^4/4 - x^2/2 + a x", low=-1.0, high=1.0)


def potential(x, a):
    return 0.25 * x**4 - 0.5 * x * x + a * x


def force(x, a):
    return x * x * x - x + a


def curvature(x, a):
    return abs(3.0 * x * x - 1.0)


TILTED_WELL = register(Model(name=NAME, potential=potential, force=force, curvature=curvature,
                             parameters=(TILT,), description="tilted double well U = x^4/4 - x^2/2 + a x"))
