"""The noises, one file each, and the registry that ``noise=`` names are looked up in.

Built in: ``white`` (:mod:`.white`), ``ou`` (:mod:`.ou`), ``dichotomous`` (:mod:`.dichotomous`)
and ``harmonic`` (:mod:`.harmonic`). A new noise is one file that defines a
:class:`~stochpend.noises.base.Noise` and calls :func:`register`; the integrator, every
backend, the runner, checkpoints and the command line then take it by name (docs/models.md).
"""

from __future__ import annotations

from stochpend.model.noises.base import Noise, NoiseKernel
from stochpend.model.noises.dichotomous import DICHOTOMOUS
from stochpend.model.noises.harmonic import HARMONIC
from stochpend.model.noises.ou import OU
from stochpend.model.noises.white import WHITE

__all__ = ["BUILTIN", "Noise", "NoiseKernel", "get", "names", "register", "unregister"]

#: The built-in noises, in the order of ``params.NOISES``.
BUILTIN = (WHITE, OU, DICHOTOMOUS, HARMONIC)

_REGISTRY: dict[str, Noise] = {noise.name: noise for noise in BUILTIN}


def register(noise: Noise) -> Noise:
    """Make ``noise`` available as ``noise=noise.name`` in this process. Returns it."""
    if not isinstance(noise, Noise):
        raise ValueError(f"noise={noise!r} is not accepted: a stochpend.noises.Noise")
    if noise.name in {n.name for n in BUILTIN}:
        raise ValueError(f"name={noise.name!r} is not accepted: it is a built-in noise")
    _REGISTRY[noise.name] = noise
    return noise


def unregister(name: str) -> None:
    if name not in {n.name for n in BUILTIN}:
        _REGISTRY.pop(name, None)


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def get(name: str) -> Noise | None:
    return _REGISTRY.get(name) if isinstance(name, str) else None
