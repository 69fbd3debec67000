"""The kernels' speed at two commits, in one sitting (issue 33: "no kernel more than 3 % slower").

    .venv/bin/python -m benchmarks.commit_speed --old c9b0e83 [--new WORKTREE_OR_REF] [--rounds 5]

Each row is the benchmark's main workload (OU noise, D = tau = omega = 1, theta_0 uniform, float64,
to t = 100, 2 threads), timed as ``stochpend.simulate`` in a process of its own after a short call
that loads or compiles its kernels:

* ``fixed``: 10^5 paths at the fixed step h = 0.01 (10^9 path-steps, the SIMD lock-step blocks),
  no bias estimate;
* ``adaptive``: 10^5 paths at the default step control (the lane machine), no bias estimate;
* ``pairs``: 10^3 paths and 5·10^4 coupled pairs of the bias estimate (the pair kernel's work).

The old commit runs from a git worktree (its own source and Numba cache), the new one from this
checkout's ``src`` unless ``--new`` names a ref. Rows alternate old, new within each round, so a
load that changes between rounds cancels in the per-round ratio; the table gives each time, the
ratios new/old and their median. Both commits must print the same statistic (a restructuring
that keeps the numbers bit for bit). A benchmark: it prints, it asserts nothing.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: Run in the child process: one row, printing "seconds statistic".
_CHILD = """
import sys, time
sys.path.insert(0, sys.argv[1])
import stochpend
row = sys.argv[2]
kw = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=100000, t_max=100.0, times=[100.0], seed=1,
          progress=False, bias_paths=0)
if row == "fixed":
    kw.update(step_c=0.0, h_max=0.01)
if row == "pairs":
    kw.update(paths=1000, bias_paths=50000)
stochpend.simulate(**{**kw, "paths": 512, "bias_paths": 0, "t_max": 1.0, "times": [1.0]})
if row == "pairs":
    stochpend.simulate(**{**kw, "paths": 64, "bias_paths": 64, "t_max": 1.0, "times": [1.0]})
t0 = time.perf_counter()
ds = stochpend.simulate(**kw)
print(f"{time.perf_counter() - t0:.4f} {float(ds.mean_E2.values[-1])!r}")
"""

ROWS = ("fixed", "adaptive", "pairs")


def _source(ref: str, where: Path) -> Path:
    """``src`` of ``ref`` checked out as a detached worktree under ``where``."""
    tree = where / ref.replace("/", "_")
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "-q", "--detach", str(tree), ref], check=True)
    return tree / "src"


def _time(src: Path, row: str, threads: int) -> tuple[float, str]:
    env = {**os.environ, "NUMBA_NUM_THREADS": str(threads), "OMP_NUM_THREADS": str(threads)}
    out = subprocess.run([sys.executable, "-c", _CHILD, str(src), row], capture_output=True, text=True,
                         env=env, check=True).stdout.split()
    return float(out[0]), out[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", required=True, help="the commit before (a git ref)")
    parser.add_argument("--new", default=None, help="the commit after (default: this checkout's src)")
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--rows", default=",".join(ROWS), help=f"comma-separated among {', '.join(ROWS)}")
    args = parser.parse_args(argv)
    rows = [r for r in args.rows.split(",") if r]
    with tempfile.TemporaryDirectory(prefix="commit-speed-") as tmp:
        where = Path(tmp)
        try:
            old = _source(args.old, where)
            new = _source(args.new, where) if args.new else ROOT / "src"
            times: dict[tuple[str, str], list[float]] = {}
            for r in range(args.rounds):
                for row in rows:
                    got = {}
                    for label, src in (("old", old), ("new", new)):
                        seconds, value = _time(src, row, args.threads)
                        times.setdefault((row, label), []).append(seconds)
                        got[label] = value
                        print(f"round {r + 1} {label} {row}: {seconds:.3f} s ({value})", file=sys.stderr)
                    if got["old"] != got["new"]:
                        print(f"warning: {row}: the statistic differs ({got['old']} against {got['new']})",
                              file=sys.stderr)
        finally:
            for tree in where.iterdir():
                subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)], check=False)
    print(f"| row | {args.old} (s) | {args.new or 'this checkout'} (s) | new/old per round | median |")
    print("|---|---|---|---|---|")
    for row in rows:
        o, n = times[(row, "old")], times[(row, "new")]
        ratios = [b / a for a, b in zip(o, n, strict=True)]
        print(f"| {row} | {', '.join(f'{x:.2f}' for x in o)} | {', '.join(f'{x:.2f}' for x in n)} | "
              f"{', '.join(f'{x:.3f}' for x in ratios)} | {statistics.median(ratios):.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
