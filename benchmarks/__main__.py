"""``python -m benchmarks``: the issue-5 benchmark, every implementation in one sitting.

Workload: OU noise, D = tau = omega = 1, 10**4 paths, fixed step 0.01, 10**4 steps (10**8
path-steps), float64; simulation time only. Each measurement runs in its own subprocess (a
fresh interpreter, so peak memory is per implementation), one after the other; this process
only orchestrates and writes ``benchmarks/RESULTS.md``.

    python -m benchmarks              # full run (a few minutes), writes benchmarks/RESULTS.md
    python -m benchmarks --quick      # 1/100 of the work, smoke run, writes nothing unless --out
    python -m benchmarks --no-diffrax # skip the JAX/diffrax part

Every implementation prints <E^2>/(D t/tau^2) at the last time, so a fast wrong answer shows.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
HERE = Path(__file__).resolve().parent
D = TAU = OMEGA = 1.0
H = 0.01
SEED = 1


# ----------------------------------------------------------------------------------------------
# Worker side: one measurement per process, printed as one JSON line.
# ----------------------------------------------------------------------------------------------
def _rusage():
    import resource

    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def _timed(fn, repeat):
    """Best of ``repeat`` calls of fn(); wall and CPU seconds of that call, and its value."""
    import time as _t

    best = None
    for _ in range(repeat):
        cpu0, _m = _rusage()
        w0 = _t.perf_counter()
        value = fn()
        wall = _t.perf_counter() - w0
        cpu = _rusage()[0] - cpu0
        if best is None or wall < best[0]:
            best = (wall, cpu, value)
    return best


def _worker_stochpend(spec):
    import numba

    from stochpend.simulate import simulate

    # "fixed" and "fast": the fixed-step run, which the runner gives the SIMD lock-step driver
    # (stochpend._backends.cpu.spec_for); "adaptive": the default step control.
    mode = spec["mode"]
    threads = spec.get("threads")
    paths, t_max = spec["paths"], spec["t_max"]
    kw = dict(noise="ou", D=D, tau=TAU, omega=OMEGA, seed=SEED, threads=threads)
    if mode in ("fixed", "fast"):
        kw.update(step_c=0.0, h_max=H)
    # Warm-up (loads or compiles the kernels), not timed.
    simulate(paths=min(paths, 64), t_max=min(t_max, 0.05), times=[min(t_max, 0.05)], **kw)
    import tracemalloc

    tracemalloc.start()
    wall, cpu_s, ds = _timed(lambda: simulate(paths=paths, t_max=t_max, times=[t_max], **kw),
                             spec.get("repeat", 1))
    traced_peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    ps = int(ds.attrs["path_steps"])
    return {
        "available": True, "wall_s": wall, "cpu_s": cpu_s, "path_steps": ps,
        "threads": threads or numba.get_num_threads(),
        "E2_scaled": float(ds["mean_E2"].values[-1]) / (D * t_max / TAU**2),
        "E2_scaled_stderr": float(ds["mean_E2_stderr"].values[-1]) / (D * t_max / TAU**2),
        "peak_rss_mb": _rusage()[1], "traced_peak_mb": traced_peak,
    }


def _worker_numpy(spec):
    import tracemalloc

    import numpy as np

    from benchmarks import numpy_ref

    paths, t_max = spec["paths"], spec["t_max"]
    numpy_ref.simulate(16, 0.05, H, seed=SEED)  # warm-up
    tracemalloc.start()
    wall, cpu_s, r = _timed(lambda: numpy_ref.simulate(paths, t_max, H, D=D, tau=TAU, omega=OMEGA,
                                                       seed=SEED, rng=spec.get("rng", "numpy")),
                            spec.get("repeat", 1))
    traced_peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    E = r.energy(OMEGA)
    return {
        "available": True, "wall_s": wall, "cpu_s": cpu_s, "path_steps": paths * r.steps,
        "threads": 1, "E2_scaled": float(np.mean(E * E)) / (D * t_max / TAU**2),
        "E2_scaled_stderr": float(np.std(E * E) / np.sqrt(paths)) / (D * t_max / TAU**2),
        "peak_rss_mb": _rusage()[1], "traced_peak_mb": traced_peak,
    }


def _worker_c(spec):
    import numpy as np

    from benchmarks import c_ref

    if c_ref.compiler() is None:
        return {"available": False, "reason": "gcc not found"}
    paths, t_max = spec["paths"], spec["t_max"]
    threads = spec.get("threads") or 0
    flavour = spec.get("flavour", "fast")
    t0 = time.perf_counter()
    lib = c_ref.build(flavour)
    build_s = time.perf_counter() - t0
    c_ref.run(16, 0.05, H, seed=SEED, variant=spec["variant"], threads=threads, flavour=flavour)
    wall, cpu_s, r = _timed(lambda: c_ref.run(paths, t_max, H, D=D, tau=TAU, omega=OMEGA, seed=SEED,
                                              variant=spec["variant"], threads=threads,
                                              flavour=flavour),
                            spec.get("repeat", 1))
    E = r.energy(OMEGA)
    return {
        "available": True, "wall_s": r.seconds, "cpu_s": cpu_s, "path_steps": paths * r.steps,
        "threads": threads or lib.sp_max_threads(), "build_s": build_s,
        "E2_scaled": float(np.mean(E * E)) / (D * t_max / TAU**2),
        "E2_scaled_stderr": float(np.std(E * E) / np.sqrt(paths)) / (D * t_max / TAU**2),
        "peak_rss_mb": _rusage()[1], "compile_command": c_ref.compile_command(flavour),
    }


def _worker_jit(spec):
    """First call (compile, the on-disk cache being empty) against the second call."""
    t_spawn = spec["t_spawn"]
    t_entry = time.monotonic()
    from stochpend.simulate import simulate

    t_import = time.monotonic()
    kw = dict(noise="ou", D=D, tau=TAU, omega=OMEGA, paths=1000, t_max=1.0, times=[1.0], seed=SEED,
              step_c=0.0, h_max=H)
    t0 = time.perf_counter()
    simulate(**kw)
    first = time.perf_counter() - t0
    t_ready = time.monotonic()
    cpu_ready = time.process_time()  # CPU time of the whole process so far (all threads)
    t0 = time.perf_counter()
    c0 = time.process_time()
    simulate(**kw)
    second = time.perf_counter() - t0
    second_cpu = time.process_time() - c0
    return {
        "ready_cpu_s": cpu_ready - second_cpu,
        "available": True, "startup_s": t_entry - t_spawn, "import_s": t_import - t_spawn,
        "first_call_s": first, "second_call_s": second, "compile_s": first - second,
        "ready_s": t_ready - t_spawn - second,
        "peak_rss_mb": _rusage()[1],
    }


def _worker_micro(spec):
    from benchmarks import micro

    return {"available": True, "rows": micro.run(), "peak_rss_mb": _rusage()[1]}


WORKERS = {"stochpend": _worker_stochpend, "numpy": _worker_numpy, "c": _worker_c,
           "jit": _worker_jit, "micro": _worker_micro}


def worker_main(spec_json: str) -> int:
    spec = json.loads(spec_json)
    try:
        out = WORKERS[spec["kind"]](spec)
    except Exception as exc:  # reported in the table, not fatal for the run
        out = {"available": False, "reason": f"{type(exc).__name__}: {exc}"}
    print("RESULT " + json.dumps(out), flush=True)
    return 0


# ----------------------------------------------------------------------------------------------
# Orchestrator side.
# ----------------------------------------------------------------------------------------------
class Runner:
    def __init__(self, cache_dir: str, verbose: bool = True):
        self.cache_dir = cache_dir
        self.verbose = verbose
        self.records: list[dict] = []

    def env(self, threads: int | None = None, cache_dir: str | None = None,
            wide: bool = False) -> dict:
        env = dict(os.environ)
        env["NUMBA_CACHE_DIR"] = cache_dir or self.cache_dir
        if wide:
            env["NUMBA_CPU_FEATURES"] = wide_features()
        env["PYTHONPATH"] = os.pathsep.join([str(ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        if threads:
            env["OMP_NUM_THREADS"] = str(threads)
        return env

    def worker(self, spec: dict, *, label: str, group: str, cache_dir: str | None = None,
               timeout: float = 900) -> dict:
        spec = dict(spec)
        load0 = os.getloadavg()[0]
        spec["t_spawn"] = time.monotonic()
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "benchmarks", "--worker", json.dumps(spec)],
            cwd=ROOT, env=self.env(spec.get("threads"), cache_dir, spec.get("wide", False)),
            capture_output=True, text=True,
            timeout=timeout,
        )
        out = None
        for line in proc.stdout.splitlines():
            if line.startswith("RESULT "):
                out = json.loads(line[len("RESULT "):])
        if out is None:
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
            out = {"available": False, "reason": f"worker failed (rc={proc.returncode}): {' | '.join(tail)}"}
        return self._record(out, label, group, spec, load0, time.perf_counter() - t0)

    def diffrax(self, python: str | None, paths: int, t_max: float, *, label: str, group: str):
        load0 = os.getloadavg()[0]
        t0 = time.perf_counter()
        if python is None:
            out = {"available": False,
                   "reason": "no JAX environment: .venv-bench/bin/python missing "
                             "(python3.11 -m venv .venv-bench && .venv-bench/bin/pip install jax diffrax)"}
        else:
            proc = subprocess.run(
                [python, str(HERE / "diffrax_ref.py"), "--paths", str(paths), "--t-max", str(t_max),
                 "--h", str(H), "--seed", str(SEED)],
                cwd=ROOT, capture_output=True, text=True, timeout=900,
            )
            out = None
            for line in proc.stdout.splitlines():
                if line.startswith("{"):
                    out = json.loads(line)
            if out is None:
                tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
                out = {"available": False, "reason": f"failed (rc={proc.returncode}): {' | '.join(tail)}"}
            elif out.get("available"):
                out["wall_s"] = out["steady_s"]
                out["cpu_s"] = out.get("steady_cpu_s")
                out["path_steps"] = out["paths"] * out["steps"]
                out["threads"] = "XLA default"
        spec = {"kind": "diffrax", "paths": paths, "t_max": t_max}
        return self._record(out, label, group, spec, load0, time.perf_counter() - t0)

    def _record(self, out, label, group, spec, load0, elapsed):
        out = dict(out)
        out.update(label=label, group=group, spec={k: v for k, v in spec.items() if k != "t_spawn"},
                   loadavg_before=load0, process_s=elapsed)
        if out.get("available") and "path_steps" in out and out.get("wall_s"):
            out["rate"] = out["path_steps"] / out["wall_s"]
            if out.get("cpu_s"):
                out["rate_per_cpu_s"] = out["path_steps"] / out["cpu_s"]
        self.records.append(out)
        if self.verbose:
            print(f"  {_line(out)}", flush=True)
        return out


def _fmt_rate(r):
    return "-" if r is None else f"{r / 1e6:,.1f} M"


def _line(rec):
    if not rec.get("available"):
        return f"{rec['label']}: not available ({rec.get('reason')})"
    parts = [rec["label"] + ":"]
    if "rate" in rec:
        parts.append(f"{_fmt_rate(rec['rate'])} path-steps/s")
        parts.append(f"({rec['path_steps']:.3g} path-steps in {rec['wall_s']:.2f} s)")
    if "E2_scaled" in rec:
        parts.append(f"<E2>/(Dt/tau2) = {rec['E2_scaled']:.4f}")
    if "compile_s" in rec:
        parts.append(f"compile {rec['compile_s']:.2f} s")
    if "ready_s" in rec:
        parts.append(f"ready after {rec['ready_s']:.2f} s")
    parts.append(f"load {rec['loadavg_before']:.2f}")
    return " ".join(parts)


def machine_info() -> dict:
    info = {"date": time.strftime("%Y-%m-%d %H:%M:%S %Z"), "python": platform.python_version(),
            "platform": platform.platform()}
    try:
        lscpu = subprocess.run(["lscpu"], capture_output=True, text=True).stdout
        for line in lscpu.splitlines():
            key, _, val = line.partition(":")
            if key.strip() in ("Model name", "CPU(s)", "Thread(s) per core", "Core(s) per socket",
                               "L2 cache", "L3 cache", "Hypervisor vendor"):
                info[key.strip()] = val.strip()
        flags = next((l for l in lscpu.splitlines() if l.startswith("Flags")), "")
        info["avx512f"] = "avx512f" in flags
    except OSError:
        pass
    try:
        import llvmlite
        import numba
        import numpy

        info.update(numba=numba.__version__, numpy=numpy.__version__, llvmlite=llvmlite.__version__)
    except ImportError:
        pass
    info["gcc"] = (subprocess.run(["gcc", "--version"], capture_output=True, text=True).stdout
                   .splitlines() or ["-"])[0] if shutil.which("gcc") else "not found"
    try:
        with open("/proc/meminfo") as f:
            info["memory"] = f.readline().split(":")[1].strip()
    except OSError:
        pass
    return info


def wide_features() -> str:
    """The host's LLVM features plus ``-prefer-256-bit``: lets LLVM use 512-bit vectors.

    LLVM's tuning for recent Intel and AMD cores prefers 256-bit vectors; Numba passes the host
    CPU's name and features, so its loops are vectorized 4 doubles wide. The environment
    variable NUMBA_CPU_FEATURES (read when Numba starts) replaces the feature string.
    """
    import llvmlite.binding as ll

    ll.initialize_native_target()
    return ll.get_host_cpu_features().flatten() + ",-prefer-256-bit"


def find_bench_python() -> str | None:
    cand = ROOT / ".venv-bench" / "bin" / "python"
    return str(cand) if cand.exists() else None


def run_all(args) -> dict:
    quick = args.quick
    # Main workload: 10**4 paths x 10**4 steps; quick: 10**3 x 10**3.
    paths = 1_000 if quick else 10_000
    t_max = 10.0 if quick else 100.0
    repeat = 1 if quick else 2
    cache_dir = tempfile.mkdtemp(prefix="stochpend_bench_numba_")
    R = Runner(cache_dir)
    info = machine_info()
    t_start = time.perf_counter()
    load_start = os.getloadavg()
    print(f"stochpend benchmark ({'quick' if quick else 'full'}), {info.get('Model name', '?')}, "
          f"{info.get('CPU(s)', '?')} CPUs, load {load_start[0]:.2f}", flush=True)

    print("JIT compile and on-disk cache:", flush=True)
    jit_dir = tempfile.mkdtemp(prefix="stochpend_bench_jit_")
    R.worker({"kind": "jit"}, label="stochpend first process (empty cache)", group="jit", cache_dir=jit_dir)
    R.worker({"kind": "jit"}, label="stochpend second process (cache on disk)", group="jit", cache_dir=jit_dir)
    fast_dir = tempfile.mkdtemp(prefix="stochpend_bench_jitfast_")
    R.worker({"kind": "jit", "fast": True}, label="stochpend fast, first process (empty cache)", group="jit",
             cache_dir=fast_dir)
    R.worker({"kind": "jit", "fast": True}, label="stochpend fast, second process (cache on disk)", group="jit",
             cache_dir=fast_dir)
    # Populate the run's cache so that the timed workers only load.
    R.worker({"kind": "stochpend", "mode": "fixed", "paths": 64, "t_max": 0.1}, label="(cache warm-up)",
             group="warmup")
    R.worker({"kind": "stochpend", "mode": "adaptive", "paths": 64, "t_max": 0.1}, label="(cache warm-up)",
             group="warmup")
    R.worker({"kind": "stochpend", "mode": "fast", "paths": 64, "t_max": 0.1}, label="(cache warm-up)",
             group="warmup")
    R.worker({"kind": "stochpend", "mode": "fast", "paths": 64, "t_max": 0.1, "wide": True},
             label="(cache warm-up)", group="warmup")

    print("Micro-benchmarks (1 thread, CPU time):", flush=True)
    micro = R.worker({"kind": "micro"}, label="micro-benchmarks", group="micro")

    print(f"Main workload: OU, D = tau = omega = 1, {paths} paths, h = {H}, t = {t_max:g}:", flush=True)
    main = {}
    main["fixed"] = R.worker({"kind": "stochpend", "mode": "fixed", "paths": paths, "t_max": t_max,
                              "repeat": repeat}, label="stochpend fixed-step", group="main")
    main["adaptive"] = R.worker({"kind": "stochpend", "mode": "adaptive", "paths": paths, "t_max": t_max,
                                 "repeat": repeat}, label="stochpend adaptive (default step control)",
                                group="main")
    main["fast"] = R.worker({"kind": "stochpend", "mode": "fast", "paths": paths, "t_max": t_max,
                             "repeat": repeat}, label="stochpend fast fixed-step", group="main")
    main["fast512"] = R.worker({"kind": "stochpend", "mode": "fast", "paths": paths, "t_max": t_max,
                                "repeat": repeat, "wide": True},
                               label="stochpend fast fixed-step, 512-bit vectors", group="main")
    main["c_simd"] = R.worker({"kind": "c", "variant": "simd", "paths": paths, "t_max": t_max,
                               "repeat": repeat}, label="C reference, SIMD blocks (OpenMP)", group="main")
    main["c_simd256"] = R.worker({"kind": "c", "variant": "simd", "flavour": "fast256", "paths": paths,
                                  "t_max": t_max, "repeat": repeat},
                                 label="C reference, SIMD blocks, gcc's default 256-bit vectors",
                                 group="main")
    main["c_scalar"] = R.worker({"kind": "c", "variant": "scalar", "paths": paths, "t_max": t_max,
                                 "repeat": repeat}, label="C reference, scalar per path (OpenMP)",
                                group="main")
    main["numpy"] = R.worker({"kind": "numpy", "paths": paths, "t_max": t_max, "repeat": 1},
                             label="NumPy (default_rng)", group="main")
    if args.no_diffrax:
        main["diffrax"] = R._record({"available": False, "reason": "skipped (--no-diffrax)"},
                                    "diffrax (JAX CPU, Heun)", "main", {}, os.getloadavg()[0], 0.0)
    else:
        main["diffrax"] = R.diffrax(find_bench_python(), paths, t_max, label="diffrax (JAX CPU, Heun)",
                                    group="main")

    print("Thread scaling (same workload):", flush=True)
    threads = {}
    for impl, spec in (("fixed", {"kind": "stochpend", "mode": "fixed"}),
                       ("fast", {"kind": "stochpend", "mode": "fast"}),
                       ("fast512", {"kind": "stochpend", "mode": "fast", "wide": True}),
                       ("c_simd", {"kind": "c", "variant": "simd"}),
                       ("c_scalar", {"kind": "c", "variant": "scalar"}),
                       ("numpy", {"kind": "numpy"})):
        if impl == "numpy":
            threads[(impl, 1)] = main["numpy"]
            continue
        for n in (1, 2):
            s = dict(spec, paths=paths, t_max=t_max, threads=n, repeat=1)
            threads[(impl, n)] = R.worker(s, label=f"{main[impl]['label']}, {n} thread(s)", group="threads")

    print("Scaling with paths (path-steps per point about constant):", flush=True)
    path_list = [10**k for k in range(2, 6 if quick else 8)]
    budget = 10**6 if quick else 10**8
    scaling = {}
    for n in path_list:
        steps = max(10, min(10_000 if not quick else 1_000, budget // n))
        tm = steps * H
        for impl, spec in (("fixed", {"kind": "stochpend", "mode": "fixed"}),
                           ("fast", {"kind": "stochpend", "mode": "fast"}),
                           ("c_simd", {"kind": "c", "variant": "simd"}),
                           ("numpy", {"kind": "numpy"})):
            s = dict(spec, paths=n, t_max=tm, repeat=1)
            scaling[(impl, n)] = R.worker(s, label=f"{main[impl]['label']}, {n:.0e} paths x {steps} steps",
                                          group="paths")
    total = time.perf_counter() - t_start
    shutil.rmtree(cache_dir, ignore_errors=True)
    shutil.rmtree(jit_dir, ignore_errors=True)
    shutil.rmtree(fast_dir, ignore_errors=True)
    return {"info": info, "quick": quick, "paths": paths, "t_max": t_max, "main": main,
            "threads": threads, "scaling": scaling, "path_list": path_list, "total_s": total,
            "load_start": load_start, "load_end": os.getloadavg(), "records": R.records,
            "micro": micro}


# ----------------------------------------------------------------------------------------------
# Report.
# ----------------------------------------------------------------------------------------------
def _rate(rec, cpu=False):
    if not rec or not rec.get("available"):
        return None
    return rec.get("rate_per_cpu_s") if cpu else rec.get("rate")


def _ratio_val(a, b, cpu=False):
    ra, rb = _rate(a, cpu), _rate(b, cpu)
    return ra / rb if ra and rb else None


def _ratio(a, b, cpu=False):
    v = _ratio_val(a, b, cpu)
    return "-" if v is None else f"{v:.2f}x"


MAIN_ORDER = ("fixed", "fast", "fast512", "adaptive", "c_simd", "c_simd256", "c_scalar", "numpy", "diffrax")


def report(res: dict) -> str:
    info, main, thr = res["info"], res["main"], res["threads"]
    L = []
    L.append("# Benchmark results (issue 5)\n")
    L.append(f"Written by `python -m benchmarks{' --quick' if res['quick'] else ''}` "
             f"on {info['date']} in {res['total_s']:.0f} s. Do not edit by hand: rerun `make bench`.\n")
    L.append("## Machine\n")
    for k in ("Model name", "CPU(s)", "Thread(s) per core", "Core(s) per socket", "L2 cache", "L3 cache",
              "Hypervisor vendor", "memory", "avx512f", "platform", "python", "numpy", "numba", "llvmlite",
              "gcc"):
        if k in info:
            L.append(f"- {k}: {info[k]}")
    ls, le = res["load_start"], res["load_end"]
    L.append(f"- load average at start: {ls[0]:.2f} {ls[1]:.2f} {ls[2]:.2f}; at end: "
             f"{le[0]:.2f} {le[1]:.2f} {le[2]:.2f}")
    if max(ls[0], le[0]) > 2.5:
        L.append("\n**The machine was shared during this run** (load average well above the 2 cores): "
                 "other processes took CPU time, so the wall-clock rates are lower than on an idle "
                 "machine and vary from row to row. The CPU-time columns (path-steps per CPU-second "
                 "of the measuring process) are much less affected and are the ones to compare "
                 "across rows; the 2-thread wall-clock rates and the thread scaling are only "
                 "meaningful on an idle machine.")
    L.append("")
    L.append(f"## Main workload\n\nOU noise, D = τ = ω = 1, {res['paths']:,} paths, fixed step h = {H}, "
             f"t = {res['t_max']:g} ({res['paths'] * round(res['t_max'] / H):.0e} path-steps), float64; "
             "θ₀ uniform, Ω₀ = 0, ξ₀ stationary; time of the simulation call only (compilation "
             "excluded, reported below), best of the repeats. Each row is its own process. Every "
             "implementation reports ⟨E²⟩/(Dt/τ²) at the last time (second-order averaging predicts "
             "0.25 as t → ∞; at t = 100 it is still about 0.20). stochpend, its fast kernel and the C "
             "reference use the same Philox numbers (the ⟨E²⟩ agree to ~1e-5 relative, the chaotic "
             "dynamics amplifying round-off differences over 10⁴ steps); NumPy and diffrax use their "
             "own generators (agreement within the standard error).\n")
    L.append("| implementation | threads | path-steps/s (wall) | path-steps per CPU-s | cpu/wall | "
             "stochpend fixed / this (wall) | stochpend fast / this (wall) | stochpend fast / this (CPU) | "
             "peak RSS (MB) | ⟨E²⟩/(Dt/τ²) ± s.e. | load before |")
    L.append("|---|---|---|---|---|---|---|---|---|---|---|")
    for key in MAIN_ORDER:
        rec = main.get(key)
        if rec is None:
            continue
        if not rec.get("available"):
            L.append(f"| {rec['label']} | | not available: {rec.get('reason')} | | | | | | | | |")
            continue
        cpuw = f"{rec['cpu_s'] / rec['wall_s']:.2f}" if rec.get("cpu_s") else "-"
        se = f" ± {rec['E2_scaled_stderr']:.4f}" if "E2_scaled_stderr" in rec else ""
        L.append(f"| {rec['label']} | {rec.get('threads', '-')} | {_fmt_rate(_rate(rec))} | "
                 f"{_fmt_rate(_rate(rec, True))} | {cpuw} | {_ratio(main['fixed'], rec)} | "
                 f"{_ratio(main['fast'], rec)} | {_ratio(main['fast'], rec, True)} | "
                 f"{rec.get('peak_rss_mb', 0):.0f} | {rec['E2_scaled']:.4f}{se} | {rec['loadavg_before']:.2f} |")
    L.append("\nNotes: *fast* is `stochpend._backends.cpu_fast` (SIMD blocks of 64 paths, "
             "branch-free log/sin/cos) run through `simulate()` in place of `cpu.advance_paths`; "
             "*512-bit vectors* is the same with `NUMBA_CPU_FEATURES=<host features>,-prefer-256-bit` "
             "(LLVM otherwise vectorizes 4 doubles wide on this CPU). The C reference is "
             f"`{main['c_simd'].get('compile_command', 'gcc')}`; the 256-bit row drops "
             "`-mprefer-vector-width=512` (the brief's flags exactly). diffrax's threads are XLA's "
             "own pool (its CPU time covers all of them).")
    adaptive = main["adaptive"]
    if adaptive.get("available") and main["fixed"].get("available"):
        L.append(f"\nThe adaptive run (default step control, h ≤ 0.05) takes {adaptive['path_steps']:.3g} "
                 f"path-steps in {adaptive['wall_s']:.2f} s, against {main['fixed']['wall_s']:.2f} s for "
                 "the fixed-step run: compare wall times, not path-steps/s.")
    d = main["diffrax"]
    if d.get("available"):
        L.append(f"\ndiffrax {d['diffrax_version']} on JAX {d['jax_version']} (separate venv): first call "
                 f"{d['first_call_s']:.2f} s (trace + XLA compile + run), steady {d['steady_s']:.2f} s, "
                 f"compile ≈ {d['compile_s']:.2f} s, import {d['import_s']:.2f} s; peak RSS "
                 f"{d['peak_rss_mb']:.0f} MB. Heun is another scheme (two drift evaluations per step); "
                 "its ⟨E²⟩ is statistically comparable, not equal.")
    for key in ("numpy", "fixed", "fast"):
        rec = main[key]
        if rec.get("available") and "traced_peak_mb" in rec:
            L.append(f"\n{rec['label']}: tracemalloc peak during the timed call {rec['traced_peak_mb']:.1f} MB.")

    L.append("\n## Targets\n")
    L.append("Wall-clock ratios from the main table, and the same ratios in path-steps per CPU-second "
             "(the comparison that survives a shared machine; for NumPy, 1 thread, it compares the "
             "work per core).\n")
    rows = [
        ("stochpend fixed ≥ 0.7× C reference (SIMD, 512-bit)", "fixed", "c_simd", 0.7),
        ("stochpend fast ≥ 0.7× C reference (SIMD, 512-bit)", "fast", "c_simd", 0.7),
        ("stochpend fast (512-bit) ≥ 0.7× C reference (SIMD, 512-bit)", "fast512", "c_simd", 0.7),
        ("stochpend fast ≥ 0.7× C reference (SIMD, 256-bit, brief's flags)", "fast", "c_simd256", 0.7),
        ("stochpend fixed ≥ 0.7× C reference (scalar)", "fixed", "c_scalar", 0.7),
        ("stochpend fixed ≥ 30× NumPy", "fixed", "numpy", 30),
        ("stochpend fast ≥ 30× NumPy", "fast", "numpy", 30),
        ("stochpend fixed ≥ 100× diffrax", "fixed", "diffrax", 100),
        ("stochpend fast ≥ 100× diffrax", "fast", "diffrax", 100),
    ]
    L.append("| target | measured (wall) | met | measured (CPU time) | met |")
    L.append("|---|---|---|---|---|")

    def cell(v, goal):
        return ("-", "-") if v is None else (f"{v:.2f}x", "yes" if v >= goal else "no")

    for name, a, b, goal in rows:
        w = cell(_ratio_val(main[a], main[b]), goal)
        c = cell(_ratio_val(main[a], main[b], True), goal)
        L.append(f"| {name} | {w[0]} | {w[1]} | {c[0]} | {c[1]} |")
    for impl in ("fixed", "fast", "fast512"):
        w = cell(_ratio_val(thr[(impl, 2)], thr[(impl, 1)]), 1.7)
        L.append(f"| {main[impl]['label']}: 2 threads ≥ 1.7× 1 thread | {w[0]} | {w[1]} | - | - |")
    jit = [r for r in res["records"] if r["group"] == "jit"]
    for r in jit:
        if "second process" in r["label"] and r.get("available"):
            rc = r.get("ready_cpu_s")
            L.append(f"| {r['label']}: < 1 s before computing | {r['ready_s']:.2f} s | "
                     f"{'yes' if r['ready_s'] < 1 else 'no'} | "
                     f"{'-' if rc is None else f'{rc:.2f} s'} | "
                     f"{'-' if rc is None else ('yes' if rc < 1 else 'no')} |")

    L.append("\n## JIT compile time and the on-disk cache\n")
    L.append("Each row is a fresh process with `NUMBA_CACHE_DIR` set to a new directory (first row of "
             "each pair: empty; second: what the first wrote). Times from the moment the parent "
             "spawned the process. `ready` = process start to the start of computing (interpreter, "
             "imports, kernel load or compile) = `import done` + first call − second call.\n")
    L.append("`ready (CPU)` is the same in CPU time of the process (all its threads): what `ready` "
             "would be on an idle machine, give or take the threads' spinning.\n")
    L.append("| process | interpreter up | `import stochpend` done | first call | second call | "
             "compile ≈ | ready | ready (CPU) | peak RSS (MB) | load before |")
    L.append("|---|---|---|---|---|---|---|---|---|---|")
    for r in jit:
        if not r.get("available"):
            L.append(f"| {r['label']} | not available: {r.get('reason')} | | | | | | | | |")
            continue
        L.append(f"| {r['label']} | {r['startup_s']:.2f} s | {r['import_s']:.2f} s | {r['first_call_s']:.2f} s | "
                 f"{r['second_call_s']:.3f} s | {r['compile_s']:.2f} s | {r['ready_s']:.2f} s | "
                 f"{r.get('ready_cpu_s', float('nan')):.2f} s | {r['peak_rss_mb']:.0f} | {r['loadavg_before']:.2f} |")
    L.append("\n(first/second call: `simulate()` of 1,000 paths × 100 steps, fixed step.)")

    L.append("\n## Thread scaling (main workload)\n")
    L.append("| implementation | 1 thread (wall) | 2 threads (wall) | speed-up (wall) | 1 thread per CPU-s | "
             "2 threads per CPU-s | cpu/wall at 2 threads | load before 2-thread run |")
    L.append("|---|---|---|---|---|---|---|---|")
    for impl in ("fixed", "fast", "fast512", "c_simd", "c_scalar"):
        a, b = thr[(impl, 1)], thr[(impl, 2)]
        cw = f"{b['cpu_s'] / b['wall_s']:.2f}" if b.get("available") and b.get("cpu_s") else "-"
        L.append(f"| {main[impl]['label']} | {_fmt_rate(_rate(a))} | {_fmt_rate(_rate(b))} | "
                 f"{_ratio(b, a)} | {_fmt_rate(_rate(a, True))} | {_fmt_rate(_rate(b, True))} | {cw} | "
                 f"{b.get('loadavg_before', 0):.2f} |")

    L.append("\n## Scaling with paths (path-steps/s, wall; 2 threads, NumPy 1)\n")
    L.append("About 10⁸ path-steps per point (10⁶ with --quick): fewer steps for the big ensembles, "
             "at least 10, so the per-call costs (initial conditions, statistics) weigh more there. "
             "In parentheses: path-steps per CPU-second.\n")
    impls = ("fixed", "fast", "c_simd", "numpy")
    L.append("| paths | steps | " + " | ".join(main[i]["label"] for i in impls) + " |")
    L.append("|---|---|" + "---|" * len(impls))
    for n in res["path_list"]:
        recs = [res["scaling"][(i, n)] for i in impls]
        steps = recs[0].get("path_steps", 0) // n if recs[0].get("available") else "-"
        L.append(f"| {n:.0e} | {steps} | " + " | ".join(
            f"{_fmt_rate(_rate(r))} ({_fmt_rate(_rate(r, True))})" for r in recs) + " |")

    micro = res.get("micro")
    if micro and micro.get("available"):
        from benchmarks.micro import table

        L.append("\n## Cost of each operation (micro-benchmarks, 1 thread, CPU time)\n")
        L.append("`python -m benchmarks.micro`; see docs/performance.md for the operation count.\n")
        L.append(table(micro["rows"]))

    L.append("\n## Raw records\n\n<details><summary>JSON</summary>\n\n```json")
    L.append(json.dumps([{k: v for k, v in r.items() if k != "rows"} for r in res["records"]],
                        indent=1, default=str))
    L.append("```\n</details>\n")
    return "\n".join(L)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker_main(argv[1])
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="1/100 of the work (smoke run)")
    p.add_argument("--no-diffrax", action="store_true", help="skip the JAX/diffrax part")
    p.add_argument("--out", type=Path, default=None,
                   help="where to write the report (default: benchmarks/RESULTS.md for a full run, "
                        "nothing for --quick)")
    args = p.parse_args(argv)
    res = run_all(args)
    text = report(res)
    out = args.out if args.out is not None else (None if args.quick else HERE / "RESULTS.md")
    if out is not None:
        out.write_text(text + "\n")
        print(f"wrote {out} ({res['total_s']:.0f} s)")
    else:
        print(f"done in {res['total_s']:.0f} s (no report written; use --out)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
