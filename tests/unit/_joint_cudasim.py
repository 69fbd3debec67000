"""Run the joint-histogram cases of test_joint_histogram.py on the CUDA backend in Numba's CUDA
simulator and save each run's histogram counts (the energy histogram's and the joint one's).

Usage: ``NUMBA_ENABLE_CUDASIM=1 python _joint_cudasim.py CASES.json OUT.npz``. The simulator
must be chosen before Numba is imported, so it runs in a process of its own.
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np


def main(cases_path: str, out_path: str) -> None:
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        raise SystemExit("set NUMBA_ENABLE_CUDASIM=1 before running this script")
    from stochpend.engine import runner
    from stochpend.model.settings import SimulationConfig

    with open(cases_path) as f:
        cases = json.load(f)
    out = {}
    for name, kwargs in cases.items():
        config = SimulationConfig.build(**kwargs)
        acc, _ = runner.run_batches(config, 0, config.n_batches, backend="cuda", chunk_paths=kwargs["paths"] // 2)
        out[f"{name}/hist"] = acc.hist
        out[f"{name}/sums"] = acc.sums
    np.savez(out_path, **out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
