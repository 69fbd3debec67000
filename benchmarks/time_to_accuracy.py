"""Time to a stated accuracy (issue 35, item 5): a benchmark, not a timed test.

    .venv/bin/python -m benchmarks.time_to_accuracy                 # writes benchmarks/RESULTS_ACCURACY.md
    .venv/bin/python -m benchmarks.time_to_accuracy --quick         # a smoke run (1e-2; t = 1, 10; prints only)

For each case, output time t and relative total error ε on ⟨E⟩ and ⟨E²⟩ (95 %: statistical
half-width plus a bound on the discretisation bias), the wall time of:

(a) ``simulate(target_error=ε)``: multilevel Monte Carlo on coupled fixed-step levels, run for
    real (``src/stochpend/runs/multilevel.py``). Where its plan exceeds the budget
    (``--budget-path-steps``) it refuses before any work and names the path-steps it would
    take: the row then gives that work at the rate the run's levels measured, marked "projected".
(b) one level at the best fixed step: a sweep of h = h_0/2^k (k = 0 … 5); at each h a pilot run
    (``simulate(h_max=h, step_c=0)``) measures the statistic's variance per path, the bias
    (its coupled-pair estimate, value + 2 s.e.: the same kind of bound (a) uses) and the rate;
    the paths N for the statistical half-width ε|P| − bias follow, and the time is N·t/h
    path-steps at the measured rate. The h with the least time is the best fixed step. The
    sweep's own pilots are not charged: (b) is the best a user could do who knew h in advance.
(c) ``accuracy="auto"`` with rtol = ε/2: the step level it picks, then the paths for a half-width
    of ε/2 at that level's measured variance and rate.
(d) diffrax (``diffrax_ref.py``, Heun, OU pendulum only) at (b)'s h and N: its steady rate
    measured on about 2e6 path-steps, the work projected; needs the separate ``.venv-bench``
    (benchmarks/README.md), "not available" without it.
(e) the C reference (``benchmarks/c_ref``, OU pendulum only) at (b)'s best h and N: its rate
    measured on a pilot of the same size, the work projected.

(b)–(e) are projections from measured rates and variances (a user would also have to find h);
(a) is a run. Machine and load are written with the table: compare rows of one sitting only.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path

#: The cases: the paper's OU pendulum and the damped family's Boltzmann pendulum (stationary,
#: <E> exact: stochpend.theory.family.boltzmann_pendulum_mean_E) at T = 4, where <E> = 1.88 (at
#: T = 1 it is 0.054, a small difference of large terms: a relative target there measures the
#: spread of E, not the methods).
CASES = {
    "ou-pendulum": dict(noise="ou", D=1.0, tau=1.0, omega=1.0),
    "boltzmann-pendulum": dict(noise="white", D=0.0, omega=1.0, gamma=1.0, additive_D=8.0,
                               initial_temperature=4.0),
}
STATISTICS = ("mean_E", "mean_E2")
Z95 = 1.959963984540054


@dataclass
class Row:
    case: str
    t: float
    eps: float
    method: str
    seconds: float
    path_steps: float
    how: str  # "run", "projected", "not available", ...
    note: str = ""


def _simulate(**kwargs):
    import stochpend

    return stochpend.simulate(progress=False, **kwargs)


def method_a(case: dict, t: float, eps: float, budget: float, seed: int, h_max: float,
             budget_s: float | None = None) -> Row:
    started = time.perf_counter()
    label = f"(a) target_error, h_max {h_max:g}"
    try:
        ds = _simulate(**case, t_max=t, times=[t], target_error=eps, seed=seed, max_path_steps=budget,
                       max_seconds=budget_s, h_max=h_max)
    except ValueError as exc:
        m = re.search(r"([0-9.]+e\+?[0-9]+) path-steps", str(exc))
        # a refusal after the pilot names the plan at the estimates and, where much lower, the
        # plan with each statistic two standard errors larger: both ends go in the note
        low = re.search(r"and to ([0-9.]+e\+?[0-9]+)", str(exc))
        note = (f"plan {float(m.group(1)):.3g} path-steps at the pilot's estimates, {float(low.group(1)):.3g} "
                "two standard errors up; " if m and low else "") + str(exc)[:120]
        return Row("", t, eps, label, math.nan, float(m.group(1)) if m else math.nan, "refused", note)
    seconds = time.perf_counter() - started
    certified = all(bool(ds[f"{s}_certified"].values.all()) for s in STATISTICS)
    worst = max(float(ds[f"{s}_relative_total_error"].values.max()) for s in STATISTICS)
    # where the work went: each level's share of the path-steps (level 0 first); the speed-up
    # over one level at the best step is bounded by the coarse levels' share, which no bias
    # machinery (more levels, Richardson) reduces
    per_level = ds["level_path_steps"].values.astype(float)
    shares = "/".join(f"{100 * x / per_level.sum():.0f}" for x in per_level)
    return Row("", t, eps, label, seconds, float(ds.attrs["path_steps"]), "run",
               f"levels {ds.sizes['level']} (% of path-steps {shares}), worst relative total {worst:.2g}, "
               f"{'certified' if certified else 'NOT certified'}")


@dataclass
class Pilot:
    h: float
    mean: dict
    sd: dict  # per-path standard deviation of each statistic's sample
    bias_bound: dict
    rate: float  # path-steps/s
    path_steps_per_path: float


def pilot(case: dict, t: float, h: float, paths: int, seed: int, **extra) -> Pilot:
    ds = _simulate(**case, t_max=t, times=[t], h_max=h, step_c=extra.pop("step_c", 0.0), paths=paths,
                   seed=seed, bias_paths=paths, **extra)
    mean, sd, bias = {}, {}, {}
    for s in STATISTICS:
        mean[s] = float(ds[s].values[-1])
        sd[s] = float(ds[f"{s}_stderr"].values[-1]) * math.sqrt(paths)
        b = ds.get(f"{s}_bias")
        bias[s] = (abs(float(b.values[-1])) + 2.0 * float(ds[f"{s}_bias_stderr"].values[-1])
                   if b is not None else math.inf)
    per_path = float(ds.attrs.get("path_steps", paths * t / h)) / paths
    # The rate from a run of about 2e7 path-steps without the bias pairs: a pilot of a few
    # steps a path would measure the start-up, not the stepping.
    n_rate = int(min(max(paths, 2e7 / per_path), 2e6))
    extra.pop("accuracy", None), extra.pop("rtol", None)
    h_used = float(ds.attrs.get("h_max", h))
    timed = _simulate(**case, t_max=t, times=[t], h_max=h_used, step_c=float(ds.attrs.get("step_c", 0.0)),
                      paths=n_rate, seed=seed + 7919, bias_paths=0, **extra)
    rate = float(timed.attrs["path_steps"]) / float(timed.attrs["wall_time_s"])
    return Pilot(h_used, mean, sd, bias, rate, per_path)


def paths_for(p: Pilot, eps: float, z: float = Z95) -> float:
    """Paths for a total of eps |P| on every statistic, the bias bound taken off first."""
    need = 0.0
    for s in STATISTICS:
        room = eps * abs(p.mean[s]) - p.bias_bound[s]
        if not room > 0:
            return math.inf
        need = max(need, (z * p.sd[s] / room) ** 2)
    return need


def method_b(case: dict, t: float, eps: float, pilots: list[Pilot]) -> tuple[Row, Pilot | None, float]:
    best: tuple[float, Pilot | None, float] = (math.inf, None, math.inf)
    for p in pilots:
        n = paths_for(p, eps)
        seconds = n * p.path_steps_per_path / p.rate
        if seconds < best[0]:
            best = (seconds, p, n)
    seconds, p, n = best
    if p is None:
        return Row("", t, eps, "(b) best fixed step", math.inf, math.inf, "projected",
                   "no step of the sweep meets the target"), None, math.inf
    return Row("", t, eps, "(b) best fixed step", seconds, n * p.path_steps_per_path, "projected",
               f"h = {p.h:g}, N = {n:.3g}"), p, n


def method_c(case: dict, t: float, eps: float, paths: int, seed: int) -> Row:
    try:
        p = pilot(case, t, 0.05, paths, seed, step_c=0.1, accuracy="auto", rtol=eps / 2)
    except ValueError as exc:
        return Row("", t, eps, "(c) accuracy auto", math.nan, math.nan, "refused", str(exc)[:120])
    n = 0.0
    for s in STATISTICS:
        n = max(n, (Z95 * p.sd[s] / (0.5 * eps * abs(p.mean[s]))) ** 2)
    return Row("", t, eps, "(c) accuracy auto", n * p.path_steps_per_path / p.rate, n * p.path_steps_per_path,
               "projected", f"h_max = {p.h:g} (adaptive), N = {n:.3g}")


def method_d(case_name: str, t: float, eps: float, best: Pilot | None, n: float) -> Row:
    import json
    import subprocess

    here = Path(__file__).resolve().parents[1] / ".venv-bench" / "bin" / "python"
    if case_name != "ou-pendulum" or best is None or not math.isfinite(n) or not here.exists():
        why = ("OU pendulum only (diffrax_ref.py's SDE)" if case_name != "ou-pendulum" else
               "no step meets the target" if best is None or not math.isfinite(n) else
               "no .venv-bench (benchmarks/README.md)")
        return Row("", t, eps, "(d) diffrax", math.nan, math.nan, "not available", why)
    per_path = math.ceil(t / best.h - 1e-9)
    paths = int(min(max(1000, 2e6 / per_path), 200_000))  # about 2e6 path-steps: JAX's steady rate
    proc = subprocess.run([str(here), str(Path(__file__).with_name("diffrax_ref.py")), "--paths", str(paths),
                           "--t-max", repr(t), "--h", repr(best.h)], capture_output=True, text=True, timeout=1800)
    try:
        out = json.loads(proc.stdout.strip().splitlines()[-1])
    except (IndexError, ValueError):
        return Row("", t, eps, "(d) diffrax", math.nan, math.nan, "failed", proc.stderr.strip()[-120:])
    if not out.get("available"):
        return Row("", t, eps, "(d) diffrax", math.nan, math.nan, "not available", out.get("reason", ""))
    rate = float(out["path_steps_per_s"])
    steps = n * per_path
    return Row("", t, eps, "(d) diffrax", steps / rate, steps, "projected",
               f"Heun at (b)'s h = {best.h:g} and N (its own bias not measured), "
               f"{rate / 1e6:.2g} M path-steps/s measured")


def method_e(case_name: str, t: float, eps: float, best: Pilot | None, n: float, paths: int) -> Row:
    if case_name != "ou-pendulum" or best is None or not math.isfinite(n):
        return Row("", t, eps, "(e) C reference", math.nan, math.nan, "not available",
                   "OU pendulum only" if case_name != "ou-pendulum" else "no step meets the target")
    from benchmarks import c_ref

    if c_ref.compiler() is None:
        return Row("", t, eps, "(e) C reference", math.nan, math.nan, "not available", "no C compiler")
    per_path = math.ceil(t / best.h - 1e-9)
    n_rate = int(min(max(paths, 2e7 / per_path), 2e6))  # about 2e7 path-steps: the stepping, not the start
    r = c_ref.run(n_rate, t, best.h)
    rate = n_rate * per_path / r.seconds
    steps = n * per_path
    return Row("", t, eps, "(e) C reference", steps / rate, steps, "projected",
               f"h = {best.h:g}, {rate / 1e6:.0f} M path-steps/s measured")


def run(case_names: list[str], times: list[float], targets: list[float], *, pilot_paths: int,
        budget: float, h0: float, n_h: int, seed: int, a_h_max: list[float], log,
        budget_s: float | None = None) -> list[Row]:
    rows: list[Row] = []
    for name in case_names:
        case = CASES[name]
        for t in times:
            pilots = [pilot(case, t, h0 / 2**k, pilot_paths, seed + 1 + k) for k in range(n_h)]
            for eps in targets:
                block = [method_a(case, t, eps, budget, seed, h, budget_s) for h in a_h_max]
                b, best, n = method_b(case, t, eps, pilots)
                block += [b, method_c(case, t, eps, pilot_paths, seed + 99), method_d(name, t, eps, best, n),
                          method_e(name, t, eps, best, n, pilot_paths)]
                for a in block[:len(a_h_max)]:
                    if a.how == "refused" and best is not None and math.isfinite(a.path_steps):
                        # from the plan at the estimates (the note keeps the lower end)
                        a.seconds = a.path_steps / best.rate
                        a.how = "projected (refused)"
                for r in block:
                    r.case = name
                    log(_line(r))
                rows += block
    return rows


def _fmt_s(x: float) -> str:
    if not math.isfinite(x):
        return "–"
    return f"{x:.3g} s" if x < 3600 else f"{x / 3600:.3g} h"


def _line(r: Row) -> str:
    return (f"{r.case} t={r.t:g} eps={r.eps:g} {r.method}: {_fmt_s(r.seconds)} "
            f"({r.path_steps:.3g} path-steps, {r.how}) {r.note}")


def table(rows: list[Row]) -> str:
    out = ["| case | t | ε | method | wall time | path-steps | how | note | (b)/(this) |",
           "|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        b = next(x for x in rows if x.case == r.case and x.t == r.t and x.eps == r.eps
                 and x.method.startswith("(b)"))
        # A refused (a)'s seconds project the plan at its pilot's estimates, which may be far
        # from what the run would take (1.71e12 path-steps named where 2.4e10 was about right):
        # no ratio to it.
        measured = not r.how.startswith("projected (refused)")
        ratio = (b.seconds / r.seconds if measured and math.isfinite(r.seconds) and r.seconds > 0
                 and math.isfinite(b.seconds) else math.nan)
        out.append(f"| {r.case} | {r.t:g} | {r.eps:g} | {r.method} | {_fmt_s(r.seconds)} | "
                   f"{r.path_steps:.3g} | {r.how} | {r.note} | {'–' if math.isnan(ratio) else f'{ratio:.3g}×'} |")
    return "\n".join(out)


def speedups(rows: list[Row]) -> str:
    """Issue 35's "Fast" criterion per (case, t, eps): (a)'s wall time against the best of
    (b)-(e), and whether (a) certified (a refused or projected (a) is not a result)."""
    out = ["| case | t | ε | (a) | best of (b)–(e) | speed-up |", "|---|---|---|---|---|---|"]
    keys = sorted({(r.case, r.t, r.eps) for r in rows}, key=lambda k: (list(CASES).index(k[0]), k[1], -k[2]))
    for key in keys:
        block = [r for r in rows if (r.case, r.t, r.eps) == key]
        a = min((r for r in block if r.method.startswith("(a)")), key=lambda r: r.seconds
                if math.isfinite(r.seconds) else math.inf)
        others = [r for r in block if not r.method.startswith("(a)") and math.isfinite(r.seconds)]
        best = min(others, key=lambda r: r.seconds) if others else None
        certified = a.how == "run" and "NOT" not in a.note
        state = ", certified" if certified else ", NOT certified" if a.how == "run" else ""
        what = f"{_fmt_s(a.seconds)} ({a.how}{state})"
        if best is None:
            out.append(f"| {key[0]} | {key[1]:g} | {key[2]:g} | {what} | none meets the target | – |")
            continue
        # only a certified (a) met the target: an uncertified or refused one has no speed-up
        ratio = best.seconds / a.seconds if certified and a.seconds > 0 else math.nan
        out.append(f"| {key[0]} | {key[1]:g} | {key[2]:g} | {what} | {_fmt_s(best.seconds)} {best.method[:3]} | "
                   f"{'–' if math.isnan(ratio) else f'{ratio:.3g}×'} |")
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a smoke run: eps 1e-2, t = 1, 10, small pilots")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--times", default="1,10,100")
    ap.add_argument("--targets", default="1e-3,3e-4")
    ap.add_argument("--pilot-paths", type=int, default=20_000)
    ap.add_argument("--budget-path-steps", type=float, default=1e12)
    ap.add_argument("--budget-seconds", type=float, default=600.0,
                    help="(a)'s wall-time budget (max_seconds): a run that would take longer is refused "
                         "before its work and its row projected")
    ap.add_argument("--h0", type=float, default=0.2)
    ap.add_argument("--n-h", type=int, default=5)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--a-h-max", default="0.2", help="(a)'s coarsest steps, one row each")
    ap.add_argument("--out", default=str(Path(__file__).with_name("RESULTS_ACCURACY.md")))
    args = ap.parse_args(argv)
    if args.quick:
        args.times, args.targets, args.pilot_paths, args.n_h = "1,10", "1e-2", 2000, 3
    started = time.perf_counter()
    load0 = os.getloadavg()
    rows = run(args.cases.split(","), [float(x) for x in args.times.split(",")],
               [float(x) for x in args.targets.split(",")], pilot_paths=args.pilot_paths,
               budget=args.budget_path_steps, h0=args.h0, n_h=args.n_h, seed=args.seed,
               a_h_max=[float(x) for x in args.a_h_max.split(",")], budget_s=args.budget_seconds,
               log=lambda s: print(s, file=sys.stderr, flush=True))
    text = "\n".join([
        "# Time to a stated accuracy (issue 35, item 5)", "",
        f"Written by `python -m benchmarks.time_to_accuracy` on {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())} "
        f"in {time.perf_counter() - started:.0f} s; machine: {platform.processor() or platform.machine()}, "
        f"{os.cpu_count()} CPUs, load average {load0[0]:.2f} at start and {os.getloadavg()[0]:.2f} at end. "
        f"Options: {' '.join(argv if argv is not None else sys.argv[1:]) or '(defaults)'}.", "",
        "Relative total error ε (95 %: statistical half-width + bias bound) on both ⟨E⟩ and ⟨E²⟩ "
        "at the one output time t. (a) is a run; (b), (c), (e) are projections from measured "
        "variances and rates (module docstring). Compare rows of this table only.", "",
        "Speed-up of (a) over the best of (b)–(e) (issue 35, \"Fast\"):", "", speedups(rows), "",
        table(rows), ""])
    if args.quick:
        print(text)
    else:
        Path(args.out).write_text(text, encoding="utf-8")
        print(f"wrote {args.out}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
