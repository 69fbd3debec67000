"""The CPU kernels at LLVM's preferred vector width against 512-bit vectors: a benchmark, not a timed test.

    .venv/bin/python -m benchmarks.vector_width            # 3 interleaved rounds
    .venv/bin/python -m benchmarks.vector_width --rounds 5

On a host with AVX-512 stochpend compiles its kernels with 512-bit vectors
(:func:`stochpend.numerics._cputarget.prefer_wide_vectors`). Setting ``NUMBA_CPU_FEATURES`` to
the host's own features (LLVM's, unchanged) turns that off, which gives back LLVM's choice:
256-bit vectors on Intel's AVX-512 server cores, 512-bit on AMD's Zen 4. Each round runs one
process of each kind, one after the other, with the same warm kernel cache; each process times
the OU pendulum (D = tau = omega = 1, 10^4 paths to t = 100, no bias pairs) at the fixed step
h = 0.01 and at the default adaptive step (best of 3 runs each, path-steps per second of
``wall_time_s``), and one ``target_error=3e-3`` run at t = 10 (its wall time; the first round
may include compiling). The processes print ``mean_E`` of that run, which must agree to the bit.
Compare rows of one run only.
"""

from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

_WORKER = """
import time, stochpend
rates = {}
for mode, kw in (("fixed", dict(h_max=0.01, step_c=0.0)), ("adaptive", {})):
    best = 0.0
    for _ in range(3):
        ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=10000, t_max=100.0, seed=5,
                                bias_paths=0, progress=False, **kw)
        best = max(best, float(ds.attrs["path_steps"]) / float(ds.attrs["wall_time_s"]) / 1e6)
    rates[mode] = best
t = time.perf_counter()
ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, t_max=10.0, times=[10.0], target_error=3e-3,
                        seed=1, progress=False)
print(ds.attrs["cpu_target"], rates["fixed"], rates["adaptive"], time.perf_counter() - t,
      repr(float(ds["mean_E"].values[-1])), sep="|")
"""


def _host_features() -> str:
    import llvmlite.binding as ll

    return str(ll.get_host_cpu_features().flatten())


def run_one(llvm_choice: bool) -> list[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES",
                                                          "STOCHPEND_CPU_TARGET")}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT / "src"), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    if llvm_choice:
        env["NUMBA_CPU_FEATURES"] = _host_features()
    proc = subprocess.run([sys.executable, "-c", _WORKER], capture_output=True, text=True, env=env, check=True)
    return proc.stdout.strip().splitlines()[-1].split("|")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args(argv)
    print(f"# {platform.machine()}, {os.cpu_count()} CPUs; M path-steps/s (best of 3), target run's wall")
    print("| round | kernels (cpu_target) | fixed h = 0.01 | adaptive | target 3e-3 at t = 10 | mean_E |")
    print("|---|---|---:|---:|---:|---|")
    for r in range(1, args.rounds + 1):
        for llvm_choice in (True, False):
            target, fixed, adaptive, seconds, mean = run_one(llvm_choice)
            print(f"| {r} | {target} | {float(fixed):.1f} | {float(adaptive):.1f} | {float(seconds):.2f} s | {mean} |",
                  flush=True)


if __name__ == "__main__":
    main()
