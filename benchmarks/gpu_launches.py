"""Kernel launches, host synchronisations and copies of a CUDA-backend run, counted without a GPU.

Runs ``stochpend.simulate(..., backend="cuda")`` in Numba's CUDA simulator with the simulator's
kernel launch (``FakeCUDAKernel.__call__``) and its device arrays' copies and allocations
wrapped to count them, then profiles the host side (cProfile of the main thread: the
simulator runs each block's threads in other threads, so the kernels' own work is not in the
profile, only the host waiting on them inside the launch call)::

    python benchmarks/gpu_launches.py [--paths 64] [--n-times 12] [--t-max 10] [--profile 15]

What counts as a host synchronisation on a real GPU: every ``copy_to_host`` (it waits for the
kernels before it) and every ``copy_to_device`` of pageable host memory (numba-cuda's default
stream: it waits too). Launches are asynchronous. The counts do not depend on the simulator,
except the advance relaunches, which depend on ``max_steps = max(1000, 2**31 / paths)``: at the
tiny sizes the simulator can run every segment takes one launch; at 10**8 paths a launch takes
at most 1000 steps (``cuda.Engine.max_steps``).
"""

from __future__ import annotations

import argparse
import collections
import cProfile
import io
import os
import platform
import pstats
import sys
import time
from pathlib import Path

os.environ["NUMBA_ENABLE_CUDASIM"] = "1"  # before numba is imported
ROOT = Path(__file__).resolve().parent.parent
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

import numpy as np  # noqa: E402
from numba.cuda.simulator import kernel as sim_kernel  # noqa: E402
from numba.cuda.simulator.cudadrv import devicearray as sim_array  # noqa: E402


class Counts:
    def __init__(self) -> None:
        self.launches: collections.Counter = collections.Counter()
        self.blocks: collections.Counter = collections.Counter()
        self.to_host = 0
        self.to_host_bytes = 0
        self.to_device = 0
        self.to_device_bytes = 0
        self.kernel_seconds = 0.0
        self.sites: collections.Counter = collections.Counter()


def _site() -> str:
    """The stochpend function (class.method) that asked for the copy."""
    frame = sys._getframe(2)
    while frame is not None and "stochpend" not in frame.f_code.co_filename:
        frame = frame.f_back
    while frame is not None and frame.f_code.co_name.startswith("<") and frame.f_back is not None:
        frame = frame.f_back  # a generator expression: the function that ran it
    if frame is None:
        return "?"
    owner = frame.f_locals.get("self")
    prefix = f"{type(owner).__name__}." if owner is not None else ""
    return f"{Path(frame.f_code.co_filename).stem}: {prefix}{frame.f_code.co_name}"


COUNTS = Counts()


def _instrument() -> None:
    launch = sim_kernel.FakeCUDAKernel.__call__
    to_host = sim_array.FakeCUDAArray.copy_to_host
    to_device = sim_array.FakeCUDAArray.copy_to_device

    def counted_launch(self, *args):
        if self._device:  # a device function called from a kernel: not a launch
            return launch(self, *args)
        name = getattr(self.fn, "__name__", "?")
        COUNTS.launches[name] += 1
        COUNTS.blocks[name] += int(np.prod(self.grid_dim))
        started = time.perf_counter()
        try:
            return launch(self, *args)
        finally:
            COUNTS.kernel_seconds += time.perf_counter() - started

    def counted_to_host(self, ary=None, stream=0):
        COUNTS.to_host += 1
        COUNTS.sites["to host", _site()] += 1
        COUNTS.to_host_bytes += self._ary.nbytes
        return to_host(self, ary, stream)

    def counted_to_device(self, ary, stream=0):
        COUNTS.to_device += 1
        COUNTS.sites["to device", _site()] += 1
        COUNTS.to_device_bytes += np.asarray(ary).nbytes if not isinstance(ary, sim_array.FakeCUDAArray) else 0
        return to_device(self, ary, stream)

    sim_kernel.FakeCUDAKernel.__call__ = counted_launch
    sim_array.FakeCUDAArray.copy_to_host = counted_to_host
    sim_array.FakeCUDAArray.copy_to_device = counted_to_device


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, naming the parameter, exit 2
        self.exit(2, f"gpu_launches: error: {message}\n")


def main(argv: list[str] | None = None) -> int:
    parser = _Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--paths", type=int, default=64)
    parser.add_argument("--batches", type=int, default=2)
    parser.add_argument("--n-times", type=int, default=12)
    parser.add_argument("--t-max", type=float, default=10.0)
    parser.add_argument("--bias-paths", type=int, default=32)
    parser.add_argument("--profile", type=int, default=15, help="host functions listed (by own time)")
    args = parser.parse_args(argv)
    _instrument()
    import stochpend
    from stochpend.observables import DISPLACEMENT, LOG_ENERGY

    run = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=args.paths, n_batches=args.batches,
               t_max=args.t_max, n_times=args.n_times, seed=5, bias_paths=args.bias_paths,
               observables=(DISPLACEMENT.name, LOG_ENERGY.name), joint_bins=(8, 8), backend="cuda")
    # compile every kernel first (the CPU's pair sums of the bias estimate too): counted is the run
    try:
        stochpend.simulate(**{**run, "paths": 4 * args.batches, "t_max": 0.1, "bias_paths": 2 * args.batches})
    except ValueError as error:  # a bad --paths, --n-times, ...: the library's one line
        print(f"gpu_launches: error: {' '.join(str(error).split())}", file=sys.stderr)
        return 2
    global COUNTS
    COUNTS = Counts()
    profile = cProfile.Profile()
    started = time.perf_counter()
    profile.enable()
    try:
        stochpend.simulate(**run)
    except ValueError as error:
        print(f"gpu_launches: error: {' '.join(str(error).split())}", file=sys.stderr)
        return 2
    finally:
        profile.disable()
    wall = time.perf_counter() - started
    c = COUNTS
    n_times = args.n_times
    print(f"Counted in Numba's CUDA simulator on {platform.node()} ({platform.processor() or platform.machine()}, "
          f"{os.cpu_count()} CPUs), Python {platform.python_version()}: stochpend.simulate(noise='ou', D=1, tau=1, "
          f"omega=1, paths={args.paths}, n_batches={args.batches}, t_max={args.t_max:g}, n_times={n_times}, "
          f"bias_paths={args.bias_paths}, observables=(displacement, log_energy), joint_bins=(8, 8), backend='cuda').")
    print()
    print("| kernel | launches | per output time | blocks launched |")
    print("|---|---:|---:|---:|")
    for name, count in sorted(c.launches.items()):
        print(f"| {name} | {count} | {count / n_times:.2f} | {c.blocks[name]} |")
    total = sum(c.launches.values())
    print(f"| all | {total} | {total / n_times:.2f} | {sum(c.blocks.values())} |")
    print()
    print("| host synchronisation | count | per output time | bytes |")
    print("|---|---:|---:|---:|")
    print(f"| copy_to_host (device -> host, waits for the kernels) | {c.to_host} | {c.to_host / n_times:.2f} | {c.to_host_bytes} |")
    print(f"| copy_to_device (host -> device, pageable: synchronous) | {c.to_device} | {c.to_device / n_times:.2f} "
          f"| {c.to_device_bytes} |")
    print()
    print("| copy | asked for by | count | per output time |")
    print("|---|---|---:|---:|")
    for (direction, site), count in sorted(c.sites.items()):
        print(f"| {direction} | {site} | {count} | {count / n_times:.2f} |")
    print()
    print(f"Wall time {wall:.2f} s, of which {c.kernel_seconds:.2f} s inside kernel launches (the simulator running "
          f"the kernels) and {wall - c.kernel_seconds:.2f} s host side.")
    out = io.StringIO()
    stats = pstats.Stats(profile, stream=out)
    stats.sort_stats("tottime").print_stats(r"stochpend", args.profile)
    print()
    print("Host profile (cProfile, main thread, stochpend's functions by own time):")
    print("```")
    print("\n".join(line for line in out.getvalue().splitlines() if line.strip())[-4000:])
    print("```")
    return 0


if __name__ == "__main__":
    sys.exit(main())
