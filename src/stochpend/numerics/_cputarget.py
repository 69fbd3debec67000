"""The instruction set the CPU kernels are compiled for: this machine's own, or a fixed baseline.

Numba compiles every kernel for the host's CPU (its name and features: vector width, FMA, ...).
The kernels are written so that their numbers do not depend on it: no fast-math flags (so no
reassociation and no fused multiply-add contraction; LLVM must keep IEEE semantics), the
transcendental functions are the C library's or :mod:`stochpend.numerics.fastmath`'s branch-free ones,
and every sum runs in a fixed order (docs/development.md, "What is bit-identical, and where").
A machine with AVX-512 and one with AVX2 only then give the same bits, which the golden tests
check with the kernels compiled both ways (``make test-baseline``).

For a guarantee that does not rest on that reasoning (a heterogeneous cluster, two laptops), the
kernels can be compiled for one fixed target on every machine: :data:`BASELINE_NAME`
(x86-64-v3: AVX2, FMA, BMI2, the level of every x86-64 server and laptop since 2013-2015),
chosen by ``STOCHPEND_CPU_TARGET=baseline`` in the environment (set before Python starts: Dask
workers and child processes inherit it), ``stochpend --cpu-target baseline`` or
:func:`select` before the first kernel of the process compiles. Numba's cache keeps the two
targets' kernels apart (its index is keyed by the CPU name and features).

On an x86-64 host with AVX-512 the kernels are compiled with 512-bit vectors
(:func:`prefer_wide_vectors`): LLVM tunes Intel's AVX-512 server cores (``skylake-avx512`` to
``emeraldrapids``) to prefer 256-bit vectors, so Numba's lane loops ran there at half the width
the hardware has (AMD's ``znver4`` has no such preference). The width changes how many paths
one instruction steps, not a number.

Every result names the target its kernels were compiled for (the ``cpu_target`` attribute,
:func:`describe`).
"""

from __future__ import annotations

import os
import platform
import sys

#: The environment variable that chooses the target: ``host`` (default) or ``baseline``.
ENV = "STOCHPEND_CPU_TARGET"
TARGETS = ("host", "baseline")

#: LLVM's name for the x86-64-v3 micro-architecture level, and its features written out (Numba
#: needs both: with a name alone it would add the host's features).
BASELINE_NAME = "x86-64-v3"
BASELINE_FEATURES = ",".join(
    "+" + f for f in ("64bit", "avx", "avx2", "bmi", "bmi2", "cmov", "crc32", "cx16", "cx8", "f16c", "fma", "fxsr",
                      "lzcnt", "mmx", "movbe", "popcnt", "sahf", "sse", "sse2", "sse3", "sse4.1", "sse4.2", "ssse3",
                      "xsave"))
#: What the host must have to run baseline code (else: SIGILL, so it is refused first).
_BASELINE_NEEDS = ("avx", "avx2", "fma", "bmi", "bmi2", "f16c", "lzcnt", "movbe")


def _accepted() -> str:
    return f"{ENV} must be one of {', '.join(TARGETS)} (baseline: {BASELINE_NAME}, x86-64 with AVX2 and FMA)"


def requested() -> str:
    """The target the environment asks for (``host`` when unset); ValueError for another word."""
    value = os.environ.get(ENV, "").strip().lower() or "host"
    if value not in TARGETS:
        raise ValueError(f"{ENV}={os.environ.get(ENV)!r} is not accepted: {_accepted()}")
    return value


def _compiled() -> bool:
    """Whether Numba has made its CPU code generator in this process (its target is then fixed)."""
    numba = sys.modules.get("numba")
    if numba is None:
        return False
    from numba.core import registry

    return "_toplevel_target_context" in vars(registry.cpu_target)


def _host_supports_baseline() -> str | None:
    """None if this machine runs x86-64-v3 code, else why not."""
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return f"this machine is {platform.machine()}, the baseline is for x86-64"
    import llvmlite.binding as ll

    features = ll.get_host_cpu_features()
    missing = [f for f in _BASELINE_NEEDS if not features.get(f, False)]
    if missing:
        return f"this CPU lacks {', '.join(missing)}"
    return None


def select(target: str) -> None:
    """Compile this process's CPU kernels (and its children's) for ``target``.

    ``"baseline"``: :data:`BASELINE_NAME` on every machine; ``"host"``: this machine's own CPU
    (Numba's default). Must come before the process compiles or loads its first Numba kernel;
    afterwards only the target already in use is accepted. ValueError (one line) otherwise.
    """
    global _wide_features
    if target not in TARGETS:
        raise ValueError(f"cpu_target={target!r} is not accepted: one of {', '.join(TARGETS)}")
    if target == "baseline":
        why = _host_supports_baseline()
        if why is not None:
            raise ValueError(f"cpu_target='baseline' is not accepted: {why}")
        name, features = BASELINE_NAME, BASELINE_FEATURES
    else:
        name, features = None, None
    if _compiled():
        if current_name() != (name or _host_name()):
            raise ValueError(
                f"cpu_target={target!r} is not accepted: this process has compiled its kernels for "
                f"{current_name()} already; set {ENV}={target} before starting Python")
        os.environ[ENV] = target
        return
    os.environ[ENV] = target  # children (Dask workers, the CLI's subprocesses) inherit it
    for var, value in (("NUMBA_CPU_NAME", name), ("NUMBA_CPU_FEATURES", features)):
        if value is None:
            os.environ.pop(var, None)
        else:
            os.environ[var] = value
    numba = sys.modules.get("numba")
    if numba is not None:  # Numba read the environment at import: set its config directly
        numba.config.CPU_NAME = name
        numba.config.CPU_FEATURES = features
    if target == "host":  # the host's own features again, with 512-bit vectors where it has AVX-512
        _wide_features = None
        if numba is not None:
            prefer_wide_vectors()


def apply_environment() -> None:
    """Apply :data:`ENV` if it asks for the baseline (called before any kernel is compiled); for
    the host, 512-bit vectors where it has AVX-512 (:func:`prefer_wide_vectors`), once Numba is
    imported (``import stochpend`` loads neither Numba nor LLVM)."""
    if requested() == "baseline":
        select("baseline")
    elif "numba" in sys.modules:
        prefer_wide_vectors()


def configure_numba() -> None:
    """:func:`apply_environment` before a Numba kernel is made (``_jitcache.own_index``, which
    names every cached kernel, calls it under the ``numba.njit``), since Numba fixes its code
    generator (CPU name, features) when it makes a process's first kernel, compiled or not. An unknown
    ``STOCHPEND_CPU_TARGET`` is left to the run's own check (``RunOptions.build``). Imports Numba."""
    import numba  # noqa: F401 - the caller makes kernels; apply_environment acts once Numba is in

    try:
        apply_environment()
    except ValueError:
        pass


#: The LLVM feature that turns off its preference for 256-bit vectors on Intel's AVX-512 cores
#: (X86's ``TuningPrefer256Bit``; without it the preferred width is 512).
WIDE_FEATURE = "-prefer-256-bit"
#: The features this process set for its host (None: it set none).
_wide_features: str | None = None


def wide_features(features: dict[str, bool], flattened: str) -> str | None:
    """The features string for 512-bit vectors: ``flattened`` (LLVM's host features, ``+avx,...``)
    with :data:`WIDE_FEATURE`, where ``features`` (the same as a map) has AVX-512; else None."""
    if not features.get("avx512f", False):
        return None
    return f"{flattened},{WIDE_FEATURE}"


def prefer_wide_vectors() -> bool:
    """Compile this process's kernels for its host with 512-bit vectors where the host has
    AVX-512: the host's own CPU name and features, with LLVM's 256-bit preference off.

    On a 2-vCPU Intel Xeon (``emeraldrapids``, 2026-11-29) this took the fixed-step OU pendulum
    from 75-83 to 89-103 M path-steps/s and the adaptive lanes from 33-46 to 45-48, the numbers
    the same to the bit (``python -m benchmarks.vector_width``, docs/performance.md). Does nothing (returns False) for the baseline target,
    where ``NUMBA_CPU_NAME`` or ``NUMBA_CPU_FEATURES`` is set (the user's own choice), off x86-64,
    or once Numba has compiled (its code generator is fixed then). Returns whether this process's
    kernels are compiled so. Sets Numba's configuration, not the environment: a child process
    decides for itself."""
    global _wide_features
    import numba

    if _wide_features is not None:
        return numba.config.CPU_FEATURES == _wide_features
    if (requested() != "host" or _compiled() or platform.machine().lower() not in ("x86_64", "amd64")
            or numba.config.CPU_NAME is not None or numba.config.CPU_FEATURES is not None):
        return False
    import llvmlite.binding as ll

    features = ll.get_host_cpu_features()
    wide = wide_features(dict(features), features.flatten())
    if wide is None:
        return False
    numba.config.CPU_NAME = str(ll.get_host_cpu_name())
    numba.config.CPU_FEATURES = _wide_features = wide
    return True


def _host_name() -> str:
    import llvmlite.binding as ll

    return str(ll.get_host_cpu_name())


def current_name() -> str:
    """The CPU name Numba compiles for in this process (LLVM's name, e.g. ``znver4``)."""
    import numba

    return str(numba.config.CPU_NAME or _host_name())


def describe() -> str:
    """What a result's ``cpu_target`` attribute says: the CPU name the kernels were compiled for
    and why, e.g. ``"znver4 (host)"`` or ``"x86-64-v3 (baseline)"``. In a process that has
    made no kernel yet (a Dask worker asked before its first task) it first settles what they
    will be compiled for (:func:`configure_numba`), so that the answer holds for them."""
    configure_numba()
    import numba

    name = current_name()
    if name == BASELINE_NAME and numba.config.CPU_FEATURES == BASELINE_FEATURES:
        return f"{name} (baseline)"
    if _wide_features is not None and numba.config.CPU_FEATURES == _wide_features:
        return f"{name} (host, 512-bit vectors)"
    if numba.config.CPU_NAME:
        return f"{name} (NUMBA_CPU_NAME, features {numba.config.CPU_FEATURES or 'host'})"
    return f"{name} (host)"


def planned() -> str:
    """:func:`describe` without importing Numba or LLVM (``stochpend info`` starts fast): what
    this process's kernels will be compiled for, from the environment; the host by its model
    name (LLVM's name of it appears in a result's ``cpu_target``)."""
    try:
        target = requested()
    except ValueError as exc:
        return f"unknown ({exc})"
    if target == "baseline":
        return f"{BASELINE_NAME} (baseline)"
    name = os.environ.get("NUMBA_CPU_NAME")
    if name:
        return f"{name} (NUMBA_CPU_NAME, features {os.environ.get('NUMBA_CPU_FEATURES') or 'host'})"
    wide = (", 512-bit vectors" if os.environ.get("NUMBA_CPU_FEATURES") is None
            and "avx512f" in _cpuinfo("flags").split() else "")
    return f"this machine's CPU (host: {_model_name()}{wide})"


def _cpuinfo(field: str) -> str:
    """The first value of ``field`` in /proc/cpuinfo ("" where there is none)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.split(":", 1)[0].strip() == field:
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def _model_name() -> str:
    return _cpuinfo("model name") or platform.processor() or platform.machine()
