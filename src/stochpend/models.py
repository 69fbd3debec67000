"""Oscillators a user defines in Python, run by the same kernels as the built-in ones.

A model is four plain scalar functions of the coordinate x (floats in, a float out), of the
kind ``stochpend.physics`` defines for the built-in potentials:

* ``potential(x)``: U(x); the energy is E = Omega**2/2 + omega**2 U(x);
* ``force(x)``: U'(x); the deterministic force is -omega**2 U'(x);
* ``curvature(x)``: |U''(x)| (or a bound on it), used only by the step control
  h <= c / sqrt(|omega**2 + xi| |U''(x)|); default 1;
* ``noise_shape(x)``: G(x), what the noise multiplies in dOmega/dt = -omega**2 U' - xi G;
  default U'(x) (the pendulum's placement). With ``coupling="position"`` G = x regardless.

They must be compilable by Numba in nopython mode (``math`` functions, arithmetic,
conditionals; no Python objects), which also makes them CUDA device functions.

How it works, and why it is the same code: the kernels (``_backends/cpu.py``,
``_backends/cuda.py``) and the integrator (``schemes.py``) call the physics only through the
module-level name ``physics``. For a registered model their source is compiled once more with
that name bound to a namespace of the user's functions instead of ``stochpend.physics``:
nothing else changes, so the noise updates, the random streams, the step control, the
statistics and the outputs are those of the built-in models. These copies are compiled in
memory (not cached on disk): the first run of a model in a process pays the compilation.

Example (docs/models.md)::

    import math
    import stochpend
    from stochpend.models import Model, register

    register(Model(
        name="double-well",
        potential=lambda x: 0.25 * x**4 - 0.5 * x**2,
        force=lambda x: x**3 - x,
        curvature=lambda x: abs(3.0 * x * x - 1.0),
    ))
    ds = stochpend.simulate(potential="double-well", noise="ou", D=0.5, tau=1.0, paths=10_000)
"""

from __future__ import annotations

import ast
import functools
import inspect
import math
import types
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba.extending import register_jitable

from stochpend import physics

__all__ = ["Model", "get", "names", "register", "unregister"]

#: The built-in potentials' names (a model may not take one).
BUILTIN = tuple(physics.POTENTIALS)

_REGISTRY: dict[str, Model] = {}


def _one(x: float) -> float:
    return 1.0


@dataclass(frozen=True)
class Model:
    """A user-defined oscillator (see the module docstring for the meaning of each function).

    ``periodic``: x is an angle, reduced to [-pi, pi) after each step (like the pendulum's).
    ``E_min``: the lowest energy per omega**2 (min of U), for the histogram's lower edge;
    default: the minimum of U on [-10, 10] (or [-pi, pi] when periodic).
    """

    name: str
    potential: Callable[[float], float]
    force: Callable[[float], float]
    curvature: Callable[[float], float] = _one
    noise_shape: Callable[[float], float] | None = None
    periodic: bool = False
    E_min: float | None = None
    description: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or self.name in BUILTIN:
            raise ValueError(f"name={self.name!r} is not accepted: a non-empty name other than "
                             f"the built-in {', '.join(BUILTIN)}")
        for attr in ("potential", "force", "curvature"):
            if not callable(getattr(self, attr)):
                raise ValueError(f"{attr}={getattr(self, attr)!r} is not accepted: a function of x")
        if self.noise_shape is not None and not callable(self.noise_shape):
            raise ValueError(f"noise_shape={self.noise_shape!r} is not accepted: a function of x or None")
        # Evaluate once in Python: a function that fails here would fail inside a kernel.
        for attr in ("potential", "force", "curvature", "noise_shape"):
            f = getattr(self, attr)
            if f is None:
                continue
            try:
                value = float(f(0.5))
            except Exception as error:
                raise ValueError(f"{attr} is not accepted: calling it with x=0.5 raised "
                                 f"{type(error).__name__}: {error}") from None
            if not math.isfinite(value):
                raise ValueError(f"{attr} is not accepted: it returned {value} at x=0.5")

    # -- plain Python views (validation, histogram edges) ----------------------------------
    def G(self, x: float, coupling: str) -> float:
        if coupling == "position":
            return x
        return float((self.noise_shape or self.force)(x))

    def energy_floor(self) -> float:
        """min U (per omega**2), for the histogram's lower edge."""
        if self.E_min is not None:
            return float(self.E_min)
        span = math.pi if self.periodic else 10.0
        grid = np.linspace(-span, span, 20001)
        return float(min(self.potential(float(x)) for x in grid))

    def source(self) -> str:
        """The functions' source, for provenance (empty where Python cannot find it)."""
        parts = []
        for attr in ("potential", "force", "curvature", "noise_shape"):
            f = getattr(self, attr)
            if f is None or f is _one:
                continue
            try:
                parts.append(inspect.getsource(f).strip())
            except (OSError, TypeError):
                parts.append(f"{attr}: source unavailable")
        return "\n".join(parts)


def register(model: Model) -> Model:
    """Make ``model`` available as ``potential=model.name`` everywhere (replaces one of the
    same name). Returns it."""
    if not isinstance(model, Model):
        raise ValueError(f"model={model!r} is not accepted: a stochpend.models.Model")
    _REGISTRY[model.name] = model
    _kernel_module.cache_clear()
    return model


def unregister(name: str) -> None:
    _REGISTRY.pop(name, None)
    _kernel_module.cache_clear()


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def get(name: str) -> Model | None:
    return _REGISTRY.get(name)


# -- the physics namespace of a model ---------------------------------------------------------
def physics_namespace(model: Model) -> types.ModuleType:
    """An object with ``stochpend.physics``'s interface whose functions are the model's.

    Each function has the built-in signature (the potential and coupling codes are passed
    through and ignored, except the position coupling), registered with ``register_jitable``
    so that the kernels inline it on the CPU and on the GPU alike.
    """
    U = register_jitable(model.potential)
    dU = register_jitable(model.force)
    d2U = register_jitable(model.curvature)
    G = register_jitable(model.noise_shape) if model.noise_shape is not None else dU
    periodic = bool(model.periodic)
    position = physics.COUPLING_POSITION

    @register_jitable
    def potential(x, potential_code, power_n):
        return U(x)

    @register_jitable
    def force_shape(x, potential_code, power_n):
        return dU(x)

    @register_jitable
    def curvature(x, potential_code, power_n):
        return abs(d2U(x))

    @register_jitable
    def noise_shape(x, potential_code, power_n, coupling_code):
        if coupling_code == position:
            return x
        return G(x)

    @register_jitable
    def energy(x, Omega, omega2, potential_code, power_n):
        return 0.5 * Omega * Omega + omega2 * U(x)

    @register_jitable
    def wrap_angle(x, potential_code):
        if periodic:
            return x - 2.0 * math.pi * math.floor((x + math.pi) / (2.0 * math.pi))
        return x

    # A module object, because Numba resolves ``physics.f`` only on modules.
    namespace = types.ModuleType(f"stochpend._model_{model.name}_physics")
    for name in dir(physics):
        if name.isupper():
            setattr(namespace, name, getattr(physics, name))
    for f in (potential, force_shape, curvature, noise_shape, energy, wrap_angle):
        setattr(namespace, f.__name__, f)
    return namespace


class _NoDiskCache(ast.NodeTransformer):
    """``cache=True`` -> ``cache=False``, and drop the ``drop_stale_cache(__file__)`` call: the
    copies live in memory only."""

    def visit_keyword(self, node: ast.keyword) -> ast.keyword:
        if node.arg == "cache":
            node.value = ast.Constant(False)
        return node

    def visit_Expr(self, node: ast.Expr) -> ast.AST | None:
        call = node.value
        if isinstance(call, ast.Call) and getattr(call.func, "id", "") == "drop_stale_cache":
            return None
        return node


def _recompiled(module: types.ModuleType, name: str, bindings: dict) -> types.ModuleType:
    """A copy of ``module`` compiled from its source, with module globals ``bindings``
    (e.g. ``physics``) replaced after its imports ran; Numba compiles lazily, so the kernels
    see the replacements."""
    tree = _NoDiskCache().visit(ast.parse(inspect.getsource(module)))
    copy = types.ModuleType(name)
    copy.__dict__["__file__"] = module.__file__
    exec(compile(ast.fix_missing_locations(tree), f"<stochpend model copy of {module.__name__}>",
                 "exec"), copy.__dict__)
    copy.__dict__.update(bindings)
    return copy


@functools.lru_cache(maxsize=None)
def _kernel_module(name: str, backend: str) -> types.ModuleType:
    """The kernels of model ``name`` for ``backend`` ("cpu" or "cuda")."""
    from stochpend import schemes

    model = _REGISTRY[name]
    user_physics = physics_namespace(model)
    user_schemes = _recompiled(schemes, f"stochpend._model_{name}_schemes", {"physics": user_physics})
    if backend == "cpu":
        from stochpend._backends import cpu

        return _recompiled(cpu, f"stochpend._model_{name}_cpu",
                           {"physics": user_physics, "schemes": user_schemes})
    from stochpend._backends import cuda

    return _recompiled(cuda, f"stochpend._model_{name}_cuda",
                       {"physics": user_physics, "schemes": user_schemes})


def kernels(name: str, backend: str = "cpu") -> types.ModuleType:
    """The kernel module (same interface as ``stochpend._backends.cpu`` or ``.cuda``) running
    model ``name``."""
    if name not in _REGISTRY:
        raise ValueError(f"potential={name!r} is not accepted: no model of that name is registered "
                         "in this process (stochpend.models.register)")
    return _kernel_module(name, backend)
