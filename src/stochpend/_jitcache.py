"""Keep Numba's on-disk cache honest.

Numba invalidates a cached kernel when the kernel's own source file changes, but not when a
function it inlines from another module does (the integrator, the noises, the oscillators,
``rng``). Kernels built from closures are also keyed by their closure's pickled functions, but
a function referred to by module name (``rng.draw_normals``) is pickled by reference only. Each kernel module calls :func:`drop_stale_cache` at import: it hashes the kernel
module together with the shared modules and deletes the module's cache files when the hash
differs from the one recorded beside them, so an edit anywhere recompiles.

Numba names each compiled function ``<qualname>$<n>``, with ``n`` from a counter that is
unique in one process only, and a cached kernel calls the pieces it does not inline by those
names. A process that compiles other pieces first (another Spec's ``build.<locals>.advance_path``)
can give them the very names a cached kernel was written with, and the kernel, once loaded,
then calls them: another noise's step, wrong numbers, no error. :func:`salt_unique_ids` (run
at import) starts the counter at a random point per process, so names written by different
processes never meet.
"""

from __future__ import annotations

import hashlib
import itertools
import secrets
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent
SHARED_SOURCES = ("integrator.py", "rng.py", "mathlib.py", "fastmath.py", "stats.py",
                  "noises", "oscillators")
#: Part of the cache stamp: caches written before the counter was salted are dropped.
_NAMING = b"numba unique ids salted per process (1)"


def salt_unique_ids() -> None:
    """Start Numba's per-function counter at a random multiple of 2**20 below 2**60 (once per
    process): two processes then share a function name with probability ~2**-40."""
    from numba.core.bytecode import FunctionIdentity

    if not getattr(FunctionIdentity, "_stochpend_salted", False):
        FunctionIdentity._unique_ids = itertools.count((secrets.randbits(40) + 1) << 20)
        FunctionIdentity._stochpend_salted = True


salt_unique_ids()


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
    if _writable(_PACKAGE / "_backends" / "__pycache__"):
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


def drop_stale_cache(module_file: str) -> None:
    """Delete ``module_file``'s Numba cache if it or a shared source changed since it was built."""
    module = Path(module_file).resolve()
    digest = hashlib.sha256(_NAMING)
    for path in [module, *(_PACKAGE / name for name in SHARED_SOURCES)]:
        for file in sorted(path.glob("*.py")) if path.is_dir() else [path]:
            if file.is_file():
                digest.update(file.read_bytes())
    cache_dir = module.parent / "__pycache__"
    stamp = cache_dir / f"{module.stem}.sources.sha256"
    try:
        if stamp.is_file() and stamp.read_text() == digest.hexdigest():
            return
        for pattern in (f"{module.stem}.*.nbi", f"{module.stem}.*.nbc"):
            for stale in cache_dir.glob(pattern):
                stale.unlink(missing_ok=True)
        cache_dir.mkdir(exist_ok=True)
        stamp.write_text(digest.hexdigest())
    except OSError:  # a read-only install: Numba then compiles in memory or uses its own dir
        pass


def own_index(key: str):
    """Decorator (under ``numba.njit(cache=True)``): give a kernel built per Spec its own cache
    index file, named after ``key`` (the Spec's label).

    Numba keeps one index file per function (its qualified name and line) and, when two
    processes add entries to it at once, both may pick the same data file name: the index can
    end up mapping one Spec's key to another Spec's machine code, which a later process then
    runs without a word (seen here: the dichotomous kernel running another noise's step after
    concurrent test processes). With one index per Spec, processes that race write the same
    Spec's code, so whichever write wins is right.
    """
    tag = hashlib.sha256(key.encode()).hexdigest()[:16]

    def rename(fn):
        fn.__qualname__ = f"{fn.__qualname__}_{tag}"
        return fn

    return rename


def in_cache(kernel) -> bool:
    """Whether calling the Numba dispatcher ``kernel`` will not compile: compiled (or loaded)
    in this process already, or with an index in Numba's on-disk cache (one per Spec, see
    :func:`own_index`; :func:`drop_stale_cache` removes stale ones at import). A kernel that is
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
        self._listener = None

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
