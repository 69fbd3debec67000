"""Start-up and first-run times a new user meets (issue 20), run by hand, not a timed test:

    PYTHONPATH=src .venv/bin/python benchmarks/startup.py            # all rows, 5 runs each
    PYTHONPATH=src .venv/bin/python benchmarks/startup.py --runs 3 --only help,info

Each row runs its command in a fresh process ``--runs`` times and prints the median and the range
of the wall times (seconds). "simulate cold" gives every run an empty Numba cache
(``NUMBA_CACHE_DIR`` set to a new temporary directory), so it includes compiling every kernel the
demo run needs; "simulate cached" runs once untimed to fill the cache, then is timed. On a shared
machine the numbers move with the load: report the machine and the load with them.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: The README's demo run (``make demo``), at the size the first-hour issue measured.
DEMO = ["simulate", "--noise", "ou", "--D", "1", "--tau", "1", "--omega", "1", "--paths", "2000",
        "--t-max", "100", "--n-times", "12", "--seed", "1", "-q"]
CLI = [sys.executable, "-c", "from stochpend.cli import main; main()"]
ROWS = {
    "import": [sys.executable, "-c", "import stochpend"],
    "help": [*CLI, "--help"],
    "info": [*CLI, "info"],
    "simulate-cached": [*CLI, *DEMO],
    "simulate-cold": [*CLI, *DEMO],
}


def timed(cmd: list[str], env: dict[str, str]) -> float:
    """Wall time (s) of one run of ``cmd``; a failed run stops the benchmark."""
    start = time.perf_counter()
    done = subprocess.run(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    elapsed = time.perf_counter() - start
    if done.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed (exit {done.returncode}):\n{done.stderr}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--only", default=",".join(ROWS), help=f"comma-separated rows of {', '.join(ROWS)}")
    args = parser.parse_args()
    nproc = os.cpu_count()
    load = os.getloadavg()[0]
    print(f"# {nproc} CPUs, load average {load:.2f}, python {sys.version.split()[0]}, {args.runs} runs per row")
    with tempfile.TemporaryDirectory() as scratch:
        for name in args.only.split(","):
            cmd = ROWS[name]
            env = dict(os.environ)
            times = []
            if name == "simulate-cached":
                env["NUMBA_CACHE_DIR"] = str(Path(scratch) / "warm")
                timed(cmd, env)
            for run in range(args.runs):
                if name == "simulate-cold":
                    env["NUMBA_CACHE_DIR"] = str(Path(scratch) / f"cold{run}")
                times.append(timed(cmd, env))
            print(f"{name:16s} median {statistics.median(times):7.3f} s   "
                  f"range {min(times):.3f}-{max(times):.3f} s", flush=True)


if __name__ == "__main__":
    main()
