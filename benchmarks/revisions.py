"""Path-steps/s of two source trees in one sitting (the restructuring's no-slowdown check).

Usage (one process per measurement, alternate the trees, compare only within one sitting):

    git archive OLD_COMMIT src | tar -x -C /tmp/old
    for r in 1 2 3; do for src in /tmp/old/src src; do
        .venv/bin/python benchmarks/revisions.py $src fixed      # or another mode below
    done; done

Modes, one per kernel a run spends its time in:

* ``fixed``: the OU pendulum with the fixed step h = 0.01, 10**4 paths to t = 100 (1.0e8
  path-steps; the SIMD lock-step driver);
* ``adaptive``: the default step control, 10**4 paths to t = 200 (5.1e7 path-steps; the SIMD lane
  machine);
* ``one-path``: the harmonic oscillator with white noise on x (``coupling="position"``), adaptive:
  the C library's one-path kernel, every model without a SIMD driver;
* ``events``: the dichotomous noise on the pendulum, adaptive: the one-path kernel with the
  noise's events;
* ``pairs``: the bias estimate's coupled pairs of the adaptive run (SIMD pair lanes), timed by
  their own ``bias_wall_time_s`` (2048 pairs to t = 200);
* ``damped``, ``damped-additive``: the adaptive run with gamma = 0.5 (and an additive white
  noise D_a = 0.5): the family's terms on the default path (issue 23; the old tree has none).

Each prints one JSON line: the best wall time of two runs after a warm-up that loads or compiles
the kernels, the path-steps, their rate, and <E>(t_max), which must be the same for both trees
when the restructuring keeps the numbers.
"""

import json
import sys
import time

sys.path.insert(0, sys.argv[1])
import stochpend  # noqa: E402

mode = sys.argv[2]
kw = dict(noise="ou", D=1.0, tau=1.0, omega=1.0, seed=1, bias_paths=0)
if mode == "fixed":
    kw.update(step_c=0.0, h_max=0.01, paths=10000, t_max=100.0, n_times=10)
elif mode == "adaptive":
    kw.update(paths=10000, t_max=200.0, n_times=40)
elif mode == "one-path":
    kw.update(noise="white", potential="harmonic", coupling="position", D=0.5, paths=10000, t_max=40.0,
              n_times=10)
elif mode == "events":
    kw.update(noise="dichotomous", paths=10000, t_max=100.0, n_times=10)
elif mode == "pairs":
    kw.update(paths=2048, t_max=200.0, n_times=40, bias_paths=2048)
elif mode == "damped":
    kw.update(paths=10000, t_max=200.0, n_times=40, gamma=0.5)
elif mode == "damped-additive":
    kw.update(paths=10000, t_max=200.0, n_times=40, gamma=0.5, additive_D=0.5)
else:
    raise SystemExit(f"mode={mode!r} is not accepted")
stochpend.simulate(**{**kw, "paths": 256, "t_max": 1.0, "bias_paths": min(kw["bias_paths"], 256)})  # warm-up
best = None
for _ in range(2):
    t0 = time.perf_counter()
    ds = stochpend.simulate(**kw)
    wall = time.perf_counter() - t0
    if mode == "pairs":  # the pairs alone: their own clock and their steps
        wall, steps = float(ds.attrs["bias_wall_time_s"]), int(ds.attrs["bias_path_steps"])
    else:
        steps = int(ds.attrs["path_steps"])
    if best is None or wall < best[0]:
        best = (wall, steps, float(ds.mean_E[-1]))
print(json.dumps({"src": sys.argv[1], "mode": mode, "wall": best[0], "path_steps": best[1],
                  "rate": best[1] / best[0], "mean_E": best[2], "file": stochpend.__file__}))
