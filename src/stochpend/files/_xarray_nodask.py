"""xarray without Dask where no Dask object exists: 0.6 s less for every process that reads or
builds a result ('stochpend show', every simulate).

Where Dask is installed, xarray imports it to classify every array it wraps (an index, a
variable): ``is_dask_collection(x)`` imports ``dask.base`` (all of Dask) and
``isinstance(data, array_type("dask"))`` imports ``dask.array``, to answer "no" for a NumPy
array. Only Dask makes Dask objects, so before Dask (or ``dask.array``) has been imported -- by a
sweep, a ``chunks=`` open, the user -- no object can be one: :func:`install` makes both checks
answer "no" then, and leaves them to Dask once it is loaded (``array_type`` caches nothing in
the meantime). The one object this could misjudge is a non-Dask class implementing Dask's
collection protocol while Dask is installed but not imported; xarray then treats it as the duck
array it also is.

Installed by ``import stochpend``: it patches ``xarray.namedarray.utils`` and
``xarray.namedarray.pycompat`` as soon as each is imported (at once if xarray was imported
first), importing nothing itself. Another xarray without these functions is left alone.
"""

from __future__ import annotations

import sys
from types import SimpleNamespace
from typing import Any

_UTILS = "xarray.namedarray.utils"
_PYCOMPAT = "xarray.namedarray.pycompat"
_MARK = "_stochpend_no_dask"


def _patch_utils(utils: Any) -> None:
    original = getattr(utils, "is_dask_collection", None)
    if original is None or getattr(original, _MARK, False):
        return

    def is_dask_collection(x: object) -> bool:
        if "dask" not in sys.modules:  # nothing can be a Dask collection before Dask is loaded
            return False
        return bool(original(x))

    setattr(is_dask_collection, _MARK, True)
    # is_duck_dask_array (and through it is_chunked_array) look the name up here when called.
    utils.is_dask_collection = is_dask_collection


def _patch_pycompat(pycompat: Any) -> None:
    original = getattr(pycompat, "_get_cached_duck_array_module", None)
    if original is None or getattr(original, _MARK, False):
        return

    def get_module(mod: str) -> Any:
        if mod == "dask" and "dask.array" not in sys.modules:  # no Dask array exists yet
            from packaging.version import Version  # xarray's own dependency, imported by it

            return SimpleNamespace(module=None, version=Version("0.0.0"), type=(), available=False)
        return original(mod)

    setattr(get_module, _MARK, True)
    # array_type and mod_version look the name up here when called.
    pycompat._get_cached_duck_array_module = get_module


_PATCHES = {_UTILS: _patch_utils, _PYCOMPAT: _patch_pycompat}


class _Finder:
    """Patches each of the two modules right after it is executed; leaves sys.meta_path after both.
    (A meta path finder needs only find_spec: importlib.abc, 15 ms to import, is not needed.)"""

    def __init__(self) -> None:
        self.pending = {name for name in _PATCHES if name not in sys.modules}

    def find_spec(self, fullname: str, path: Any, target: Any = None) -> Any:
        if fullname not in self.pending:
            return None
        self.pending.discard(fullname)
        if not self.pending:
            sys.meta_path.remove(self)
        # The spec the rest of sys.meta_path would give (this finder answers only these names).
        spec = next((s for f in sys.meta_path if f is not self and hasattr(f, "find_spec")
                     for s in [f.find_spec(fullname, path, target)] if s is not None), None)
        loader = getattr(spec, "loader", None)
        if loader is None or not hasattr(loader, "exec_module"):
            return spec
        exec_module = loader.exec_module

        def exec_and_patch(module: Any) -> None:
            exec_module(module)
            _PATCHES[fullname](module)

        loader.exec_module = exec_and_patch
        return spec


def install() -> None:
    """Patch xarray now where it is loaded, else when it is (see the module docstring)."""
    for name, patch in _PATCHES.items():
        if name in sys.modules:
            patch(sys.modules[name])
    if (any(name not in sys.modules for name in _PATCHES)
            and not any(isinstance(f, _Finder) for f in sys.meta_path)):
        sys.meta_path.insert(0, _Finder())
