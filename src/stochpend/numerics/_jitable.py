"""``register_jitable`` without importing Numba until something compiles.

The noises, oscillators, models and math functions are ``register_jitable``: plain Python
functions that Numba compiles into the kernels that call them. Numba's decorator imports
Numba (about a second, more on a busy machine), and the commands that compute nothing
(``list``, ``show``, ``info``, ``theory``, ``--help``) read these modules for their names,
descriptions and parameters only. Here the decorator returns the function unchanged, as
Numba's does, and registers it with Numba:

* at once, where Numba is already imported;
* otherwise when Numba is first imported, by anyone (the package's kernels, a test, a user's
  ``numba.njit``): an import hook (:class:`_NumbaWatcher`) runs the registrations as soon as
  ``numba/__init__`` has run, before any code can be compiled.

So a kernel sees every function registered, whichever was imported first, and a process that
never compiles never imports Numba (tests/unit/test_light_commands.py).
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
import threading
from collections.abc import Callable
from typing import Any

__all__ = ["register_jitable", "when_numba"]

_PENDING: list[Callable[[], None]] = []
_LOCK = threading.RLock()


def _numba_ready() -> bool:
    """Numba is imported and its ``__init__`` has finished (its version is set last)."""
    module = sys.modules.get("numba")
    return module is not None and getattr(getattr(module, "__spec__", None), "_initializing", False) is False


def _flush() -> None:
    with _LOCK:
        pending, _PENDING[:] = list(_PENDING), []
        _NumbaWatcher.remove()
    for action in pending:
        action()


def when_numba(action: Callable[[], None]) -> None:
    """Run ``action`` (a registration with Numba) now if Numba is imported, else right after
    Numba is first imported."""
    with _LOCK:
        if not _numba_ready():
            _PENDING.append(action)
            _NumbaWatcher.install()
            return
    _flush()  # anything queued before Numba was imported, in order, then this
    action()


def register_jitable(*args: Any, **kwargs: Any) -> Any:
    """Numba's ``numba.extending.register_jitable``, deferred until Numba is imported: use as
    ``@register_jitable`` or ``@register_jitable(inline="always")``. Returns the function."""

    def wrap(fn: Callable[..., Any]) -> Callable[..., Any]:
        def register() -> None:
            from numba.extending import register_jitable as numba_register_jitable

            if kwargs:
                numba_register_jitable(**dict(kwargs))(fn)
            else:
                numba_register_jitable(fn)

        when_numba(register)
        return fn

    if kwargs or not args:
        return wrap
    return wrap(*args)


class _Loader(importlib.abc.Loader):
    """Numba's own loader, which runs the queued registrations once Numba's ``__init__`` ran."""

    def __init__(self, loader: Any) -> None:
        self._loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> Any:
        return self._loader.create_module(spec)

    def exec_module(self, module: Any) -> None:
        self._loader.exec_module(module)
        module.__loader__ = self._loader
        if module.__spec__ is not None:
            module.__spec__.loader = self._loader
        _flush()

    def __getattr__(self, name: str) -> Any:  # get_resource_reader, is_package, ...
        return getattr(self._loader, name)


class _NumbaWatcher(importlib.abc.MetaPathFinder):
    """On ``sys.meta_path`` while registrations wait: finds ``numba`` as the other finders do
    and wraps its loader (:class:`_Loader`). Removed after the registrations ran."""

    _instance: _NumbaWatcher | None = None

    @classmethod
    def install(cls) -> None:
        if cls._instance is None:
            cls._instance = cls()
            sys.meta_path.insert(0, cls._instance)

    @classmethod
    def remove(cls) -> None:
        if cls._instance is not None:
            try:
                sys.meta_path.remove(cls._instance)
            except ValueError:
                pass
            cls._instance = None

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> importlib.machinery.ModuleSpec | None:
        if name != "numba":
            return None
        for finder in sys.meta_path:
            if finder is self or not hasattr(finder, "find_spec"):
                continue
            spec = finder.find_spec(name, path, target)
            if spec is not None:
                if spec.loader is not None and not isinstance(spec.loader, _Loader):
                    spec.loader = _Loader(spec.loader)
                return spec
        return None
