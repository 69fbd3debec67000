"""Run by test_one_table.py in a copy of the package whose statistics table has one more line
(a mean of Omega**6): check that the new statistic reaches the sums of the backend named on the
command line, the Dataset and the bias estimate, and print what was found as JSON.

Usage: ``python _one_entry_check.py cpu|cuda`` (cuda: under NUMBA_ENABLE_CUDASIM=1).
"""

from __future__ import annotations

import json
import sys

import numpy as np

import stochpend
from stochpend import observables
from stochpend.engine import runner
from stochpend.model.settings import SimulationConfig

backend = sys.argv[1]
out: dict = {"package": stochpend.__file__}


class Capture:
    """A checkpointer that keeps the chunk's per-path state once the last output time is summed."""

    n_times = 0
    state: dict = {}

    def maybe_save(self, state) -> None:
        if state.j == self.n_times:
            state.pull()
            self.state = {"Omega": np.array(state.Omega, dtype=np.float64), "status": np.array(state.status)}


paths = 400 if backend == "cpu" else 48
config = SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=paths, t_max=2.0,
                                times=[0.5, 2.0], seed=3, n_batches=8)
capture = Capture()
capture.n_times = len(config.times)
acc, _ = runner.run_batches(config, 0, config.n_batches, backend=backend, checkpointer=capture,
                            chunk_paths=paths)
kept = capture.state["status"] == 0
last = acc.sums[:, -1, :].sum(axis=0)
out["count"] = int(last[observables.S_COUNT])
out["finite_paths"] = int(kept.sum())
out["sum_Omega6"] = float(last[observables.column("Omega6")])
out["state_sum_Omega6"] = float(np.sum(capture.state["Omega"][kept] ** 6))
out["sum_Omega4"] = float(last[observables.column("Omega4")])
out["state_sum_Omega4"] = float(np.sum(capture.state["Omega"][kept] ** 4))

if backend == "cpu":
    ds = stochpend.simulate(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=paths, t_max=2.0, times=[0.5, 2.0],
                            seed=3, n_batches=8, bias_paths=64)
    out["variables"] = sorted(v for v in ds.data_vars if "Omega6" in v)
    out["long_name"] = ds["mean_Omega6"].attrs.get("long_name")
    out["mean_Omega6"] = ds["mean_Omega6"].values.tolist()
    out["mean_Omega6_stderr"] = ds["mean_Omega6_stderr"].values.tolist()
    out["mean_Omega6_bias_stderr"] = ds["mean_Omega6_bias_stderr"].values.tolist()
    out["mean_Omega4"] = ds["mean_Omega4"].values.tolist()
print(json.dumps(out))
