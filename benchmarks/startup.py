"""Start-up and first-run times a new user meets (issues 20 and 36), run by hand, not a timed test:

    .venv/bin/python benchmarks/startup.py                      # every row, 5 runs each
    .venv/bin/python benchmarks/startup.py --runs 3 --only help,info
    .venv/bin/python benchmarks/startup.py --record             # ... and write its section of RESULTS.md

Each row runs its command in a fresh process ``--runs`` times and prints the median and the range
of the wall times (seconds), and the target where issue 36 set one (medians of 5 on an idle
2-core machine: ``--help`` <= 0.3 s, ``show`` of a small result <= 1 s, ``info`` <= 1.5 s).
"show" reads a 12-time, 2000-path result written (untimed) first; "simulate cold" gives every
run an empty Numba cache (``NUMBA_CACHE_DIR`` set to a new temporary directory), so it includes
compiling every kernel the demo run needs; "simulate cached" runs once untimed to fill the cache,
then is timed. On a shared machine the numbers move with the load: the header gives the machine
and the load average before and after, and ``--record`` writes them with the table.
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import re
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
#: The README's demo run (``make demo``), at the size the first-hour issue measured.
DEMO = ["simulate", "--noise", "ou", "--D", "1", "--tau", "1", "--omega", "1", "--paths", "2000",
        "--t-max", "100", "--n-times", "12", "--seed", "1", "-q"]
#: The installed console script when there is one beside this Python (what a user types), else
#: the same entry point through ``-c``.
_SCRIPT = Path(sys.executable).with_name("stochpend")
CLI = [str(_SCRIPT)] if _SCRIPT.exists() else [sys.executable, "-c", "from stochpend.cli import main; main()"]
SMALL_RESULT = "small.nc"  # written in the scratch directory before the rows run
ROWS = {
    "import": [sys.executable, "-c", "import stochpend"],
    "help": [*CLI, "--help"],
    "version": [*CLI, "--version"],
    "show": [*CLI, "show", SMALL_RESULT],
    "info": [*CLI, "info"],
    "list": [*CLI, "list"],
    "theory": [*CLI, "theory"],
    "simulate-cached": [*CLI, *DEMO],
    "simulate-cold": [*CLI, *DEMO],
}
#: Issue 36's targets (s): medians of 5 on an idle 2-core machine.
TARGETS = {"help": 0.3, "show": 1.0, "info": 1.5}
#: The section of RESULTS.md this script owns (``python -m benchmarks`` keeps it when it rewrites the file).
BEGIN, END = "<!-- benchmarks/startup.py: begin -->", "<!-- benchmarks/startup.py: end -->"


#: CPU seconds (user + system) of each finished child, read by :func:`timed`.
CPU_TIMES: list[float] = []


def timed(cmd: list[str], env: dict[str, str], cwd: str) -> float:
    """Wall time (s) of one run of ``cmd`` (its CPU time is appended to :data:`CPU_TIMES`: on a
    loaded machine the wall time grows with the load, a one-thread start-up's CPU time hardly);
    a failed run stops the benchmark."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    CPU_TIMES.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed (exit {done.returncode}):\n{done.stderr}")
    return elapsed


def machine() -> str:
    """One line: CPU model, CPUs usable, memory, Python, OS."""
    model = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    memory = ""
    try:
        kb = int(re.search(r"MemTotal:\s+(\d+)", Path("/proc/meminfo").read_text()).group(1))  # type: ignore[union-attr]
        memory = f", {kb / 2**20:.0f} GiB memory"
    except (OSError, AttributeError, ValueError):
        pass
    return f"{model}, {cpus} CPUs{memory}, Python {platform.python_version()}, {platform.platform()}"


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def record(lines: list[str], results_md: Path) -> None:
    """Replace (or append) this script's section of ``results_md``."""
    section = "\n".join([BEGIN, *lines, END])
    text = results_md.read_text() if results_md.exists() else ""
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        text = head + section + rest.split(END, 1)[1]
    else:
        text = text.rstrip("\n") + "\n\n" + section + "\n"
    results_md.write_text(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", default=",".join(r for r in ROWS if r != "simulate-cold"),
                        help=f"comma-separated rows of {', '.join(ROWS)} (default: all but simulate-cold)")
    parser.add_argument("--record", action="store_true", help="write the table into benchmarks/RESULTS.md")
    args = parser.parse_args()
    names = args.only.split(",")
    unknown = [n for n in names if n not in ROWS]
    if unknown:
        parser.error(f"unknown rows {unknown}; rows: {', '.join(ROWS)}")
    load_before = _load()
    header = f"{machine()}; load average (1, 5, 15 min) before: {load_before}"
    print(f"# {header}; {args.runs} runs per row", flush=True)
    out = ["| row | command | median (s) | range (s) | CPU time, median (s) | target (s) |", "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as scratch:
        env = dict(os.environ)
        env["NUMBA_CACHE_DIR"] = str(Path(scratch) / "warm")
        if "show" in names or "simulate-cached" in names:  # fills the warm cache, writes the file show reads
            timed([*CLI, *DEMO, "--out", SMALL_RESULT], env, scratch)
        for name in names:
            cmd = ROWS[name]
            run_env = dict(env)
            times = []
            del CPU_TIMES[:]
            for run in range(args.runs):
                if name == "simulate-cold":
                    run_env["NUMBA_CACHE_DIR"] = str(Path(scratch) / f"cold{run}")
                times.append(timed(cmd, run_env, scratch))
            median = statistics.median(times)
            cpu = statistics.median(CPU_TIMES)
            target = TARGETS.get(name)
            verdict = "" if target is None else (f"{target:g} (met)" if median <= target else f"{target:g} (NOT met)")
            shown = " ".join(["stochpend", *cmd[len(CLI):]] if cmd[:len(CLI)] == CLI else ["python", *cmd[1:]])
            print(f"{name:16s} median {median:7.3f} s   range {min(times):.3f}-{max(times):.3f} s   "
                  f"CPU {cpu:.3f} s   {verdict}", flush=True)
            out.append(f"| {name} | `{shown}` | {median:.3f} | {min(times):.3f}-{max(times):.3f} | {cpu:.3f} | {verdict} |")
    load_after = _load()
    print(f"# load average after: {load_after}")
    if args.record:
        when = datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")
        lines = ["## Start-up of the commands (benchmarks/startup.py)", "",
                 f"Written by `python benchmarks/startup.py --record` on {when}: each row {args.runs} fresh "
                 "processes, median and range of the wall time; targets of issue 36 (medians of 5 on an idle "
                 "2-core machine). On a loaded machine every wall time is longer: compare the load averages; "
                 "the CPU time (user + system) of a one-thread start-up hardly grows with the load.", "",
                 f"- machine: {machine()}",
                 f"- load average (1, 5, 15 min) before: {load_before}; after: {load_after}", "", *out]
        record(lines, HERE / "RESULTS.md")
        print(f"wrote its section of {HERE / 'RESULTS.md'}")


if __name__ == "__main__":
    main()
