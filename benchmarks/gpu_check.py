"""Everything the GPU has to show, in one command and one Markdown report (issue 34, item 7).

Run on a machine with an NVIDIA GPU (``make gpu-check``, or directly)::

    python benchmarks/gpu_check.py [--out out/gpu-check.md] [--quick] [--only STEP ...]

Steps, in this order (each timed; a failure is recorded and the next step runs):

* ``device-tests``: ``pytest tests/unit/test_cuda_device.py`` (Philox by the ``mul.wide.u32``
  intrinsic, known answers and draws against the CPU);
* ``bench``: ``benchmarks/gpu_bench.py --record`` (CPU agreement check, then stochpend against
  its CUDA C reference; appends to benchmarks/RESULTS_GPU.md);
* ``oracle``: the damped harmonic oscillator with white noise on the force and additive white
  noise on the GPU (float64 and float32), against the scheme's exact second-moment map (built
  from the integrator's own step function, no sampling: tests/statistical/test_family_dynamics.py
  does the same on the CPU), in standard errors;
* ``family``: the paper's pendulum with damping, the additive white noise and per-path
  accumulators (a time average, the displacement, a first passage, ln(E - E_min)) on the GPU
  and on the CPU, same seed: each statistic's difference in the CPU's standard errors;
* ``reproduce``: ``stochpend reproduce --backend cuda`` of a short case (``--reproduce``,
  default ``fig1 --quick``), its wall time and files.

The report states the device, the versions, and every figure of every step. Exit status: 0 when
every step passed, 1 when one failed, 2 without a usable GPU (one line; the CUDA simulator is
refused unless ``--allow-simulator``, which runs the steps at toy size to test this script).
"""

from __future__ import annotations

import argparse
import datetime as _dt
import math
import os
import platform
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT / "src") not in sys.path:
    sys.path.insert(0, str(ROOT / "src"))

STEPS = ("device-tests", "bench", "oracle", "family", "reproduce")
DEFAULT_OUT = ROOT / "out" / "gpu-check.md"
#: Standard errors within which a statistic must agree with its reference.
Z = 4.0


@dataclass
class Step:
    """One step's outcome: ``status`` passed, failed or skipped; ``lines`` its Markdown."""

    name: str
    status: str
    seconds: float
    lines: list[str] = field(default_factory=list)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, naming the parameter, exit 2 (no usage block)
        self.exit(2, f"gpu_check: error: {message}\n")


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    parser = _Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"the report (default {DEFAULT_OUT.relative_to(ROOT)})")
    parser.add_argument("--only", nargs="+", choices=STEPS, default=list(STEPS), metavar="STEP",
                        help=f"run only these steps ({', '.join(STEPS)})")
    parser.add_argument("--quick", action="store_true", help="smaller ensembles (about a minute of GPU)")
    parser.add_argument("--reproduce", default="fig1 --quick", help="the reproduce step's arguments")
    parser.add_argument("--allow-simulator", action="store_true",
                        help="run under NUMBA_ENABLE_CUDASIM=1 at toy size (tests this script; nothing measured)")
    return parser.parse_args(argv)


# -- the report -----------------------------------------------------------------------------
def versions() -> str:
    import numba

    parts = [f"Python {platform.python_version()}", f"numpy {np.__version__}", f"numba {numba.__version__}"]
    from importlib import metadata

    for name in ("stochpend", "numba-cuda", "nvidia-cuda-nvcc-cu12", "nvidia-nvjitlink-cu12"):
        try:
            parts.append(f"{name} {metadata.version(name)}")
        except metadata.PackageNotFoundError:
            pass
    try:
        from numba.cuda.cudadrv.driver import driver

        parts.append("CUDA driver API " + ".".join(str(v) for v in driver.get_version()))
    except Exception:
        pass
    return ", ".join(parts)


def report(device: str, environment: str, steps: list[Step], stamp: str) -> str:
    """The Markdown report: the device, the versions, a summary table, then each step's figures."""
    lines = [f"# GPU check, {stamp}", "", f"Device: {device}", "", f"Versions: {environment}", "",
             f"Host: {platform.node()} ({platform.processor() or platform.machine()}, {os.cpu_count()} CPUs)", "",
             "| step | status | wall (s) |", "|---|---|---:|"]
    lines += [f"| {s.name} | {s.status} | {s.seconds:.1f} |" for s in steps]
    for s in steps:
        lines += ["", f"## {s.name}: {s.status}", "", *s.lines]
    return "\n".join(lines) + "\n"


# -- steps ----------------------------------------------------------------------------------
def _subprocess(command: list[str], timeout: float = 3600.0) -> tuple[int, str]:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT / "src"), str(ROOT),
                                                                      os.environ.get("PYTHONPATH")) if p)}
    res = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=timeout)
    return res.returncode, res.stdout + res.stderr


def _fenced(text: str, last: int = 60) -> list[str]:
    kept = text.rstrip().splitlines()[-last:]
    return ["```", *kept, "```"]


def step_device_tests(args) -> tuple[bool | None, list[str]]:
    rc, out = _subprocess([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "-rs",
                           "tests/unit/test_cuda_device.py"])
    skipped = rc == 0 and " passed" not in out
    return (None if skipped else rc == 0), _fenced(out, 30)


def step_bench(args) -> tuple[bool | None, list[str]]:
    command = [sys.executable, "benchmarks/gpu_bench.py", "--record"]
    if args.allow_simulator:  # toy size, no reference, results not recorded
        command = [sys.executable, "benchmarks/gpu_bench.py", "--allow-simulator", "--paths", "64",
                   "--steps", "3", "--check-paths", "0", "--no-reference", "--precisions", "float64",
                   "--modes", "fixed"]
    elif args.quick:
        command += ["--paths", "1e6", "1e7"]
    rc, out = _subprocess(command)
    keep = [line for line in out.splitlines() if line.startswith(("|", "device", "environment", "(", "reference",
                                                                  "agreement", "appended", "CPU"))]
    return rc == 0, keep or _fenced(out)


def scheme_moments(h: float, n: int, D: float, d: tuple, x0: float = 1.0) -> np.ndarray:
    """(<x^2>, <x Omega>, <Omega^2>) after n steps h of the damped harmonic oscillator with white
    noise D on the force and the additive white noise (family record d), start (x0, 0): the
    scheme is linear in the state, so its second moments follow an exact map read off the
    kernel's own step function (as tests/statistical/test_family_dynamics.py)."""
    from stochpend.engine import integrator

    B0, B1, a = integrator.linear_step_maps(h, d, {"damping", "additive"})
    M = np.array([[x0 * x0, 0.0], [0.0, 0.0]])
    for _ in range(n):
        M = B0 @ M @ B0.T + D * h * (B1 @ M @ B1.T) + np.outer(a, a)
    return np.array([M[0, 0], M[0, 1], M[1, 1]])


def step_oracle(args) -> tuple[bool | None, list[str]]:
    from types import SimpleNamespace

    import stochpend
    from stochpend.model import dynamics

    D, gamma, D_a, h = 0.5, 0.7, 0.3, 0.1
    times = (1.0, 4.0)
    paths = 64 if args.allow_simulator else (10**6 if args.quick else 10**7)
    d = dynamics.record(SimpleNamespace(dyn_params=dynamics.resolve({"gamma": gamma, "additive_D": D_a})))
    lines = [f"Harmonic oscillator, white noise D = {D} on the force, damping gamma = {gamma}, additive "
             f"white noise D_a = {D_a}, fixed h = {h}, start (1, 0), {paths} paths, seed 7; reference: the "
             f"scheme's exact moment map. Pass: every |z| < {Z:g}.", "",
             "| precision | t | statistic | GPU | scheme (exact) | GPU std. error | z |", "|---|---:|---|---:|---:|---:|---:|"]
    ok = True
    for precision in ("float64", "float32"):
        ds = stochpend.simulate(noise="white", D=D, omega=1.0, potential="harmonic", paths=paths, t_max=4.0,
                                times=times, seed=7, theta0=1.0, Omega0=0.0, h_max=h, step_c=0.0, gamma=gamma,
                                additive_D=D_a, bias_paths=0, backend="cuda", precision=precision)
        for i, t in enumerate(times):
            x2, _, O2 = scheme_moments(h, round(t / h), D, d)
            for name, want in (("mean_sin2theta", x2), ("mean_Omega2", O2)):
                value, se = float(ds[name][i]), float(ds[f"{name}_stderr"][i])
                z = (value - want) / se
                ok = ok and abs(z) < Z
                lines.append(f"| {precision} | {t:g} | {name} | {value:.6g} | {want:.6g} | {se:.2g} | {z:+.2f} |")
    return ok, lines


def step_family(args) -> tuple[bool | None, list[str]]:
    import stochpend
    from stochpend.observables import DISPLACEMENT, LOG_ENERGY, FirstPassage, TimeAverage, register, unregister

    extra = (TimeAverage("gc_Om2_avg", lambda x, Omega, xi, t: Omega * Omega, window=(0.0, 2.0)),
             FirstPassage("gc_escape", lambda x, Omega, xi, t: 0.5 * Omega * Omega - math.cos(x), threshold=1.5))
    for o in extra:
        register(o)
    names = ("gc_Om2_avg", "gc_escape", DISPLACEMENT.name, LOG_ENERGY.name)
    paths = 64 if args.allow_simulator else (10**5 if args.quick else 10**6)
    run = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=paths, t_max=2.0, times=(1.0, 2.0), seed=21,
               gamma=0.3, additive_D=0.2, bias_paths=0, observables=names)
    try:
        started = time.perf_counter()
        gpu = stochpend.simulate(**run, backend="cuda")
        gpu_s = time.perf_counter() - started
        started = time.perf_counter()
        cpu = stochpend.simulate(**run, backend="cpu")
        cpu_s = time.perf_counter() - started
    finally:
        for o in extra:
            unregister(o.name)
    lines = [f"Pendulum, OU noise D = tau = omega = 1, damping 0.3, additive white noise 0.2, t = 1, 2, {paths} "
             f"paths, seed 21, accumulators {', '.join(names)}; GPU (float64) {gpu_s:.1f} s, CPU {cpu_s:.1f} s "
             f"(first calls: compilation included). The same paths and draws on both: z is the difference "
             f"in the CPU's standard errors, pass |z| < {Z:g}.", "",
             "| statistic | t | GPU | CPU | z |", "|---|---:|---:|---:|---:|"]
    ok = True
    for name in sorted(v for v in cpu.data_vars if f"{v}_stderr" in cpu.data_vars and "time" in cpu[v].dims):
        for i, t in enumerate(cpu["time"].values):
            g, c, se = float(gpu[name][i]), float(cpu[name][i]), float(cpu[f"{name}_stderr"][i])
            if not (math.isfinite(g) or math.isfinite(c)):
                continue
            z = (g - c) / se if se > 0 else (0.0 if g == c else math.inf)
            ok = ok and (abs(z) < Z or (math.isnan(g) and math.isnan(c)))
            lines.append(f"| {name} | {t:g} | {g:.6g} | {c:.6g} | {z:+.3f} |")
    return ok, lines


def step_reproduce(args) -> tuple[bool | None, list[str]]:
    with tempfile.TemporaryDirectory(prefix="gpu-check-") as tmp:
        command = [sys.executable, "-m", "stochpend", "reproduce", *shlex.split(args.reproduce),
                   "--backend", "cuda", "--out", tmp]
        rc, out = _subprocess(command)
        files = sorted(str(p.relative_to(tmp)) for p in Path(tmp).rglob("*") if p.is_file())
    return rc == 0, [f"`stochpend reproduce {args.reproduce} --backend cuda`: exit {rc}, {len(files)} files "
                     f"({', '.join(files[:12])}{', ...' if len(files) > 12 else ''})", "", *_fenced(out, 25)]


STEP_FUNCTIONS: dict[str, Callable] = {"device-tests": step_device_tests, "bench": step_bench,
                                       "oracle": step_oracle, "family": step_family,
                                       "reproduce": step_reproduce}


def run_step(name: str, function: Callable, args) -> Step:
    started = time.perf_counter()
    try:
        ok, lines = function(args)
    except Exception as error:  # recorded, and the next step runs
        ok, lines = False, [f"raised {type(error).__name__}: {' '.join(str(error).split())[:500]}"]
    status = "skipped" if ok is None else ("passed" if ok else "failed")
    return Step(name, status, time.perf_counter() - started, lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from stochpend.engine import cuda as gpu

    ok, why = gpu.availability()
    if not ok or (gpu._simulator_enabled() and not args.allow_simulator):
        print(f"gpu_check: no usable GPU: {why}", file=sys.stderr)
        return 2
    steps = []
    for name in STEPS:
        if name in args.only:
            step = run_step(name, STEP_FUNCTIONS[name], args)
            print(f"gpu_check: {name}: {step.status} ({step.seconds:.1f} s)", flush=True)
            steps.append(step)
    stamp = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
    text = report(why, versions(), steps, stamp)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(text)
    print(f"gpu_check: report written to {args.out}")
    return 1 if any(s.status == "failed" for s in steps) else 0


if __name__ == "__main__":
    sys.exit(main())
