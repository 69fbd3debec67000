"""Path-steps/s of two source trees in one sitting (the restructuring's no-slowdown check).

Usage (one process per measurement, alternate the trees, compare only within one sitting):

    git archive OLD_COMMIT src | tar -x -C /tmp/old
    for r in 1 2 3; do for src in /tmp/old/src src; do
        .venv/bin/python benchmarks/revisions.py $src fixed      # or: adaptive
    done; done

``fixed``: the OU pendulum with the fixed step h = 0.01, 10**4 paths to t = 100 (1.0e8
path-steps; the SIMD lock-step driver). ``adaptive``: the default step control, 10**4 paths to
t = 200 (5.1e7 path-steps). Each prints one JSON line: the best wall time of two runs after a
warm-up that loads or compiles the kernels, the path-steps, their rate, and <E>(t_max), which
must be the same for both trees when the restructuring keeps the numbers.
"""

import json
import sys
import time

sys.path.insert(0, sys.argv[1])
import stochpend  # noqa: E402

mode = sys.argv[2]
kw = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, seed=1)
if mode == "fixed":
    kw.update(step_c=0.0, h_max=0.01, paths=10000, t_max=100.0, n_times=10)
else:
    kw.update(paths=10000, t_max=200.0, n_times=40)
stochpend.simulate(**{**kw, "paths": 256, "t_max": 1.0})  # warm-up: load or compile the kernels
best = None
for _ in range(2):
    t0 = time.perf_counter()
    ds = stochpend.simulate(**kw)
    wall = time.perf_counter() - t0
    if best is None or wall < best[0]:
        best = (wall, int(ds.attrs["path_steps"]), float(ds.mean_E[-1]))
print(json.dumps({"src": sys.argv[1], "mode": mode, "wall": best[0], "path_steps": best[1],
                  "rate": best[1] / best[0], "mean_E": best[2], "file": stochpend.__file__}))
