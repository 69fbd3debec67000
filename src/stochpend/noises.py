"""``stochpend.noises``, the path users import: the module is :mod:`stochpend.model.noises`
(:mod:`stochpend._alias`)."""

import importlib
from typing import TYPE_CHECKING

from stochpend._alias import alias

if TYPE_CHECKING:  # pragma: no cover - type checkers and IDEs see the module's names
    from stochpend.model.noises import *  # noqa: F403

alias(__name__, importlib.import_module("stochpend.model.noises"))
