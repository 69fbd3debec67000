"""Time the CUDA backend on a GPU and append the results to benchmarks/RESULTS_GPU.md.

Run on a machine with an NVIDIA GPU and the ``cuda`` extra installed (numba-cuda with a CUDA
toolkit, e.g. ``pip install -e ".[cuda]" "numba-cuda[cu12]"``)::

    python benchmarks/gpu_bench.py                      # 1e6, 1e7, 1e8 paths, float64 + float32
    python benchmarks/gpu_bench.py --paths 1e6 --steps 100 --no-record

The case is the issue's: OU noise, D = 1, tau = 1, omega = 1, fixed step h = 0.01
(``step_c=0``), ``--steps`` steps (t_max = steps * h), 100 batches, 4 output times, seed 2024.
For every ensemble size and precision the whole ``cuda.run_batches`` call is timed (after a
warm-up call that compiles the kernels), including the statistics and the copies back.

Before timing, a small ensemble (``--check-paths``) with the same seed is run on the CPU and on
the GPU and compared: the batch sums (relative), the statistics (in standard errors), the
histograms, and path by path the final (theta, Omega, xi) and step counts (docs/gpu.md says what
to expect). With no usable GPU the script prints one line and exits with status 2.
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

from stochpend import __version__  # noqa: E402
from stochpend._backends import cpu  # noqa: E402
from stochpend._backends import cuda as gpu  # noqa: E402
from stochpend.params import SimulationConfig  # noqa: E402
from stochpend.runner import run_batches as cpu_run_batches  # noqa: E402

H = 0.01
SEED = 2024
N_TIMES = 4
N_BATCHES = 100
RESULTS = ROOT / "benchmarks" / "RESULTS_GPU.md"

#: Pass criteria of the agreement check (docs/gpu.md, "Expected CPU/GPU differences").
F64_SUMS_RTOL = 1e-9
F32_MAX_SE = 0.5


def make_config(paths: int, steps: int, batches: int = N_BATCHES) -> SimulationConfig:
    """The benchmark case."""
    t_max = steps * H
    times = [t_max * (j + 1) / N_TIMES for j in range(N_TIMES)]
    return SimulationConfig.build(
        noise="ou", D=1.0, tau=1.0, omega=1.0, paths=paths, t_max=t_max, times=times,
        seed=SEED, h_max=H, step_c=0.0, n_batches=batches,
    )


def cpu_path_states(config: SimulationConfig, n: int) -> dict[str, np.ndarray]:
    """Paths 0..n-1 through every output time with the CPU kernels (as run_batches does)."""
    engine = cpu.Engine(config, cpu.spec_for(config), n, 1)
    engine.start(0, n, 1)
    for t_target in config.times:
        while not engine.advance(float(t_target), 100_000):
            pass
    return {name: engine.arrays()[name] for name in ("x", "Omega", "xi", "t", "k", "status")}


def compare(reference, other) -> dict[str, float]:
    """Largest differences between two EnsembleSums of the same ensemble."""
    ref_sums, sums = reference.sums, other.sums
    scale = np.maximum(np.max(np.abs(ref_sums), axis=0, keepdims=True), 1e-300)
    stats_ref, stats = reference.statistics(), other.statistics()
    in_se = max(
        float(np.nanmax(np.abs(stats[name][0] - value) / se))
        for name, (value, se) in stats_ref.items()
    )
    return {
        "sums_rel": float(np.max(np.abs(sums - ref_sums) / scale)),
        "stats_in_se": in_se,
        "hist_moved": int(np.abs(other.hist - reference.hist).sum() // 2),
    }


def compare_paths(reference: dict, states: dict) -> dict[str, float]:
    dx = np.angle(np.exp(1j * (states["x"].astype(np.float64) - reference["x"])))  # wrap-aware
    return {
        "x": float(np.max(np.abs(dx))),
        "Omega": float(np.max(np.abs(states["Omega"] - reference["Omega"]))),
        "xi": float(np.max(np.abs(states["xi"] - reference["xi"]))),
        "steps_differ": int(np.sum(states["k"] != reference["k"])),
    }


def agreement(check_paths: int, steps: int, precisions: list[str],
              batches: int) -> tuple[list[str], bool, float]:
    """Run the small ensemble on both backends; returns report lines, pass flag, CPU rate."""
    config = make_config(check_paths, steps, batches)
    warm = make_config(min(check_paths, 1000), 2, batches)
    cpu_run_batches(warm, 0, warm.n_batches)  # compiles the CPU kernels
    started = time.perf_counter()
    ref, cpu_steps = cpu_run_batches(config, 0, config.n_batches)
    cpu_rate = cpu_steps / (time.perf_counter() - started)
    n_states = min(check_paths, 4096)
    ref_states = cpu_path_states(config, n_states)
    lines = [f"Agreement with the CPU backend, {check_paths} paths, seed {SEED} "
             f"(paths compared one by one: {n_states}):", ""]
    lines.append("| precision | batch sums: max rel. diff | statistics: max diff (std. errors) "
                 "| histogram counts moved | max abs. diff theta | max abs. diff Omega "
                 "| max abs. diff xi | paths with other step count | verdict |")
    lines.append("|---|---|---|---|---|---|---|---|---|")
    passed = True
    for precision in precisions:
        sums, steps_taken = gpu.run_batches(config, 0, config.n_batches, precision=precision)
        c = compare(ref, sums)
        p = compare_paths(ref_states, gpu.path_states(config, 0, n_states, precision=precision))
        if precision == "float64":
            ok = c["sums_rel"] <= F64_SUMS_RTOL and p["steps_differ"] == 0 and steps_taken == cpu_steps
        else:
            ok = c["stats_in_se"] <= F32_MAX_SE and steps_taken == cpu_steps
        passed &= ok
        lines.append(
            f"| {precision} | {c['sums_rel']:.2e} | {c['stats_in_se']:.2e} | {c['hist_moved']} "
            f"| {p['x']:.2e} | {p['Omega']:.2e} | {p['xi']:.2e} | {p['steps_differ']} "
            f"| {'pass' if ok else 'FAIL'} |"
        )
    lines.append("")
    lines.append(f"Pass criteria: float64 batch sums within {F64_SUMS_RTOL:g} (relative to each "
                 f"column's largest batch sum) and identical step counts; float32 statistics within "
                 f"{F32_MAX_SE} standard errors of the CPU.")
    return lines, passed, cpu_rate


def time_run(paths: int, steps: int, precision: str, batches: int) -> tuple[float, int]:
    config = make_config(paths, steps, batches)
    started = time.perf_counter()
    _, path_steps = gpu.run_batches(config, 0, config.n_batches, precision=precision)
    return time.perf_counter() - started, path_steps


def environment() -> str:
    import numba
    from numba import cuda

    parts = [f"stochpend {__version__}", f"numba {numba.__version__}",
             f"numba.cuda: {getattr(cuda, 'implementation', '?')}"]
    try:
        import numba_cuda

        parts.append(f"numba-cuda {numba_cuda.__version__}")
    except Exception:
        pass
    try:
        from numba.cuda.cudadrv.driver import driver

        parts.append("CUDA driver API " + ".".join(str(v) for v in driver.get_version()))
    except Exception:
        pass
    parts.append(f"Python {platform.python_version()}")
    return ", ".join(parts)


def _count(text: str) -> int:
    value = float(text)
    if value < 1 or value != int(value):
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number of paths >= 1")
    return int(value)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=_count, nargs="+", default=[10**6, 10**7, 10**8])
    parser.add_argument("--precisions", nargs="+", choices=gpu.PRECISIONS, default=list(gpu.PRECISIONS))
    parser.add_argument("--steps", type=int, default=300, help="steps of h = 0.01 (default 300)")
    parser.add_argument("--check-paths", type=_count, default=20_000,
                        help="paths of the CPU agreement check (0: skip it)")
    parser.add_argument("--batches", type=int, default=N_BATCHES, help="batches (default 100)")
    parser.add_argument("--results", type=Path, default=RESULTS, help="Markdown file to append to")
    parser.add_argument("--no-record", action="store_true", help="print only, append nothing")
    parser.add_argument("--allow-simulator", action="store_true",
                        help="run under NUMBA_ENABLE_CUDASIM=1 (tests the script; timings meaningless)")
    args = parser.parse_args(argv)

    ok, why = gpu.availability()
    if not ok or (gpu._simulator_enabled() and not args.allow_simulator):
        print(f"gpu_bench: no usable GPU: {why}", file=sys.stderr)
        return 2

    print(f"device: {why}")
    print(f"environment: {environment()}")
    lines: list[str] = []
    passed = True
    cpu_rate = float("nan")
    if args.check_paths:
        check_lines, passed, cpu_rate = agreement(args.check_paths, args.steps, args.precisions,
                                                    args.batches)
        print("\n".join(check_lines))
        lines += check_lines + [""]

    table = ["| paths | precision | wall (s) | path-steps | path-steps/s | speed-up vs CPU check run |",
             "|---:|---|---:|---:|---:|---:|"]
    print("\n".join(table))
    for precision in args.precisions:
        compile_started = time.perf_counter()
        time_run(1000, 2, precision, args.batches)  # compiles the kernels
        print(f"({precision}: first call, with compilation, {time.perf_counter() - compile_started:.1f} s)")
        for paths in args.paths:
            try:
                wall, path_steps = time_run(paths, args.steps, precision, args.batches)
            except Exception as error:  # e.g. out of device memory: record and go on
                row = f"| {paths:.0e} | {precision} | failed: {' '.join(str(error).split())[:120]} | | | |"
            else:
                rate = path_steps / wall
                speedup = rate / cpu_rate if math.isfinite(cpu_rate) else float("nan")
                row = (f"| {paths:.0e} | {precision} | {wall:.3f} | {path_steps:.3e} | {rate:.3e} "
                       f"| {speedup:.1f} |")
            print(row, flush=True)
            table.append(row)
    lines += table
    if math.isfinite(cpu_rate):
        lines += ["", f"CPU reference rate (the agreement run on this host, "
                      f"{platform.processor() or platform.machine()}): {cpu_rate:.3e} path-steps/s."]

    if not args.no_record:
        stamp = _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        header = [
            f"## {stamp}: {why}",
            "",
            f"{environment()}. OU noise, D = 1, tau = 1, omega = 1, fixed step h = {H} "
            f"(step_c = 0), {args.steps} steps (t_max = {args.steps * H:g}), {N_TIMES} output times, "
            f"{args.batches} batches, seed {SEED}; wall time of the whole cuda.run_batches call "
            "(kernels compiled beforehand).",
            "",
        ]
        new_file = not args.results.exists()
        with open(args.results, "a") as f:
            if new_file:
                f.write("# CUDA backend measurements\n\nAppended by `python benchmarks/gpu_bench.py` "
                        "(see docs/gpu.md).\n\n")
            f.write("\n".join(header + lines) + "\n\n")
        print(f"appended to {args.results}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
