"""The module paths users import today stay the modules of the layered sub-packages
(issue 33, item 7).

``stochpend.bias`` is a file of three lines that puts :mod:`stochpend.runs.bias` in its own
place in ``sys.modules``: ``import stochpend.bias`` and ``from stochpend import bias`` give the
very module the package uses (one object: a patch, ``isinstance`` and a pickle agree), and a
package's submodules resolve the same way (``stochpend.noises.ou`` is
``stochpend.model.noises.ou``, never a second copy with a second registry).
"""

from __future__ import annotations

import importlib
import pkgutil
import sys
import types


def alias(name: str, module: types.ModuleType) -> None:
    """Make the public path ``name`` (and, for a package, ``name.sub`` for each submodule)
    stand for ``module`` in ``sys.modules``."""
    sys.modules[name] = module
    for info in pkgutil.iter_modules(getattr(module, "__path__", [])):
        sys.modules[f"{name}.{info.name}"] = importlib.import_module(f"{module.__name__}.{info.name}")
