"""Keep Numba's on-disk cache honest: a cached kernel is only ever reused by the code that made it.

Numba keys a cached kernel on its own source file and its closure's cells; a function it calls
from another module (``rng.draw_normals``, the integrator's pieces) is pickled by reference, so
an edit of that module, or an upgrade of stochpend, would reuse the old machine code under the
new code's name. And Numba names each compiled function ``<module>.<qualname>$<n>``, ``n`` from
a counter unique in one process only: a cached kernel calls the pieces it does not inline by
those names, so when two pieces share a qualname (every KernelSpec's ``build.<locals>.verlet``), a
process that compiled another KernelSpec's piece first can give it the very name the cached kernel
was written with, and the kernel, once loaded, calls it (another noise's step, no error).

Both are closed by names, whatever the cache directory and whichever process wrote it:

* every cached kernel's qualname carries a tag of its key (the KernelSpec's label, the noise's name)
  and of :func:`stochpend.numerics._sources.digest`, so its cache index file is the new code's own
  (:func:`own_index`); an edit of any source that decides the numbers compiles afresh;
* every closure a builder makes (the integrator's pieces, a noise's or an oscillator's device
  functions) is named once, where it is made, after what determines its code
  (:func:`name_closures`): two functions with one qualname are then the same code, and a name
  met in another process's cache can only mean that code.

Nothing is patched in Numba and nothing is deleted: kernels of older code stay on disk unused
(delete ``__pycache__/*.nb[ic]`` or the ``NUMBA_CACHE_DIR`` folder to reclaim the space).
"""

from __future__ import annotations

import hashlib
import types
import uuid
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from stochpend.numerics import _cputarget, _sources

_PACKAGE = Path(__file__).resolve().parent.parent  # the package's root


def tag(key: str) -> str:
    """16 hex digits fixed by ``key`` and the code digest (:mod:`stochpend.numerics._sources`)."""
    return hashlib.sha256(f"{key}\0{_sources.digest()}".encode()).hexdigest()[:16]


def name_closures(functions: Iterable[Any], key: str) -> None:
    """Append :func:`tag` (``key``) to the qualname of every closure reachable from
    ``functions`` (through closure cells, tuples and Numba dispatchers' ``py_func``) that has no
    such name yet; functions defined at module level keep theirs.

    ``key`` must name everything that decides the closures' code besides the sources (e.g.
    ``"ou/float64/libm"`` for a noise's device functions, a KernelSpec's label for the
    integrator's): call it where the closures are made, before anything compiles them (Numba
    reads the qualname when it compiles).
    """
    suffix = "_" + tag(key)
    seen: set[int] = set()
    stack = list(functions)
    while stack:
        obj = stack.pop()
        if id(obj) in seen:
            continue
        seen.add(id(obj))
        if isinstance(obj, (tuple, list)):
            stack.extend(obj)
        elif hasattr(obj, "py_func") and isinstance(obj.py_func, types.FunctionType):
            # A Numba dispatcher (an inlined piece): its function named first, then its UUID.
            if "<locals>" in obj.py_func.__qualname__ and not getattr(obj.py_func, "_stochpend_named", False):
                obj.py_func.__qualname__ += suffix
                obj.py_func._stochpend_named = True  # type: ignore[attr-defined]
            _stable_uuid(obj)
            stack.append(obj.py_func)
        elif isinstance(obj, types.FunctionType):
            if "<locals>" in obj.__qualname__ and not getattr(obj, "_stochpend_named", False):
                obj.__qualname__ += suffix
                obj._stochpend_named = True  # type: ignore[attr-defined]  # read by getattr above
            for cell in obj.__closure__ or ():
                try:
                    stack.append(cell.cell_contents)
                except ValueError:  # an empty cell
                    pass


def _stable_uuid(dispatcher: Any) -> None:
    """Give a Numba dispatcher in a kernel's closure (an inlined piece, ``integrator._inline``) a
    UUID fixed by its function's module and qualname, in place of the random one Numba draws
    when it is first pickled. Numba keys a cached kernel on its closure's cells pickled, and a
    dispatcher pickles with its UUID: with a random one, every process had a new key, and
    compiled every lane machine afresh (tests/system/test_compile_time.py). The qualname carries
    the tag of what decides the code (:func:`name_closures`), so two dispatchers with one UUID
    are the same code. Numba's ``_MemoMixin`` (0.68, pinned) keeps the UUID in a private
    attribute; one already drawn is left as it is."""
    if getattr(dispatcher, "_MemoMixin__uuid", "drawn") is not None:
        return
    fn = dispatcher.py_func
    digest = hashlib.sha256(f"{fn.__module__}.{fn.__qualname__}".encode()).hexdigest()
    dispatcher._set_uuid(str(uuid.UUID(digest[:32])))


def _writable(directory: Path) -> bool:
    """Whether a cache could be written under ``directory`` (made if missing), as Numba tries."""
    import tempfile

    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
        return True
    except OSError:
        return False


def fall_back_to_a_temporary_cache() -> None:
    """With no writable kernel cache (a read-only install and an unwritable HOME: HPC modules,
    containers), Numba refuses every ``cache=True`` kernel ("no locator available"). Then
    cache in a private temporary directory, with a one-line note: the kernels compile once
    per process instead of once per machine. Runs before any kernel is decorated."""
    import os
    import sys
    import tempfile

    import numba
    from numba.misc.appdirs import AppDirs

    if numba.config.CACHE_DIR:
        return
    if _writable(_PACKAGE / "engine" / "__pycache__"):
        return
    if _writable(Path(AppDirs(appname="numba", appauthor=False).user_cache_dir)):
        return
    try:
        directory = tempfile.mkdtemp(prefix="stochpend-numba-cache-")
    except OSError:
        return  # nothing writable at all: Numba's own error says so
    import atexit
    import shutil

    atexit.register(shutil.rmtree, directory, ignore_errors=True)
    numba.config.CACHE_DIR = directory
    os.environ["NUMBA_CACHE_DIR"] = directory  # Dask workers and other children too
    if sys.stderr is not None:
        print(f"note: no writable Numba cache (read-only {_PACKAGE} and user cache); kernels are "
              f"cached in {directory} for this run (set NUMBA_CACHE_DIR to keep them)", file=sys.stderr)


fall_back_to_a_temporary_cache()


def own_index(key: str):
    """Decorator (under ``numba.njit(cache=True)`` or ``cuda.jit(cache=True)``): name a cached
    kernel after ``key`` (what decides its code besides the sources: the KernelSpec's label, the
    noise's name) and the code digest, so that it has its own cache index file, and name the
    closures it captures that have no name yet (:func:`name_closures`).

    The digest in the name makes a kernel of other code unreachable (see the module
    docstring). One index per KernelSpec also keeps racing processes apart: Numba keeps one index
    file per function and, when two processes add entries to it at once, both may pick the
    same data file name, so one KernelSpec's key could map to another KernelSpec's machine code (seen here:
    the dichotomous kernel running another noise's step after concurrent test processes).
    With one index per KernelSpec and code, processes that race write the same code.
    """

    def rename(fn):
        # Before the decorator above it makes the kernel: Numba fixes its CPU target when it makes
        # a process's first kernel (512-bit vectors on an AVX-512 host: stochpend.numerics._cputarget).
        _cputarget.configure_numba()
        fn.__qualname__ = f"{fn.__qualname__}_{tag(key)}"
        fn._stochpend_named = True
        name_closures([fn], key)
        return fn

    return rename


def in_cache(kernel) -> bool:
    """Whether calling the Numba dispatcher ``kernel`` will not compile: compiled (or loaded)
    in this process already, or with an index in Numba's on-disk cache (one per KernelSpec, see
    :func:`own_index`; a kernel of other code has another name, so no index). A kernel that is
    not cacheable (a user's model) is compiled once per process."""
    import os

    if getattr(kernel, "overloads", None):
        return True
    cache_file = getattr(getattr(kernel, "_cache", None), "_cache_file", None)
    index = getattr(cache_file, "_index_path", None)
    return index is not None and os.path.isfile(index)


class CompileClock:
    """Seconds Numba spent compiling (not loading from its cache) while installed; the first
    compile calls ``on_first_compile`` once, before that compile runs.

    A Numba ``numba:compile`` event fires only on a cache miss, around the compile itself, so a
    run whose kernels are cached reports 0 s and says nothing. Nested compiles (a kernel's
    inlined pieces) count once, inside their caller's interval. Use as a context manager.
    """

    def __init__(self, on_first_compile=None) -> None:
        self.seconds = 0.0
        self._depth = 0
        self._since = 0.0
        self._on_first = on_first_compile
        self._listener: Any = None

    def __enter__(self) -> CompileClock:
        import time

        from numba.core import event

        clock = self

        class _Listener(event.Listener):
            def on_start(self, ev) -> None:
                if clock._depth == 0:
                    if clock._on_first is not None:
                        first, clock._on_first = clock._on_first, None
                        first()
                    clock._since = time.perf_counter()
                clock._depth += 1

            def on_end(self, ev) -> None:
                clock._depth -= 1
                if clock._depth == 0:
                    clock.seconds += time.perf_counter() - clock._since

        self._listener = _Listener()
        event.register("numba:compile", self._listener)
        return self

    def __exit__(self, *exc) -> None:
        from numba.core import event

        event.unregister("numba:compile", self._listener)
