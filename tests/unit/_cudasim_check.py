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

import numpy as np

try:  # a module global, as the simulator expects of the kernels' ``cuda``
    from numba import cuda
except Exception:  # pragma: no cover - numba without its CUDA target
    cuda = None


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
    from stochpend.engine import cuda as backend
    from stochpend.engine import runner
    from stochpend.model.settings import SimulationConfig

    with open(spec_path) as f:
        cases = json.load(f)
    ok, reason = backend.availability()
    out: dict[str, np.ndarray] = {
        "availability_ok": np.array(ok),
        "availability_reason": np.array(reason),
    }
    sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
    import _user_models

    _user_models.register_all()
    import _phase_noise

    _phase_noise.register()
    for case in cases:
        name = case["name"]
        if case.get("kind") == "checkpoint":
            out.update(checkpoint_case(case))
            continue
        if case.get("kind") == "sweep":
            out.update(sweep_case(case))
            continue
        if case.get("kind") == "rng":
            out.update(rng_case(case))
            continue
        if case.get("kind") == "precision_pair":
            out.update(precision_pair_case(case))
            continue
        if case.get("kind") == "bias":
            out.update(bias_case(case))
            continue
        work = 0  # path-steps the case ran (test_cuda_sim bounds the file's work, not its time)
        config = SimulationConfig.build(**case["config"])
        default_launch = (backend._WORK_PER_LAUNCH, backend._MIN_STEPS_PER_LAUNCH)
        if case.get("launch"):
            backend._WORK_PER_LAUNCH, backend._MIN_STEPS_PER_LAUNCH = case["launch"]
        precisions = ["float64"] + (["float32"] if case.get("float32") else [])
        try:
            for precision in precisions:
                tag = "" if precision == "float64" else "32"
                progress = RecordingProgress()
                sums, path_steps = runner.run_batches(
                    config, case["first_batch"], case["stop_batch"], backend="cuda",
                    chunk_paths=case["chunk_paths"], progress=progress, precision=precision,
                )
                out[f"{name}/sums{tag}"] = sums.sums
                out[f"{name}/hist{tag}"] = sums.hist
                out[f"{name}/filled{tag}"] = sums.filled
                out[f"{name}/path_steps{tag}"] = np.array(path_steps)
                work += path_steps
                out[f"{name}/progress_total{tag}"] = np.array(progress.total)
                out[f"{name}/progress_updates{tag}"] = np.array(progress.updates)
                out[f"{name}/progress_finished{tag}"] = np.array(progress.finished)
                if case.get("check_paths"):
                    states = backend.path_states(config, 0, case["check_paths"], precision=precision)
                    for key, value in states.items():
                        out[f"{name}/state{tag}_{key}"] = value
        finally:
            backend._WORK_PER_LAUNCH, backend._MIN_STEPS_PER_LAUNCH = default_launch
        out[f"{name}/work"] = np.array(work)
    np.savez(out_path, **out)


def checkpoint_case(case: dict) -> dict[str, np.ndarray]:
    """A GPU run interrupted at its ``stop_after``-th checkpoint opportunity (after writing the
    checkpoint), then resumed, against the same run uninterrupted: Dataset variables saved as
    "<name>/ref_<var>" and "<name>/resumed_<var>"."""
    import tempfile
    from pathlib import Path

    import stochpend
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import checkpoint

    name = case["name"]
    config = SimulationConfig.build(**case["config"])
    precision = case.get("precision", "float64")
    ref = stochpend.simulate(**case["config"], backend="cuda", precision=precision,
                             chunk_paths=case["chunk_paths"])
    out: dict[str, np.ndarray] = {}
    calls = [0]

    class StopAfter(checkpoint.FileCheckpointer):
        def maybe_save(self, state):
            calls[0] += 1
            if calls[0] == case["stop_after"]:
                self.request_stop()
            super().maybe_save(state)

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "run.ckpt"
        cp = StopAfter(path, None, config=config, chunk_paths=case["chunk_paths"])
        try:
            checkpoint.run_checkpointed(config, checkpoint_path=path, every_s=None,
                                        chunk_paths=case["chunk_paths"], checkpointer=cp,
                                        backend="cuda", precision=precision)
            interrupted = False
        except checkpoint.CheckpointInterrupt:
            interrupted = True
        saved = checkpoint.read(path)
        out[f"{name}/interrupted"] = np.array(interrupted)
        out[f"{name}/saved_backend"] = np.array(saved.state.backend)
        out[f"{name}/saved_precision"] = np.array(saved.state.precision)
        out[f"{name}/saved_x_dtype"] = np.array(str(saved.state.x.dtype))
        out[f"{name}/saved_position"] = np.array([saved.state.b0, saved.state.j])
        resumed = checkpoint.resume(path, out=None)
    for var in ("mean_E", "mean_E4", "mean_Omega2", "E_hist", "batch_sum_E", "nonfinite_paths"):
        out[f"{name}/ref_{var}"] = ref[var].values
        out[f"{name}/resumed_{var}"] = resumed[var].values
    out[f"{name}/ref_path_steps"] = np.array(ref.attrs["path_steps"])
    out[f"{name}/resumed_path_steps"] = np.array(resumed.attrs["path_steps"])
    out[f"{name}/resumed_backend"] = np.array(resumed.attrs["backend"])
    return out


def sweep_case(case: dict) -> dict[str, np.ndarray]:
    """A sweep of cases with ``backend="cuda"`` (in process) against each set run alone."""
    import stochpend
    from stochpend.sweep import sweep

    name = case["name"]
    ds = sweep(case["spec"], backend="cuda", tasks_per_set=2)
    out: dict[str, np.ndarray] = {f"{name}/backend": np.array(ds.attrs.get("backend", ""))}
    for i, override in enumerate(case["spec"]["case"]):
        alone = stochpend.simulate(**{**case["spec"]["base"], **override}, backend="cuda")
        for var in ("mean_E", "E_hist", "batch_sum_E"):
            out[f"{name}/set{i}_{var}"] = ds[var].values[i]
            out[f"{name}/alone{i}_{var}"] = alone[var].values
    return out


def bias_case(case: dict) -> dict[str, np.ndarray]:
    """The bias estimate with its pairs on the GPU (``bias.estimate(..., backend="cuda")``), in
    chunks of ``chunk_pairs``: each statistic's bias and coarse value with their errors, the
    pairs' path-steps and decorrelation, saved as "<name>/<what>_<statistic>"."""
    from stochpend import bias
    from stochpend.model.settings import SimulationConfig

    name = case["name"]
    est = bias.estimate(SimulationConfig.build(**case["config"]), case["pairs"],
                        chunk_pairs=case["chunk_pairs"], backend="cuda")
    out = {f"{name}/path_steps": np.array(est.path_steps),
           f"{name}/decorrelation": est.decorrelation}
    for stat, (value, se) in est.bias.items():
        out[f"{name}/bias_{stat}"] = value
        out[f"{name}/bias_se_{stat}"] = se
        out[f"{name}/coarse_{stat}"] = est.coarse[stat][0]
    return out


def rng_case(case: dict) -> dict[str, np.ndarray]:
    """Philox words and both normal pairs of draws ``(path, n)`` computed in a CUDA kernel (the
    paths and counters of :func:`rng_inputs`, whose high words are in use)."""
    from stochpend.numerics import rng
    from stochpend.numerics.mathlib import LIBM

    name = case["name"]
    paths, counters = rng_inputs(case["n"])
    key0, key1 = rng.seed_to_key(case["seed"])
    normals32 = rng.normals_with(LIBM, np.float32)

    @cuda.jit
    def kernel(paths, counters, words, z64, z32):
        i = cuda.grid(1)
        if i >= paths.shape[0]:
            return
        w0, w1, w2, w3 = rng.draw_words(key0, key1, paths[i], counters[i])
        words[i, 0] = w0
        words[i, 1] = w1
        words[i, 2] = w2
        words[i, 3] = w3
        z64[i, 0], z64[i, 1] = rng.draw_normals(key0, key1, paths[i], counters[i])
        z32[i, 0], z32[i, 1] = normals32(key0, key1, paths[i], counters[i])

    words = np.zeros((paths.size, 4), dtype=np.uint64)
    z64 = np.zeros((paths.size, 2), dtype=np.float64)
    z32 = np.zeros((paths.size, 2), dtype=np.float32)
    kernel[(paths.size + 31) // 32, 32](paths, counters, words, z64, z32)
    return {f"{name}/words": words, f"{name}/z64": z64, f"{name}/z32": z32}


def rng_inputs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Global path indices and draw counters that use both 32-bit words of each."""
    i = np.arange(n, dtype=np.uint64)
    paths = i * np.uint64(2654435761) + (i % np.uint64(3)) * np.uint64(2**32)
    counters = i * np.uint64(40503) + (i % np.uint64(2)) * np.uint64(2**33 + 5)
    return paths, counters


def precision_pair_case(case: dict) -> dict[str, np.ndarray]:
    """The same configuration run in float64 and in float32 with *different* seeds (independent
    ensembles, for a two-sample test): the sums of each."""
    from stochpend.engine import runner
    from stochpend.model.settings import SimulationConfig

    name = case["name"]
    out: dict[str, np.ndarray] = {}
    work = 0
    for precision, seed in (("float64", case["seeds"][0]), ("float32", case["seeds"][1])):
        config = SimulationConfig.build(**{**case["config"], "seed": seed})
        sums, path_steps = runner.run_batches(config, 0, config.n_batches, backend="cuda", precision=precision)
        out[f"{name}/{precision}_sums"] = sums.sums
        work += path_steps
    out[f"{name}/work"] = np.array(work)
    return out


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
