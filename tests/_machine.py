"""What kind of machine the suite runs on, for the tests whose expected bits belong to one kind."""

from __future__ import annotations

import functools
import platform
import sys


@functools.cache
def golden_machine() -> str | None:
    """None on a machine that computes the golden fixtures' bits (x86-64 with AVX2 and FMA,
    Linux's glibc: its FMA variants of exp, log, sin, cos and pow), else what this machine is."""
    machine = platform.machine().lower()
    if machine not in ("x86_64", "amd64"):
        return f"this machine is {platform.machine()}"
    if not sys.platform.startswith("linux") or platform.libc_ver()[0] != "glibc":
        return f"this machine runs {sys.platform} without glibc"
    import llvmlite.binding as ll

    features = ll.get_host_cpu_features()
    missing = [f for f in ("avx2", "fma") if not features.get(f, False)]
    return f"this CPU lacks {' and '.join(missing)}" if missing else None
