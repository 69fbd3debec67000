"""stochpend: ensembles of the stochastic pendulum with parametric white or Ornstein-Uhlenbeck noise.

Implements K. Mallick and P. Marcq, "On the stochastic pendulum with Ornstein-Uhlenbeck noise"
(2004): the ensemble simulator, the paper's analytic results, and its reduced dynamics.

The public API, reachable after ``import stochpend`` and imported on first use (so that
``import stochpend`` and the command line start fast; Numba, xarray and Dask load only when a
name that needs them is touched):

* :func:`simulate` -- run an ensemble (``stochpend.simulate(noise="ou", ...)``);
* :mod:`io` -- ``to_netcdf`` / ``open_results``;
* :mod:`theory` -- the paper's closed forms and the B.F.P.E.; :mod:`exponents` -- growth-law
  fits; :mod:`sweep` -- parameter sweeps (Dask); :mod:`models` and :mod:`noises` -- oscillators
  and noises of your own; :mod:`plotting` -- figures of results; :mod:`paper` -- the paper's
  equation numbers; :mod:`bias` -- the discretisation-bias estimate.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

from stochpend._version import __version__
from stochpend.files import _xarray_nodask
from stochpend.numerics import _cputarget

_xarray_nodask.install()  # xarray's check for Dask arrays imports Dask only once Dask is used

try:  # STOCHPEND_CPU_TARGET=baseline: before anything compiles (Numba is not imported here)
    _cputarget.apply_environment()
except ValueError:  # a word it does not know, or a CPU that cannot: said when a run starts (RunOptions.build)
    pass

#: Submodules reachable as attributes of the package, imported on first use.
SUBMODULES = ("bias", "exponents", "io", "models", "noises", "paper", "plotting", "sweep",
              "theory")

__all__ = ["StochpendWarning", "__version__", "simulate", *SUBMODULES]

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs only
    from stochpend import models as models
    from stochpend import paper as paper
    from stochpend import theory as theory
    from stochpend.files import io as io
    from stochpend.model import noises as noises
    from stochpend.paper import plotting as plotting
    from stochpend.runs import bias as bias
    from stochpend.runs import sweep as sweep
    from stochpend.runs.simulate import simulate
    from stochpend.text._warnings import StochpendWarning
    from stochpend.theory import exponents as exponents


def __getattr__(name: str) -> Any:
    """Import a public submodule (or :func:`simulate`) when it is first touched."""
    if name == "simulate":
        from stochpend.runs.simulate import simulate

        globals()["simulate"] = simulate
        return simulate
    if name == "StochpendWarning":
        from stochpend.text._warnings import StochpendWarning

        return StochpendWarning
    if name in SUBMODULES:
        module = importlib.import_module(f"stochpend.{name}")
        globals()[name] = module
        return module
    raise AttributeError(f"module 'stochpend' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
