"""What one short path costs, piece by piece (issue 35, "Fast"): a benchmark, not a timed test.

    .venv/bin/python -m benchmarks.path_start                 # OU pendulum, h = 0.2, 4e6 paths
    .venv/bin/python -m benchmarks.path_start --paths 1e6 --steps 1,5,50

A multilevel target's level 0 runs many short paths (5 steps of h_0 = 0.2 to t = 1, 50 to
t = 10), so what a path costs beyond its steps bounds its speed-up over one fine level
(benchmarks/RESULTS_ACCURACY.md, "Where (a)'s time goes"). Two measurements, on the CPU
engine with the threads Numba has (``NUMBA_NUM_THREADS``), the kernels compiled untimed first:

* ``runner.run_batches`` of the whole ensemble at 1, 5 and 50 steps a path (one output time,
  one energy bin, as a target's level runs): the wall time a path; the slope over the steps is
  the cost of a step, the intercept that of a path's start and statistics.
* the chunk engine's three calls for one-step paths, timed apart over chunks of 5e5 paths:
  ``start`` (the initial conditions: the uniform angle and the noise's stationary xi_0, drawn
  with Philox and Box-Muller), ``advance`` (the step, with the loop's set-up) and
  ``accumulate`` (the statistics table's seven values and the histogram at the output time).

Times are walls divided by paths (ns a path, all threads together): compare rows of one run.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from stochpend.engine import cpu, runner
from stochpend.model.settings import SimulationConfig, hist_edges

H = 0.2


def _config(paths: int, steps: int) -> SimulationConfig:
    t = H * steps
    return SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, t_max=t, times=(t,), paths=paths,
                                  h_max=H, step_c=0.0, hist_bins=1, seed=1, n_batches=32)


def per_path(paths: int, steps: int, repeats: int) -> float:
    """The least wall time a path (ns) of ``repeats`` runs of ``run_batches``, after one untimed."""
    cfg = _config(paths, steps)
    best = float("inf")
    for r in range(repeats + 1):
        t0 = time.perf_counter()
        runner.run_batches(cfg, 0, cfg.n_batches)
        wall = time.perf_counter() - t0
        if r:
            best = min(best, wall)
    return best / paths * 1e9


def pieces(chunks: int, n: int = 500_000) -> dict[str, float]:
    """ns a path of the engine's start, advance (one step) and accumulate, over ``chunks``
    chunks of ``n`` paths after one untimed."""
    cfg = _config(n * (chunks + 1), 1)
    engine = cpu.Engine(cfg, cpu.spec_for(cfg), n, 4)
    edges = np.ascontiguousarray(hist_edges(cfg), dtype=np.float64)
    spent = {"start": 0.0, "advance": 0.0, "accumulate": 0.0}
    for c in range(chunks + 1):
        a = time.perf_counter()
        engine.start(c * n, n, 4)
        b = time.perf_counter()
        engine.advance(cfg.t_max, 10**9)
        d = time.perf_counter()
        engine.accumulate(0, edges[0])
        e = time.perf_counter()
        if c:
            spent["start"] += b - a
            spent["advance"] += d - b
            spent["accumulate"] += e - d
    return {k: v / (chunks * n) * 1e9 for k, v in spent.items()}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--paths", type=float, default=4e6, help="paths of each run_batches row (default 4e6)")
    ap.add_argument("--steps", default="1,5,50", help="steps a path of the rows (default 1,5,50)")
    ap.add_argument("--repeats", type=int, default=3, help="timed runs a row, the least kept (default 3)")
    ap.add_argument("--chunks", type=int, default=8, help="timed chunks for the pieces (default 8)")
    ap.add_argument("--chunk-paths", type=float, default=5e5, help="paths a chunk (default 5e5)")
    args = ap.parse_args(argv)
    import numba

    print(f"# {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
          f"{numba.get_num_threads()} Numba threads; OU pendulum D = tau = omega = 1, h = {H}")
    steps = [int(s) for s in args.steps.split(",")]
    rows = [(s, per_path(int(args.paths), s, args.repeats)) for s in steps]
    print("| steps a path | ns a path |\n|---:|---:|")
    for s, ns in rows:
        print(f"| {s} | {ns:.1f} |")
    if len(rows) >= 2:
        slope, intercept = np.polyfit([s for s, _ in rows], [ns for _, ns in rows], 1)
        print(f"\nfit: {slope:.2f} ns a step, {intercept:.1f} ns a path's start and statistics "
              f"({intercept / slope:.1f} steps' worth)")
    p = pieces(args.chunks, int(args.chunk_paths))
    print("\none-step paths, the engine's calls apart (ns a path): "
          + ", ".join(f"{k} {v:.1f}" for k, v in p.items()) + f"; sum {sum(p.values()):.1f}")


if __name__ == "__main__":
    main()
