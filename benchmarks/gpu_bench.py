"""Time the CUDA backend against a hand-written CUDA C reference of the same scheme, in one run.

Run on a machine with an NVIDIA GPU, stochpend's ``cuda`` extra and the CUDA tools of
``benchmarks/cuda-tools.txt`` (numba-cuda, NVRTC, ptxas)::

    python benchmarks/gpu_bench.py                      # 1e6, 1e7, 1e8 paths x float64, float32 x fixed, adaptive
    python benchmarks/gpu_bench.py --paths 1e6 --steps 100
    python benchmarks/gpu_bench.py --record             # ... and append the tables to benchmarks/RESULTS_GPU.md
    python benchmarks/gpu_bench.py --compile-only       # no GPU: compile both for sm_90, registers, host check
    python benchmarks/gpu_bench.py --dry-run            # print the cases and their work, run nothing

The cases: OU noise, D = tau = omega = 1, seed 2024, 100 batches, 4 output times;
**fixed** step h = 0.01 (``step_c=0``), ``--steps`` steps (t_max = steps * h); **adaptive** step
h = min(h_max, c/|Omega|, c/sqrt|omega^2 + xi|) with h_max = 0.05, c = 0.1 (the defaults), to
t_max = ``--t-max-adaptive``. For each precision, step mode and ensemble size:

* stochpend: the whole ``runner.run_batches(backend="cuda")`` call (the advance, statistics and copies), after a
  warm-up call that compiles the kernels;
* the reference (``benchmarks/cuda_ref/ref.cu``, written out and compiled at benchmark time
  with NVRTC, or with nvcc when one is on PATH or under CUDA_HOME): one thread per path, the
  state in registers, stochpend's Philox4x32-10 stream (key = seed, counter = (draw, path),
  with ``__umulhi``), normals, exact OU step and drift-kick-drift, E and E^2 summed per warp,
  one launch; timed from launch to synchronisation after a warm-up launch.

It prints path-steps/s of both, **stochpend / reference** (1 = at the floor), each kernel's
registers and the register limit on occupancy (128-thread blocks), and <E> of both in
standard errors (the same numbers on the same paths: fixed-step float64 agrees to round-off).
Before timing, a small ensemble (``--check-paths``) is run on the CPU and the GPU and compared
(batch sums, statistics, histograms, states path by path; docs/gpu.md says what to expect).

Without a usable GPU the script prints one line and exits with status 2, except ``--dry-run``
and ``--compile-only``: the latter compiles the reference for sm_90 (NVRTC or nvcc), reads its
registers with ``ptxas -v``, compiles stochpend's OU advance kernels offline
(``cuda_registers.py``), builds the reference's device functions for the host with g++ and
checks Philox (Random123 known answers), the normals and 30 fixed steps against stochpend's
Python functions; each part it cannot do (no NVRTC, no ptxas, no numba-cuda, no g++) is
skipped with its reason, and the exit status is 0 unless a check fails.
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
from stochpend.engine import cpu, runner  # noqa: E402
from stochpend.engine import cuda as gpu  # noqa: E402
from stochpend.engine.runner import run_batches as cpu_run_batches  # noqa: E402
from stochpend.model.settings import SimulationConfig  # noqa: E402

H = 0.01
SEED = 2024
N_TIMES = 4
N_BATCHES = 100
RESULTS = ROOT / "benchmarks" / "RESULTS_GPU.md"
REF_SOURCE = ROOT / "benchmarks" / "cuda_ref" / "ref.cu"
REF_HOST_CHECK = ROOT / "benchmarks" / "cuda_ref" / "host_check.cpp"
ARCH = "sm_90"
MODES = ("fixed", "adaptive")
#: The adaptive case's step controls (the package defaults) and default final time.
ADAPTIVE_H_MAX = 0.05
ADAPTIVE_C = 0.1
ADAPTIVE_T_MAX = 10.0
THREADS = 128

#: Pass criteria of the agreement check (docs/gpu.md, "Expected CPU/GPU differences").
F64_SUMS_RTOL = 1e-9
F32_MAX_SE = 0.5
#: Host check of the reference against stochpend's Python functions: float64 normals and
#: 30 steps (glibc on both sides; the order of operations is the same, so in practice equal),
#: float32 normals (Python's float32 rounds a float64 log/sin/cos; g++ calls logf/sinf/cosf).
HOST_F64_RTOL = 1e-12
HOST_F32_RTOL = 2e-6


class Skipped(Exception):
    """A part of --compile-only that this machine cannot do (the message says why)."""


def make_config(paths: int, steps: int, batches: int = N_BATCHES, mode: str = "fixed",
                t_max_adaptive: float = ADAPTIVE_T_MAX) -> SimulationConfig:
    """The benchmark case: fixed steps of H (``steps`` of them), or adaptive to t_max_adaptive."""
    t_max = steps * H if mode == "fixed" else t_max_adaptive
    times = [t_max * (j + 1) / N_TIMES for j in range(N_TIMES)]
    step = dict(h_max=H, step_c=0.0) if mode == "fixed" else dict(h_max=ADAPTIVE_H_MAX, step_c=ADAPTIVE_C)
    return SimulationConfig.build(
        noise="ou", D=1.0, tau=1.0, omega=1.0, paths=paths, t_max=t_max, times=times,
        seed=SEED, n_batches=batches, **step,
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
        sums, steps_taken = runner.run_batches(config, 0, config.n_batches, precision=precision, backend="cuda")
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


def time_run(config: SimulationConfig, precision: str) -> tuple[float, int, object]:
    """stochpend's whole ``runner.run_batches(backend="cuda")`` call: (seconds, path-steps, sums)."""
    started = time.perf_counter()
    sums, path_steps = runner.run_batches(config, 0, config.n_batches, precision=precision, backend="cuda")
    return time.perf_counter() - started, path_steps, sums


# -- the CUDA C reference ------------------------------------------------------------------------
def find_nvcc() -> str | None:
    """nvcc on PATH, under CUDA_HOME/CUDA_PATH, or in an nvidia-cuda-nvcc wheel (whose 12.x
    releases ship ptxas but not nvcc)."""
    import importlib.util
    import os
    import shutil

    found = shutil.which("nvcc")
    if found:
        return found
    for var in ("CUDA_HOME", "CUDA_PATH"):
        if os.environ.get(var):
            candidate = Path(os.environ[var]) / "bin" / "nvcc"
            if candidate.is_file():
                return str(candidate)
    spec = importlib.util.find_spec("nvidia.cuda_nvcc") if importlib.util.find_spec("nvidia") else None
    for location in (spec.submodule_search_locations or []) if spec else []:
        candidate = Path(location) / "bin" / "nvcc"
        if candidate.is_file():
            return str(candidate)
    return None


def compile_reference(arch: str = ARCH) -> dict:
    """Write ``ref.cu`` into a temporary directory and compile it for ``arch``: returns
    ``{"tool", "ptx", "cubin"}`` (bytes). nvcc when one is found, else NVRTC (cuda-bindings,
    no driver needed). Raises Skipped when neither is installed, RuntimeError on a compile error."""
    import subprocess
    import tempfile

    source = REF_SOURCE.read_text()
    nvcc = find_nvcc()
    if nvcc is not None:
        with tempfile.TemporaryDirectory(prefix="gpu-bench-") as tmp:
            cu = Path(tmp) / "ref.cu"
            cu.write_text(source)
            out = {}
            for kind in ("ptx", "cubin"):
                target = Path(tmp) / f"ref.{kind}"
                run = subprocess.run([nvcc, f"-arch={arch}", f"-{kind}", "-std=c++17", "-O3", "-o",
                                      str(target), str(cu)], capture_output=True, text=True)
                if run.returncode != 0:
                    raise RuntimeError(f"nvcc failed:\n{run.stdout}{run.stderr}")
                out[kind] = target.read_bytes()
        return {"tool": f"nvcc ({nvcc})", **out}
    try:
        from cuda.bindings import nvrtc
    except ImportError as error:
        raise Skipped(f"neither nvcc nor NVRTC (cuda-bindings) is installed ({error}); "
                      "pip install -r benchmarks/cuda-tools.txt") from None

    def check(result, what):
        err = result[0] if isinstance(result, tuple) else result
        if err != nvrtc.nvrtcResult.NVRTC_SUCCESS:
            raise RuntimeError(f"NVRTC {what} failed: {err}")
        return result[1] if isinstance(result, tuple) and len(result) > 1 else None

    try:
        prog = check(nvrtc.nvrtcCreateProgram(source.encode(), b"ref.cu", 0, [], []), "create")
    except Exception as error:  # the NVRTC library itself missing
        raise Skipped(f"NVRTC cannot be loaded ({type(error).__name__}: {error})") from None
    options = [f"--gpu-architecture={arch}".encode(), b"-std=c++17"]
    result = nvrtc.nvrtcCompileProgram(prog, len(options), options)
    size = check(nvrtc.nvrtcGetProgramLogSize(prog), "log size")
    log = b" " * size
    nvrtc.nvrtcGetProgramLog(prog, log)
    if result[0] != nvrtc.nvrtcResult.NVRTC_SUCCESS:
        raise RuntimeError(f"NVRTC compilation failed:\n{log.decode(errors='replace')}")
    ptx = b" " * check(nvrtc.nvrtcGetPTXSize(prog), "PTX size")
    check(nvrtc.nvrtcGetPTX(prog, ptx), "PTX")
    cubin = b" " * check(nvrtc.nvrtcGetCUBINSize(prog), "CUBIN size")
    check(nvrtc.nvrtcGetCUBIN(prog, cubin), "CUBIN")
    return {"tool": "NVRTC", "ptx": ptx.rstrip(b"\0"), "cubin": cubin}


def reference_registers(ptx: bytes) -> dict[str, object]:
    """``ptxas -arch=sm_90 -v`` on the reference's PTX: kernel name -> cuda_registers.Usage."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cuda_registers

    try:
        ptxas = cuda_registers.find_ptxas()
    except cuda_registers.ToolMissing as error:
        raise Skipped(str(error)) from None
    entries, _ = cuda_registers.assemble(ptxas, ptx.decode(errors="replace"), None)
    return entries


def stochpend_registers_offline(precisions: list[str], modes: list[str]) -> dict[str, object]:
    """stochpend's OU pendulum advance kernels compiled offline for sm_90 (cuda_registers.py,
    LTO): "precision/mode" -> Usage. Raises Skipped without numba-cuda or ptxas."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cuda_registers

    try:
        cuda = cuda_registers.load_numba_cuda()
        ptxas = cuda_registers.find_ptxas()
    except cuda_registers.ToolMissing as error:
        raise Skipped(str(error)) from None
    wanted = {f"advance pendulum/force/ou/{p}/{m}/libm": f"{p}/{m}" for p in precisions for m in modes}
    out = {}
    for label, kernel, signature in gpu.kernel_variants(tuple(precisions)):
        if label in wanted:
            variant = cuda_registers.as_variant(label, kernel, signature)
            ptx = cuda_registers.compile_to_ptx(cuda, variant, lto=True)
            entries, _ = cuda_registers.assemble(ptxas, ptx, None)
            out[wanted[label]] = next(iter(entries.values()))
    return out


def occupancy(registers: int) -> str:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    import cuda_registers

    warps = cuda_registers.warps_from_registers(registers, THREADS)
    return f"{registers} ({100.0 * warps / cuda_registers.MAX_WARPS_PER_SM:.1f}%)"


def host_check() -> tuple[list[str], bool]:
    """Build the reference's device functions for the host (g++) and compare them with
    stochpend's Python functions: Philox known answers, both normal pairs, 30 fixed steps."""
    import shutil
    import subprocess
    import tempfile

    from stochpend.engine import integrator
    from stochpend.numerics import rng
    from stochpend.numerics.mathlib import LIBM

    compiler = shutil.which("g++") or shutil.which("c++")
    if compiler is None:
        raise Skipped("no C++ compiler (g++) for the host build of the reference")
    seed, h, steps = 2**33 + SEED, H, 30
    with tempfile.TemporaryDirectory(prefix="gpu-bench-host-") as tmp:
        exe = Path(tmp) / "host_check"
        build = subprocess.run([compiler, "-O2", "-std=c++17", "-ffp-contract=off", "-I",
                                str(REF_SOURCE.parent), "-o", str(exe), str(REF_HOST_CHECK), "-lm"],
                               capture_output=True, text=True)
        if build.returncode != 0:
            return [f"host check: the host build of ref.cu failed:\n{build.stderr[-2000:]}"], False
        run = subprocess.run([str(exe), str(seed), repr(h), str(steps), "1", "1", "1"],
                             capture_output=True, text=True, check=True)
    key0, key1 = rng.seed_to_key(seed)
    normals32 = rng.normals_with(LIBM, np.float32)
    spec = integrator.spec("ou", adaptive=False)
    kern = integrator.build(spec)
    worst = {"kat": 0, "f64 normals": 0.0, "f32 normals": 0.0, "30 steps": 0.0}
    for line in run.stdout.splitlines():
        kind, *fields = line.split()
        if kind == "kat":
            inputs = [np.uint64(v) for v in fields[:6]]
            got = [int(v) for v in fields[7:]]
            worst["kat"] += int([int(w) for w in rng.philox4x32_10(*inputs)] != got)
        elif kind == "normals":
            path, n = np.uint64(fields[0]), np.uint64(fields[1])
            z = [float(v) for v in fields[2:]]
            want64 = rng.draw_normals(key0, key1, path, n)
            want32 = normals32(key0, key1, path, n)
            for a, b in zip(z[:2], want64, strict=True):
                worst["f64 normals"] = max(worst["f64 normals"], abs(a - b) / max(1.0, abs(b)))
            for a, b in zip(z[2:], want32, strict=True):
                worst["f32 normals"] = max(worst["f32 normals"], abs(a - float(b)) / max(1.0, abs(float(b))))
        elif kind == "path":
            path = np.uint64(fields[0])
            got = [float(v) for v in fields[1:]]
            x, Om, xi, aux = kern.init_path(key0, key1, path, 0.0, True, 0.0, 0.0, True, (1.0, 1.0))
            arrays = [np.array([v]) for v in (x, Om, xi, aux, 0.0, 0.0)]
            k = np.zeros(1, dtype=np.uint64)
            status = np.zeros(1, dtype=np.uint8)
            kern.advance_path(0, (*arrays, k, status), steps * h, steps, key0, key1, int(path),
                              (1.0, 1.0), (1.0, (2.0,), h, 0.0))
            for a, b in zip(got, (arrays[0][0], arrays[1][0], arrays[2][0]), strict=True):
                worst["30 steps"] = max(worst["30 steps"], abs(a - b) / max(1.0, abs(b)))
    ok = (worst["kat"] == 0 and worst["f64 normals"] <= HOST_F64_RTOL
          and worst["f32 normals"] <= HOST_F32_RTOL and worst["30 steps"] <= HOST_F64_RTOL)
    lines = [f"host check of the reference (g++, ref.cu's device functions) against stochpend's "
             f"Python functions, seed {seed}: Philox known answers wrong: {worst['kat']}/3; max rel. "
             f"diff float64 normals {worst['f64 normals']:.1e} (<= {HOST_F64_RTOL:g}), float32 normals "
             f"{worst['f32 normals']:.1e} (<= {HOST_F32_RTOL:g}), states after {steps} fixed steps "
             f"{worst['30 steps']:.1e} (<= {HOST_F64_RTOL:g}): {'pass' if ok else 'FAIL'}"]
    return lines, ok


class Reference:
    """The compiled reference loaded on the current device (numba's primary context), launched
    through the CUDA driver API of cuda-bindings."""

    def __init__(self, cubin: bytes) -> None:
        from cuda.bindings import driver
        from numba import cuda

        self.driver = driver
        self.cuda = cuda
        cuda.current_context()  # numba's primary context, made current on this thread
        self.module = self._ok(driver.cuModuleLoadData(cubin))
        self.d_sums = cuda.to_device(np.zeros(2))
        self.d_steps = cuda.to_device(np.zeros(1, dtype=np.uint64))

    def _ok(self, result):
        err, *rest = result if isinstance(result, tuple) else (result,)
        if err != self.driver.CUresult.CUDA_SUCCESS:
            raise RuntimeError(f"CUDA driver call failed: {err}")
        return rest[0] if len(rest) == 1 else rest

    def function(self, precision: str, mode: str):
        name = f"ref_{'f64' if precision == 'float64' else 'f32'}_{mode}".encode()
        return self._ok(self.driver.cuModuleGetFunction(self.module, name))

    def registers(self, precision: str, mode: str) -> int:
        attribute = self.driver.CUfunction_attribute.CU_FUNC_ATTRIBUTE_NUM_REGS
        return int(self._ok(self.driver.cuFuncGetAttribute(attribute, self.function(precision, mode))))

    def run(self, config: SimulationConfig, precision: str, mode: str, steps: int) -> tuple[float, int, float, float]:
        """One launch over all paths: (seconds, path-steps, <E>, its standard error)."""
        import ctypes

        from stochpend.numerics import rng

        key0, key1 = rng.seed_to_key(config.seed)
        self.d_sums.copy_to_device(np.zeros(2))
        self.d_steps.copy_to_device(np.zeros(1, dtype=np.uint64))
        values = (config.paths, 0, int(key0), int(key1), config.D, config.tau, config.omega**2,
                  config.h_max, config.step_c, config.t_max, steps if mode == "fixed" else 0,
                  self.d_sums.device_ctypes_pointer.value, self.d_steps.device_ctypes_pointer.value)
        types = (ctypes.c_ulonglong, ctypes.c_ulonglong, ctypes.c_uint, ctypes.c_uint, ctypes.c_double,
                 ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                 ctypes.c_ulonglong, ctypes.c_void_p, ctypes.c_void_p)
        blocks = -(-config.paths // THREADS)
        function = self.function(precision, mode)
        self.cuda.synchronize()
        started = time.perf_counter()
        self._ok(self.driver.cuLaunchKernel(function, blocks, 1, 1, THREADS, 1, 1, 0, 0,
                                            (values, types), 0))
        self.cuda.synchronize()
        seconds = time.perf_counter() - started
        s1, s2 = self.d_sums.copy_to_host()
        path_steps = int(self.d_steps.copy_to_host()[0])
        mean = s1 / config.paths
        return seconds, path_steps, mean, math.sqrt(max(s2 / config.paths - mean**2, 0.0) / config.paths)


def last_mean_E(sums) -> tuple[float, float]:
    value, se = sums.statistics()["mean_E"]
    return float(value[-1]), float(se[-1])


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


def _count_or_zero(text: str) -> int:
    return 0 if text.strip() in ("0", "0.0") else _count(text)


def dry_run(args) -> int:
    print(f"gpu_bench dry run: the cases of a GPU run (nothing is run); CUDA C reference: {REF_SOURCE}")
    print("| precision | step | paths | t_max | at least path-steps |")
    print("|---|---|---:|---:|---:|")
    for precision in args.precisions:
        for mode in args.modes:
            for paths in args.paths:
                config = make_config(paths, args.steps, args.batches, mode, args.t_max_adaptive)
                print(f"| {precision} | {mode} | {paths:.0e} | {config.t_max:g} "
                      f"| {paths * config.t_max / config.h_max:.3g} |")
    nvcc = find_nvcc()
    print(f"reference compiler: {'nvcc ' + nvcc if nvcc else 'NVRTC (no nvcc found)'}; "
          "--compile-only compiles both offline")
    return 0


def compile_only(args) -> int:
    """The parts that need no GPU (module docstring); returns the exit status."""
    failed = False
    reference = None
    try:
        reference = compile_reference()
        print(f"reference: compiled for {ARCH} with {reference['tool']} ({len(reference['cubin'])} bytes of cubin)")
    except Skipped as why:
        print(f"reference: skipped: {why}")
    except RuntimeError as error:
        print(f"reference: FAILED: {error}")
        failed = True
    ref_regs: dict = {}
    if reference is not None:
        try:
            ref_regs = reference_registers(reference["ptx"])
        except Skipped as why:
            print(f"reference registers: skipped: {why}")
    try:
        ours = stochpend_registers_offline(args.precisions, args.modes)
    except Skipped as why:
        print(f"stochpend registers: skipped: {why}")
        ours = {}
    if ref_regs or ours:
        print(f"Registers per thread ({ARCH}, ptxas -v; in brackets the register limit on occupancy, "
              f"{THREADS}-thread blocks):")
        print("| precision | step | stochpend advance | reference |")
        print("|---|---|---:|---:|")
        for precision in args.precisions:
            for mode in args.modes:
                name = f"ref_{'f64' if precision == 'float64' else 'f32'}_{mode}"
                usage = ours.get(f"{precision}/{mode}")
                ref = ref_regs.get(name)
                cells = [occupancy(u.registers) if u is not None else "–" for u in (usage, ref)]
                print(f"| {precision} | {mode} | {cells[0]} | {cells[1]} |")
    try:
        lines, ok = host_check()
        print("\n".join(lines))
        failed |= not ok
    except Skipped as why:
        print(f"host check: skipped: {why}")
    return 1 if failed else 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--paths", type=_count, nargs="+", default=[10**6, 10**7, 10**8])
    parser.add_argument("--precisions", nargs="+", choices=gpu.PRECISIONS, default=list(gpu.PRECISIONS))
    parser.add_argument("--modes", nargs="+", choices=MODES, default=list(MODES))
    parser.add_argument("--steps", type=int, default=300, help="fixed case: steps of h = 0.01 (default 300)")
    parser.add_argument("--t-max-adaptive", type=float, default=ADAPTIVE_T_MAX,
                        help=f"adaptive case: final time (default {ADAPTIVE_T_MAX:g})")
    parser.add_argument("--check-paths", type=_count_or_zero, default=20_000,
                        help="paths of the CPU agreement check (0: skip it)")
    parser.add_argument("--batches", type=int, default=N_BATCHES, help="batches (default 100)")
    parser.add_argument("--results", type=Path, default=RESULTS, help="Markdown file to append to")
    parser.add_argument("--record", action="store_true", help=f"append the tables to --results ({RESULTS.name})")
    parser.add_argument("--no-reference", action="store_true", help="time stochpend only")
    parser.add_argument("--allow-simulator", action="store_true",
                        help="run under NUMBA_ENABLE_CUDASIM=1 (tests the script; timings meaningless; no reference)")
    parser.add_argument("--dry-run", action="store_true", help="print the cases, run nothing")
    parser.add_argument("--compile-only", action="store_true",
                        help="no GPU needed: compile both for sm_90, registers, host check of the reference")
    args = parser.parse_args(argv)

    if args.dry_run:
        return dry_run(args)
    if args.compile_only:
        return compile_only(args)
    ok, why = gpu.availability()
    simulator = gpu._simulator_enabled()
    if not ok or (simulator and not args.allow_simulator):
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

    reference = None
    if not args.no_reference and not simulator:
        compiled = compile_reference()
        reference = Reference(compiled["cubin"])
        print(f"reference compiled with {compiled['tool']}")

    table = ["| precision | step | paths | stochpend wall (s) | stochpend path-steps/s | reference wall (s) "
             "| reference path-steps/s | stochpend / reference | registers stochpend (occupancy) "
             "| registers reference (occupancy) | <E> stochpend - reference (std. errors) |",
             "|---|---|---:|---:|---:|---:|---:|---:|---|---|---:|"]
    print("\n".join(table))
    for precision in args.precisions:
        for mode in args.modes:
            warm = make_config(1000, 2, args.batches, mode, min(args.t_max_adaptive, 0.1))
            started = time.perf_counter()
            time_run(warm, precision)  # compiles the kernels (or loads them from the disk cache)
            print(f"({precision} {mode}: first call, with compilation or cache load, "
                  f"{time.perf_counter() - started:.1f} s)")
            spec = gpu.spec_for(warm, precision)
            try:
                regs = occupancy(int(gpu.advance_kernel(spec).get_regs_per_thread()))
            except Exception:
                regs = "?"
            ref_regs = "–"
            if reference is not None:
                ref_regs = occupancy(reference.registers(precision, mode))
                reference.run(warm, precision, mode, 2)  # warm-up launch
            for paths in args.paths:
                config = make_config(paths, args.steps, args.batches, mode, args.t_max_adaptive)
                try:
                    wall, path_steps, sums = time_run(config, precision)
                    rate = path_steps / wall
                    cells = [f"{wall:.3f}", f"{rate:.3e}"]
                    if reference is not None:
                        r_wall, r_steps, r_mean, r_se = reference.run(config, precision, mode, args.steps)
                        r_rate = r_steps / r_wall
                        mean, se = last_mean_E(sums)
                        z = (mean - r_mean) / math.hypot(se, r_se)
                        cells += [f"{r_wall:.3f}", f"{r_rate:.3e}", f"{rate / r_rate:.2f}"]
                    else:
                        z = float("nan")
                        cells += ["–", "–", "–"]
                    row = (f"| {precision} | {mode} | {paths:.0e} | " + " | ".join(cells)
                           + f" | {regs} | {ref_regs} | {z:+.2f} |")
                except Exception as error:  # e.g. out of device memory: record and go on
                    row = (f"| {precision} | {mode} | {paths:.0e} | failed: "
                           f"{' '.join(str(error).split())[:120]} | | | | | | | |")
                print(row, flush=True)
                table.append(row)
    lines += table
    if math.isfinite(cpu_rate):
        lines += ["", f"CPU reference rate (the agreement run on this host, "
                      f"{platform.processor() or platform.machine()}): {cpu_rate:.3e} path-steps/s."]

    if args.record:
        stamp = _dt.datetime.now(_dt.UTC).strftime("%Y-%m-%d %H:%M UTC")
        header = [
            f"## {stamp}: {why}",
            "",
            f"{environment()}. OU noise, D = 1, tau = 1, omega = 1, seed {SEED}, {N_TIMES} output "
            f"times, {args.batches} batches; fixed: h = {H}, {args.steps} steps (t_max = "
            f"{args.steps * H:g}); adaptive: h_max = {ADAPTIVE_H_MAX}, c = {ADAPTIVE_C}, t_max = "
            f"{args.t_max_adaptive:g}. stochpend: wall time of the whole runner.run_batches(backend='cuda') call "
            "(kernels compiled beforehand); reference: benchmarks/cuda_ref/ref.cu, one launch.",
            "",
        ]
        new_file = not args.results.exists()
        with open(args.results, "a") as f:
            if new_file:
                f.write("# CUDA backend measurements\n\nAppended by `python benchmarks/gpu_bench.py "
                        "--record` (see docs/gpu.md).\n\n")
            f.write("\n".join(header + lines) + "\n\n")
        print(f"appended to {args.results}")
    return 0 if passed else 1


if __name__ == "__main__":
    sys.exit(main())
