"""The code that made these numbers: one definition for kernel caches, checkpoints, sweeps
and cached figure runs.

:data:`NUMBERS_SOURCES` names the package's files and folders that decide a simulated number
(every ``.py`` file of a folder counts, so a new noise or oscillator is covered);
:func:`digest` hashes them as installed. The kernel caches put the digest in every cached
kernel's name (:mod:`stochpend.numerics._jitcache`), checkpoints and sweep workers compare
:data:`BUILD`, and ``reproduce`` keys its stored runs with the digest: an edit of any of these
files, or an upgrade, can never reuse numbers made by other code.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path

from stochpend._version import __version__

__all__ = ["NUMBERS_SOURCES", "digest", "BUILD"]

_PACKAGE = Path(__file__).resolve().parent.parent  # the package's root

#: Files and folders of the package whose code decides a simulated number.
NUMBERS_SOURCES = ("model/settings.py", "numerics/rng.py", "numerics/mathlib.py", "numerics/fastmath.py",
                   "engine/integrator.py", "engine/runner.py", "runs/simulate.py", "model/power_sums.py",
                   "model/observables.py", "model/passage.py", "model/user_models.py", "model/dynamics.py",
                   "model/initial.py", "runs/bias.py", "runs/reduced.py", "numerics/_jitcache.py",
                   "engine/cpu.py", "engine/cuda.py", "engine/joint.py", "model/noises",
                   "model/oscillators", "model/terms")


@functools.lru_cache(maxsize=1)
def digest() -> str:
    """SHA-256 (hex) of :data:`NUMBERS_SOURCES` as installed: each file's path relative to the
    package, then its bytes, in sorted order."""
    h = hashlib.sha256()
    for name in NUMBERS_SOURCES:
        path = _PACKAGE / name
        for file in sorted(path.glob("*.py")) if path.is_dir() else [path]:
            h.update(file.relative_to(_PACKAGE).as_posix().encode() + b"\0")
            h.update(file.read_bytes())
    return h.hexdigest()


#: This process's stochpend: version and code digest (12 hex digits). Checkpoints record it;
#: every sweep worker must have the same.
BUILD = f"{__version__} (code {digest()[:12]})"
