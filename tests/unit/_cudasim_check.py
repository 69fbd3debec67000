"""Run the CUDA backend in Numba's CUDA simulator and save its results (used by test_cuda_sim.py).

Usage: ``NUMBA_ENABLE_CUDASIM=1 python _cudasim_check.py SPEC.json OUT.npz``

NUMBA_ENABLE_CUDASIM must be set before Numba is imported, and the rest of the test suite
uses the real (CPU) Numba, so the simulator runs in its own process. SPEC.json is a list of
cases ``{"name", "config": SimulationConfig.build kwargs, "first_batch", "stop_batch",
"chunk_paths", "check_paths", "float32", "launch": [work_per_launch, min_steps] or null}``;
every result is saved under ``"<name>/<what>"``.
"""

from __future__ import annotations

import json
import os
import sys
import time

import numpy as np


class RecordingProgress:
    def __init__(self) -> None:
        self.total = None
        self.updates: list[float] = []
        self.finished = False

    def start(self, total: float, description: str) -> None:
        self.total = total

    def update(self, done: float) -> None:
        self.updates.append(done)

    def finish(self) -> None:
        self.finished = True


def main(spec_path: str, out_path: str) -> None:
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        raise SystemExit("set NUMBA_ENABLE_CUDASIM=1 before running this script")
    from stochpend._backends import cuda as backend
    from stochpend.params import SimulationConfig

    with open(spec_path) as f:
        cases = json.load(f)
    ok, reason = backend.availability()
    out: dict[str, np.ndarray] = {
        "availability_ok": np.array(ok),
        "availability_reason": np.array(reason),
    }
    from stochpend import models

    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _user_models

    _user_models.register_all()
    generic_backend = backend
    for case in cases:
        name = case["name"]
        started = time.perf_counter()
        config = SimulationConfig.build(**case["config"])
        # A user-defined model runs on its own copy of the CUDA backend (stochpend.models).
        backend = (models.kernels(config.potential, "cuda") if models.get(config.potential)
                   else generic_backend)
        default_launch = (backend._WORK_PER_LAUNCH, backend._MIN_STEPS_PER_LAUNCH)
        if case.get("launch"):
            backend._WORK_PER_LAUNCH, backend._MIN_STEPS_PER_LAUNCH = case["launch"]
        precisions = ["float64"] + (["float32"] if case.get("float32") else [])
        try:
            for precision in precisions:
                tag = "" if precision == "float64" else "32"
                progress = RecordingProgress()
                sums, path_steps = backend.run_batches(
                    config, case["first_batch"], case["stop_batch"],
                    chunk_paths=case["chunk_paths"], progress=progress, precision=precision,
                )
                out[f"{name}/sums{tag}"] = sums.sums
                out[f"{name}/hist{tag}"] = sums.hist
                out[f"{name}/filled{tag}"] = sums.filled
                out[f"{name}/path_steps{tag}"] = np.array(path_steps)
                out[f"{name}/progress_total{tag}"] = np.array(progress.total)
                out[f"{name}/progress_updates{tag}"] = np.array(progress.updates)
                out[f"{name}/progress_finished{tag}"] = np.array(progress.finished)
                if case.get("check_paths"):
                    states = backend.path_states(config, 0, case["check_paths"], precision=precision)
                    for key, value in states.items():
                        out[f"{name}/state{tag}_{key}"] = value
        finally:
            backend._WORK_PER_LAUNCH, backend._MIN_STEPS_PER_LAUNCH = default_launch
        out[f"{name}/seconds"] = np.array(time.perf_counter() - started)
    np.savez(out_path, **out)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
