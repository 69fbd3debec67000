"""``python -m benchmarks``: the issue-5 benchmark, every implementation in one sitting.

Workload: OU noise, D = tau = omega = 1, 10**4 paths to t = 100, float64, simulation time only:
the fixed step 0.01 (10**8 path-steps) and the default adaptive step (2.3e7 path-steps). The
main table interleaves its rows over several rounds (median and range of each row; ratios per
round), each measurement in its own subprocess (a fresh interpreter, so peak memory is per
implementation); this process only orchestrates and writes ``benchmarks/RESULTS.md``. Also
timed: the user's run ``stochpend simulate --noise ou --D 1 --tau 1 --omega 1 --paths 10000
--t-max 1000`` as a whole process, with the kernels cached on disk and with an empty cache.

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
#: The damped row's gamma (issue 23: the default path with gamma > 0 within 15 % of the undamped).
GAMMA = 0.5
SEED = 1


# ----------------------------------------------------------------------------------------------
# Worker side: one measurement per process, printed as one JSON line.
# ----------------------------------------------------------------------------------------------
def _rusage():
    import resource

    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024.0


def _steal_s():
    """Seconds of CPU time the hypervisor gave to others (the 'steal' of /proc/stat, all CPUs):
    a timed call with steal ran on a machine shared with a neighbour, and its rate is low."""
    try:
        with open("/proc/stat") as f:
            fields = f.readline().split()
        return int(fields[8]) / os.sysconf("SC_CLK_TCK")
    except (OSError, IndexError, ValueError):
        return float("nan")


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

    from stochpend.runs.simulate import simulate

    # "fixed": the fixed-step run, which the runner gives the SIMD lock-step blocks
    # (stochpend.engine.cpu.spec_for); "adaptive": the default step control, which it gives
    # the SIMD lane machine; "adaptive_libm": the same with the C library's math one path at a
    # time (the default before the lane machine), by replacing cpu.spec_for in this process.
    mode = spec["mode"]
    threads = spec.get("threads")
    paths, t_max = spec["paths"], spec["t_max"]
    # The kernels alone, as the C and NumPy references: no bias estimate (issue 14's subsample
    # of coupled pairs; the user's run below includes it, as a user gets it).
    kw = dict(noise="ou", D=D, tau=TAU, omega=OMEGA, seed=SEED, threads=threads, bias_paths=0)
    if mode == "fixed":
        kw.update(step_c=0.0, h_max=H)
    if mode == "adaptive_damped":  # issue 23: the default path with the family's damping on
        kw.update(gamma=GAMMA)
    if mode == "adaptive_libm":
        from stochpend.engine import cpu
        from stochpend.engine.integrator import KernelSpec

        cpu.spec_for = lambda config, precision="float64": KernelSpec.of(config, precision=precision)
    # Warm-up (loads or compiles the kernels), not timed.
    simulate(paths=min(paths, 64), t_max=min(t_max, 0.05), times=[min(t_max, 0.05)], **kw)
    import tracemalloc

    tracemalloc.start()
    steal0 = _steal_s()
    wall, cpu_s, ds = _timed(lambda: simulate(paths=paths, t_max=t_max, times=[t_max], **kw),
                             spec.get("repeat", 1))
    steal = _steal_s() - steal0
    traced_peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    ps = int(ds.attrs["path_steps"])
    return {
        "available": True, "wall_s": wall, "cpu_s": cpu_s, "path_steps": ps,
        "threads": threads or numba.get_num_threads(),
        "E2_scaled": float(ds["mean_E2"].values[-1]) / (D * t_max / TAU**2),
        "E2_scaled_stderr": float(ds["mean_E2_stderr"].values[-1]) / (D * t_max / TAU**2),
        "peak_rss_mb": _rusage()[1], "traced_peak_mb": traced_peak, "steal_s": steal,
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
    variant = spec["variant"]
    if variant.startswith("adaptive_"):
        def call(n, t):
            return c_ref.run_adaptive(n, [t], D=D, tau=TAU, omega=OMEGA, seed=SEED,
                                      variant=variant[len("adaptive_"):], threads=threads,
                                      flavour=flavour)
    else:
        def call(n, t):
            return c_ref.run(n, t, H, D=D, tau=TAU, omega=OMEGA, seed=SEED, variant=variant,
                             threads=threads, flavour=flavour)
    call(16, 0.05)
    wall, cpu_s, r = _timed(lambda: call(paths, t_max), spec.get("repeat", 1))
    E = r.energy(OMEGA)
    path_steps = r.steps if variant.startswith("adaptive_") else paths * r.steps
    return {
        "available": True, "wall_s": r.seconds, "cpu_s": cpu_s, "path_steps": path_steps,
        "threads": threads or lib.sp_max_threads(), "build_s": build_s,
        "E2_scaled": float(np.mean(E * E)) / (D * t_max / TAU**2),
        "E2_scaled_stderr": float(np.std(E * E) / np.sqrt(paths)) / (D * t_max / TAU**2),
        "peak_rss_mb": _rusage()[1], "compile_command": c_ref.compile_command(flavour),
    }


def _worker_jit(spec):
    """First call (compile, the on-disk cache being empty) against the second call."""
    t_spawn = spec["t_spawn"]
    t_entry = time.monotonic()
    from stochpend.runs.simulate import simulate

    t_import = time.monotonic()
    kw = dict(noise="ou", D=D, tau=TAU, omega=OMEGA, paths=1000, t_max=1.0, times=[1.0], seed=SEED)
    if spec.get("mode", "fixed") == "fixed":
        kw.update(step_c=0.0, h_max=H)
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


def _worker_bias_share(spec):
    """The bias estimate's share of a run's wall time: simulate with the default subsample,
    ``simulation_wall_time_s`` against ``bias_wall_time_s`` (kernels loaded first). ``engine``
    "lanes" is the default (pairs in SIMD lanes, fast math); "one_pair_libm" runs the pairs one
    at a time on the C library's math with the previous default subsample (paths/32, at least
    256), by replacing ``bias.pair_spec`` and ``bias.default_bias_paths`` in this process."""
    from stochpend import bias
    from stochpend.runs.simulate import simulate

    if spec["engine"] == "one_pair_libm":
        from stochpend.engine.integrator import KernelSpec

        bias.pair_spec = lambda config, backend="cpu": KernelSpec.of(config)
        bias.default_bias_paths = lambda paths: int(max(2, min(paths, max(256, paths // 32))))
    kw = dict(noise="ou", D=D, tau=TAU, omega=OMEGA, seed=SEED, n_times=40)
    simulate(paths=256, t_max=1.0, **kw)  # loads or compiles the kernels, not timed
    steal0 = _steal_s()
    ds = simulate(paths=spec["paths"], t_max=spec["t_max"], **kw)
    return {
        "available": True, "sim_s": float(ds.attrs["simulation_wall_time_s"]),
        "bias_s": float(ds.attrs["bias_wall_time_s"]), "pairs": int(ds.attrs["bias_paths"]),
        "path_steps": int(ds.attrs["path_steps"]), "bias_path_steps": int(ds.attrs["bias_path_steps"]),
        "wall_s": float(ds.attrs["wall_time_s"]), "steal_s": _steal_s() - steal0,
        "peak_rss_mb": _rusage()[1],
    }


BIAS_WORKLOADS = ((10_000, 1000.0), (100_000, 100.0))
BIAS_ENGINES = {"lanes": "pairs in SIMD lanes, fast math, paths/48 (default)",
                "one_pair_libm": "pairs one at a time, C library math, paths/32 (before)"}


def bias_share(R, rounds: int) -> dict:
    """Interleaved rounds of every (workload, engine) of :func:`_worker_bias_share`."""
    out = {}
    for r in range(rounds):
        for paths, t_max in BIAS_WORKLOADS:
            for engine in BIAS_ENGINES:
                out.setdefault((paths, t_max, engine), []).append(R.worker(
                    {"kind": "bias_share", "engine": engine, "paths": paths, "t_max": t_max},
                    label=f"bias share, {paths} paths to t = {t_max:g}, {engine} (round {r + 1})",
                    group="bias"))
    return out


def bias_report(bias_res: dict, rounds: int) -> list[str]:
    L = ["\n## The bias estimate's share of the run (issue 19)\n",
         "OU D = τ = ω = 1, 40 output times, default step control, 2 threads; "
         "`simulation_wall_time_s` and `bias_wall_time_s` of one `simulate` call (kernels loaded "
         f"first), {rounds} interleaved rounds: median (range) of bias / simulation.\n",
         "| workload | pairs engine | pairs | pair path-steps / run's | bias s | simulation s | "
         "bias / simulation |", "|---|---|---|---|---|---|---|"]
    for (paths, t_max, engine), recs in bias_res.items():
        ok = [r for r in recs if r.get("available")]
        if not ok:
            L.append(f"| {paths} paths, t = {t_max:g} | {BIAS_ENGINES[engine]} | unavailable: "
                     f"{recs[0].get('reason', '?')} | | | | |")
            continue
        shares = [r["bias_s"] / r["sim_s"] for r in ok]
        L.append(f"| {paths} paths, t = {t_max:g} | {BIAS_ENGINES[engine]} | {ok[0]['pairs']} | "
                 f"{ok[0]['bias_path_steps'] / ok[0]['path_steps']:.3f} | "
                 f"{_median([r['bias_s'] for r in ok]):.3g} | {_median([r['sim_s'] for r in ok]):.3g} | "
                 f"**{100 * _median(shares):.1f} %** ({100 * min(shares):.1f}–{100 * max(shares):.1f} %) |")
    return L


def _worker_micro(spec):
    from benchmarks import micro

    return {"available": True, "rows": micro.run(), "peak_rss_mb": _rusage()[1]}


WORKERS = {"stochpend": _worker_stochpend, "numpy": _worker_numpy, "c": _worker_c,
           "jit": _worker_jit, "micro": _worker_micro, "bias_share": _worker_bias_share}


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

    def env(self, threads: int | None = None, cache_dir: str | None = None) -> dict:
        env = dict(os.environ)
        env["NUMBA_CACHE_DIR"] = cache_dir or self.cache_dir
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
            cwd=ROOT, env=self.env(spec.get("threads"), cache_dir),
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

    def cli(self, args: list[str], *, label: str, group: str, cache_dir: str, timeout: float = 900):
        """One whole ``python -m stochpend ...`` process, timed from spawn to exit (wall) with
        its CPU time (all threads); ``cache_dir`` is its NUMBA_CACHE_DIR."""
        import resource

        load0 = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as cwd:
            proc = subprocess.run([sys.executable, "-m", "stochpend", *args], cwd=cwd,
                                  env=self.env(cache_dir=cache_dir), capture_output=True, text=True,
                                  timeout=timeout)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        cpu_s = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
        if proc.returncode != 0:
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-3:]
            out = {"available": False, "reason": f"rc={proc.returncode}: {' | '.join(tail)}"}
        else:
            out = {"available": True, "process_wall_s": wall, "process_cpu_s": cpu_s,
                   "command": "stochpend " + " ".join(args)}
            # the table's caption (wrapped over lines): "... Wall time 7.12 s, 3.4e+08 path-steps."
            import re

            text = " ".join((proc.stdout + proc.stderr).split())
            found = re.search(r"Wall time [0-9.e+]+ s, [0-9.e+]+ path-steps", text)
            if found:
                out["reported"] = found.group(0)
        spec = {"kind": "cli", "args": args}
        return self._record(out, label, group, spec, load0, wall)

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
        parts.append(f"({rec['path_steps']:.3g} path-steps in {rec['wall_s']:.2f} s"
                     + (f", steal {rec['steal_s']:.2f} s" if "steal_s" in rec else "") + ")")
    if "E2_scaled" in rec:
        parts.append(f"<E2>/(Dt/tau2) = {rec['E2_scaled']:.4f}")
    if "compile_s" in rec:
        parts.append(f"compile {rec['compile_s']:.2f} s")
    if "ready_s" in rec:
        parts.append(f"ready after {rec['ready_s']:.2f} s")
    if "process_wall_s" in rec:
        parts.append(f"process {rec['process_wall_s']:.2f} s wall, {rec['process_cpu_s']:.2f} s CPU")
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
        info["avx2"] = " avx2 " in f" {flags} "
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


def find_bench_python() -> str | None:
    cand = ROOT / ".venv-bench" / "bin" / "python"
    return str(cand) if cand.exists() else None


#: The rows of the main table: key -> (label, worker spec without paths/t_max).
MAIN_ROWS = {
    "fixed": ("stochpend fixed step (SIMD lock-step blocks)", {"kind": "stochpend", "mode": "fixed"}),
    "adaptive": ("stochpend default: adaptive step (SIMD lanes)",
                 {"kind": "stochpend", "mode": "adaptive"}),
    "adaptive_libm": ("stochpend adaptive step, C library's math one path at a time (the old default)",
                      {"kind": "stochpend", "mode": "adaptive_libm"}),
    "adaptive_damped": (f"stochpend default with damping gamma = {GAMMA:g} (SIMD lanes)",
                        {"kind": "stochpend", "mode": "adaptive_damped"}),
    "c_simd": ("C reference, fixed step, SIMD blocks", {"kind": "c", "variant": "simd"}),
    "c_adaptive": ("C reference, adaptive step, SIMD lanes", {"kind": "c", "variant": "adaptive_simd"}),
    "c_scalar": ("C reference, fixed step, one path at a time", {"kind": "c", "variant": "scalar"}),
    "c_adaptive_scalar": ("C reference, adaptive step, one path at a time",
                          {"kind": "c", "variant": "adaptive_scalar"}),
    "numpy": ("NumPy reference, fixed step (default_rng, 1 thread)", {"kind": "numpy"}),
}
#: Fixed-step rows (10**8 path-steps) and adaptive ones (2.3e7): the workload's two step modes.
ADAPTIVE_ROWS = ("adaptive", "adaptive_libm", "adaptive_damped", "c_adaptive", "c_adaptive_scalar")
USER_RUN = ["simulate", "--noise", "ou", "--D", "1", "--tau", "1", "--omega", "1", "--paths", "10000",
            "--t-max", "1000"]


def run_all(args) -> dict:
    quick = args.quick
    # Main workload: 10**4 paths to t = 100; quick: 10**3 to t = 10.
    paths = 1_000 if quick else 10_000
    t_max = 10.0 if quick else 100.0
    rounds = 1 if quick else args.rounds
    cache_dir = tempfile.mkdtemp(prefix="stochpend_bench_numba_")
    R = Runner(cache_dir)
    info = machine_info()
    t_start = time.perf_counter()
    load_start = os.getloadavg()
    print(f"stochpend benchmark ({'quick' if quick else 'full'}), {info.get('Model name', '?')}, "
          f"{info.get('CPU(s)', '?')} CPUs, avx512f {info.get('avx512f')}, load {load_start[0]:.2f}",
          flush=True)

    print("JIT compile and on-disk cache:", flush=True)
    dirs = []
    for mode in ("fixed", "adaptive"):
        jit_dir = tempfile.mkdtemp(prefix="stochpend_bench_jit_")
        dirs.append(jit_dir)
        R.worker({"kind": "jit", "mode": mode}, label=f"stochpend {mode}, first process (empty cache)",
                 group="jit", cache_dir=jit_dir)
        R.worker({"kind": "jit", "mode": mode}, label=f"stochpend {mode}, second process (cache on disk)",
                 group="jit", cache_dir=jit_dir)
    # Populate the run's cache so that the timed workers only load.
    for mode in ("fixed", "adaptive", "adaptive_libm", "adaptive_damped"):
        R.worker({"kind": "stochpend", "mode": mode, "paths": 64, "t_max": 0.1}, label="(cache warm-up)",
                 group="warmup")

    user = {}
    if not args.no_user_run and not quick:
        print("The user's run, whole process:", flush=True)
        user_dir = tempfile.mkdtemp(prefix="stochpend_bench_user_")
        dirs.append(user_dir)
        user["cold"] = R.cli(USER_RUN, label="empty kernel cache (first run)", group="user",
                             cache_dir=user_dir)
        user["warm"] = [R.cli(USER_RUN, label=f"kernels cached on disk, run {i + 1}", group="user",
                              cache_dir=user_dir) for i in range(2)]
        user["warm"].append(R.cli(USER_RUN + ["--bias-paths", "0"],
                                  label="kernels cached on disk, without the bias estimate (--bias-paths 0)",
                                  group="user", cache_dir=user_dir))

    bias_res = {}
    if not quick:
        print("The bias estimate's share of the run:", flush=True)
        bias_res = bias_share(R, rounds)

    print("Micro-benchmarks (1 thread, CPU time):", flush=True)
    micro = R.worker({"kind": "micro"}, label="micro-benchmarks", group="micro")

    print(f"Main workload: OU, D = tau = omega = 1, {paths} paths, t = {t_max:g}, {rounds} "
          "interleaved rounds:", flush=True)
    main = {key: [] for key in MAIN_ROWS}
    for r in range(rounds):
        for key, (label, spec) in MAIN_ROWS.items():
            main[key].append(R.worker(dict(spec, paths=paths, t_max=t_max, repeat=1),
                                      label=f"{label} (round {r + 1})", group="main"))
    if args.no_diffrax:
        diffrax = R._record({"available": False, "reason": "skipped (--no-diffrax)"},
                            "diffrax (JAX CPU, Heun)", "main", {}, os.getloadavg()[0], 0.0)
    else:
        diffrax = R.diffrax(find_bench_python(), paths, t_max, label="diffrax (JAX CPU, Heun)",
                            group="main")

    print("Thread scaling (same workload):", flush=True)
    threads = {}
    for impl in ("fixed", "adaptive", "c_simd", "c_adaptive"):
        for n in (1, 2):
            s = dict(MAIN_ROWS[impl][1], paths=paths, t_max=t_max, threads=n, repeat=1)
            threads[(impl, n)] = R.worker(s, label=f"{MAIN_ROWS[impl][0]}, {n} thread(s)", group="threads")

    print("Scaling with paths (path-steps per point about constant):", flush=True)
    path_list = [10**k for k in range(2, 6 if quick else 8)]
    budget = 10**6 if quick else 10**8
    scaling = {}
    for n in path_list:
        steps = max(10, min(10_000 if not quick else 1_000, budget // n))
        tm = steps * H
        for impl in ("fixed", "adaptive", "c_simd", "numpy"):
            s = dict(MAIN_ROWS[impl][1], paths=n, t_max=tm, repeat=1)
            scaling[(impl, n)] = R.worker(s, label=f"{MAIN_ROWS[impl][0]}, {n:.0e} paths to t = {tm:g}",
                                          group="paths")
    total = time.perf_counter() - t_start
    for d in [cache_dir, *dirs]:
        shutil.rmtree(d, ignore_errors=True)
    return {"info": info, "quick": quick, "paths": paths, "t_max": t_max, "rounds": rounds,
            "main": main, "diffrax": diffrax, "user": user, "threads": threads, "scaling": scaling,
            "path_list": path_list, "total_s": total, "load_start": load_start,
            "load_end": os.getloadavg(), "records": R.records, "micro": micro, "bias": bias_res}


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


def _median(values):
    values = sorted(v for v in values if v is not None)
    if not values:
        return None
    m = len(values) // 2
    return values[m] if len(values) % 2 else 0.5 * (values[m - 1] + values[m])


def _spread(values, fmt):
    """'median (min–max)' of the non-missing values."""
    vals = [v for v in values if v is not None]
    if not vals:
        return "-"
    if len(vals) == 1:
        return fmt(vals[0])
    return f"{fmt(_median(vals))} ({fmt(min(vals))}–{fmt(max(vals))})"


def _round_ratios(main, a, b, cpu=False):
    """The ratio a/b of path-steps/s in each round (the rows a and b of one round ran back to
    back, so the ratio survives a load that changes between rounds)."""
    return [_ratio_val(x, y, cpu) for x, y in zip(main[a], main[b], strict=True)]


def _x(v):
    return f"{v:.2f}x"


def report(res: dict) -> str:
    info, main, thr = res["info"], res["main"], res["threads"]
    L = []
    L.append("# Benchmark results (issue 5)\n")
    L.append(f"Written by `python -m benchmarks{' --quick' if res['quick'] else ''}` "
             f"on {info['date']} in {res['total_s']:.0f} s. Do not edit by hand: rerun `make bench`.\n")
    L.append("## Machine\n")
    for k in ("Model name", "CPU(s)", "Thread(s) per core", "Core(s) per socket", "L2 cache", "L3 cache",
              "Hypervisor vendor", "memory", "avx2", "avx512f", "platform", "python", "numpy", "numba",
              "llvmlite", "gcc"):
        if k in info:
            L.append(f"- {k}: {info[k]}")
    ls, le = res["load_start"], res["load_end"]
    L.append(f"- load average at start: {ls[0]:.2f} {ls[1]:.2f} {ls[2]:.2f}; at end: "
             f"{le[0]:.2f} {le[1]:.2f} {le[2]:.2f}")
    if max(ls[0], le[0]) > 2.5:
        L.append("\n**The machine was shared during this run** (load average well above the 2 cores): "
                 "other processes took CPU time, so the wall-clock rates are lower than on an idle "
                 "machine and vary from round to round. The path-steps per CPU-second columns, and the "
                 "ratios of rows measured back to back in one round, are much less affected; the "
                 "2-thread wall-clock rates and the thread scaling are only meaningful on an idle "
                 "machine.")
    L.append("")
    rounds = res["rounds"]
    n_fixed = res["paths"] * round(res["t_max"] / H)
    adapt = next((r for r in main["adaptive"] if r.get("available")), {})
    L.append(f"## Main workload\n\nOU noise, D = τ = ω = 1, {res['paths']:,} paths to t = {res['t_max']:g}, "
             f"float64; θ₀ uniform, Ω₀ = 0, ξ₀ stationary; time of the simulation call only (compilation "
             f"excluded, reported below), without the bias estimate (`bias_paths=0`: the references "
             f"have none; its cost is in the user's run below). Fixed step h = {H} ({n_fixed:.1e} path-steps), or the default "
             f"adaptive step h = min(0.05, 0.1/|Ω|, 0.1/√|ω² + ξ|) ({adapt.get('path_steps', 0):.3g} "
             f"path-steps: the rates of the two step modes are compared in path-steps per second). "
             f"The rows ran one after the other, each in its own process, in {rounds} interleaved "
             f"round(s); each cell is the median over the rounds with the range in parentheses. "
             "Every implementation reports ⟨E²⟩/(Dt/τ²) at the last time (about 0.20 at t = 100); "
             "stochpend and the C reference draw the same Philox numbers, NumPy its own generator.\n")
    L.append("| implementation | threads | M path-steps/s (wall) | M path-steps per CPU-s | "
             "⟨E²⟩/(Dt/τ²) ± s.e. | peak RSS (MB) |")
    L.append("|---|---|---|---|---|---|")
    for key, (label, _) in MAIN_ROWS.items():
        recs = main[key]
        ok = [r for r in recs if r.get("available")]
        if not ok:
            reason = recs[0].get("reason") if recs else "not run"
            L.append(f"| {label} | | not available: {reason} | | | |")
            continue
        se = f" ± {ok[0]['E2_scaled_stderr']:.4f}" if "E2_scaled_stderr" in ok[0] else ""
        L.append(f"| {label} | {ok[0].get('threads', '-')} | "
                 f"{_spread([_rate(r) for r in ok], lambda v: f'{v / 1e6:.1f}')} | "
                 f"{_spread([_rate(r, True) for r in ok], lambda v: f'{v / 1e6:.1f}')} | "
                 f"{ok[0]['E2_scaled']:.4f}{se} | {max(r.get('peak_rss_mb', 0) for r in ok):.0f} |")
    d = res["diffrax"]
    if d.get("available"):
        L.append(f"| diffrax {d['diffrax_version']} (JAX CPU, Heun, fixed step) | XLA | "
                 f"{_rate(d) / 1e6:.1f} | {(_rate(d, True) or 0) / 1e6:.1f} | {d['E2_scaled']:.4f} | "
                 f"{d['peak_rss_mb']:.0f} |")
    else:
        L.append(f"| diffrax (JAX CPU, Heun) | | not available: {d.get('reason')} | | | |")
    L.append("\nThe C reference is `benchmarks/c_ref/stochpend_ref.c`, compiled "
             f"`{next((r.get('compile_command') for r in main['c_simd'] if r.get('compile_command')), 'gcc')}` "
             "(libmvec for log/sin/cos in its SIMD loops; its adaptive SIMD lanes use the same "
             "branch-free OU coefficients and expm1 polynomial as stochpend's lanes).")

    L.append("\n## Targets (ratios of path-steps/s, per round: median and range)\n")
    L.append("| target | wall | met | CPU time | met |")
    L.append("|---|---|---|---|---|")
    rows = [
        ("default (adaptive, SIMD lanes) ≥ 0.5× fixed step (SIMD blocks)", "adaptive", "fixed", 0.5),
        ("default (adaptive) ≥ 0.7× C reference adaptive (SIMD lanes)", "adaptive", "c_adaptive", 0.7),
        ("fixed step ≥ 0.7× C reference fixed step (SIMD)", "fixed", "c_simd", 0.7),
        ("default (adaptive) against the old default (one path at a time, C library)", "adaptive",
         "adaptive_libm", None),
        (f"damped default (gamma = {GAMMA:g}) ≥ 0.85× the undamped default (issue 23)", "adaptive_damped",
         "adaptive", 0.85),
        ("C reference: adaptive SIMD against fixed SIMD", "c_adaptive", "c_simd", None),
        ("fixed step against NumPy (1 thread)", "fixed", "numpy", None),
    ]
    for name, a, b, goal in rows:
        cells = []
        for cpu in (False, True):
            vals = _round_ratios(main, a, b, cpu)
            med = _median(vals)
            met = "-" if goal is None or med is None else ("yes" if med >= goal else "no")
            cells += [_spread(vals, _x), met]
        L.append(f"| {name} | {' | '.join(cells)} |")

    user = res.get("user") or {}
    if user:
        L.append("\n## The user's run, whole process\n")
        L.append(f"`{USER_RUN and 'stochpend ' + ' '.join(USER_RUN)}` (3.4e8 path-steps, 40 output "
                 "times), timed from spawn to exit by this process, with its CPU time (all threads). "
                 "Target: ≤ 8 s with the kernels cached on disk by a previous process.\n")
        L.append("| kernel cache | process wall | process CPU | stochpend's own report | load before |")
        L.append("|---|---|---|---|---|")
        for rec in [user["cold"], *user["warm"]]:
            if not rec.get("available"):
                L.append(f"| {rec['label']} | not available: {rec.get('reason')} | | | |")
                continue
            L.append(f"| {rec['label']} | {rec['process_wall_s']:.1f} s | {rec['process_cpu_s']:.1f} s | "
                     f"{rec.get('reported', '-')} | {rec['loadavg_before']:.2f} |")

    jit = [r for r in res["records"] if r["group"] == "jit"]
    L.append("\n## JIT compile time and the on-disk cache\n")
    L.append("Each row is a fresh process with `NUMBA_CACHE_DIR` set to a new directory (first row of "
             "each pair: empty; second: what the first wrote). Times from the moment the parent "
             "spawned the process. `ready` = process start to the start of computing (interpreter, "
             "imports, kernel load or compile) = `import done` + first call − second call; "
             "`ready (CPU)` the same in CPU time of the process.\n")
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
    L.append("\n(first/second call: `simulate()` of 1,000 paths to t = 1, fixed step 0.01 or the "
             "default adaptive step.)")

    L.append("\n## Thread scaling (main workload)\n")
    L.append("| implementation | 1 thread (wall) | 2 threads (wall) | speed-up (wall) | 1 thread per CPU-s | "
             "2 threads per CPU-s | load before 2-thread run |")
    L.append("|---|---|---|---|---|---|---|")
    for impl in ("fixed", "adaptive", "c_simd", "c_adaptive"):
        a, b = thr[(impl, 1)], thr[(impl, 2)]
        L.append(f"| {MAIN_ROWS[impl][0]} | {_fmt_rate(_rate(a))} | {_fmt_rate(_rate(b))} | "
                 f"{_ratio(b, a)} | {_fmt_rate(_rate(a, True))} | {_fmt_rate(_rate(b, True))} | "
                 f"{b.get('loadavg_before', 0):.2f} |")

    L.append("\n## Scaling with paths (path-steps/s, wall; 2 threads, NumPy 1)\n")
    L.append("About 10⁸ fixed-step path-steps per point (10⁶ with --quick), t = steps × 0.01 for "
             "every row (the adaptive row takes its own steps to the same t); in parentheses: "
             "path-steps per CPU-second.\n")
    impls = ("fixed", "adaptive", "c_simd", "numpy")
    L.append("| paths | t | " + " | ".join(MAIN_ROWS[i][0] for i in impls) + " |")
    L.append("|---|---|" + "---|" * len(impls))
    for n in res["path_list"]:
        recs = [res["scaling"][(i, n)] for i in impls]
        L.append(f"| {n:.0e} | {recs[0]['spec']['t_max']:g} | " + " | ".join(
            f"{_fmt_rate(_rate(r))} ({_fmt_rate(_rate(r, True))})" for r in recs) + " |")

    if res.get("bias"):
        L.extend(bias_report(res["bias"], res["rounds"]))

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


def bias_only(args) -> int:
    """``--bias-only``: the bias share table alone, in one sitting, with the machine."""
    t0 = time.perf_counter()
    cache_dir = tempfile.mkdtemp(prefix="stochpend_bench_numba_")
    R = Runner(cache_dir)
    info = machine_info()
    load0 = os.getloadavg()
    res = bias_share(R, args.rounds)
    shutil.rmtree(cache_dir, ignore_errors=True)
    L = ["# The bias estimate's share of the run\n",
         f"Written by `python -m benchmarks --bias-only` on {info['date']} in "
         f"{time.perf_counter() - t0:.0f} s. Do not edit by hand.\n",
         f"Machine: {info.get('Model name', '?')}, {info.get('CPU(s)', '?')} CPUs, avx512f "
         f"{info.get('avx512f')}; load average {load0[0]:.2f} at start, {os.getloadavg()[0]:.2f} "
         "at end."]
    L.extend(bias_report(res, args.rounds))
    out = args.out if args.out is not None else HERE / "RESULTS_BIAS.md"
    out.write_text("\n".join(L) + "\n")
    print("\n".join(L))
    print(f"wrote {out}")
    return 0


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--worker"]:
        return worker_main(argv[1])
    p = argparse.ArgumentParser(prog="python -m benchmarks", description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="1/100 of the work (smoke run)")
    p.add_argument("--no-diffrax", action="store_true", help="skip the JAX/diffrax part")
    p.add_argument("--rounds", type=int, default=3,
                   help="interleaved rounds of the main table (default 3; --quick: 1)")
    p.add_argument("--no-user-run", action="store_true",
                   help="skip the user's 3.4e8-path-step run (three whole processes)")
    p.add_argument("--out", type=Path, default=None,
                   help="where to write the report (default: benchmarks/RESULTS.md for a full run, "
                        "nothing for --quick)")
    p.add_argument("--bias-only", action="store_true",
                   help="only the bias estimate's share of the run (writes benchmarks/RESULTS_BIAS.md)")
    args = p.parse_args(argv)
    if args.bias_only:
        return bias_only(args)
    res = run_all(args)
    text = report(res)
    out = args.out if args.out is not None else (None if args.quick else HERE / "RESULTS.md")
    if out is not None:
        # benchmarks/startup.py's section (measured apart, by hand) is kept, not erased.
        from benchmarks.startup import BEGIN, END

        old = out.read_text() if out.exists() else ""
        if BEGIN in old and END in old:
            text += "\n\n" + BEGIN + old.split(BEGIN, 1)[1].split(END, 1)[0] + END
        out.write_text(text + "\n")
        print(f"wrote {out} ({res['total_s']:.0f} s)")
    else:
        print(f"done in {res['total_s']:.0f} s (no report written; use --out)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
