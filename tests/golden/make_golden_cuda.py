"""Statistics of tiny runs on the CUDA backend in Numba's CUDA simulator, saved as a golden fixture.

Usage: ``NUMBA_ENABLE_CUDASIM=1 python tests/golden/make_golden_cuda.py OUT.npz``

tests/golden/cudasim.npz was made by this script at the commit that added it (issue 37: the
output times and the skewness no longer use numpy's CPU-dispatched power loop), on a 2-core AMD
EPYC (Zen 4, AVX-512), numba 0.68.1, numpy 2.4.6; the same file came out with numpy held to AVX2
(``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512_ICL AVX512_SPR"``). It replaced
cudasim_5319e81.npz (made at 5319e81), from which only the skewness and its error differ:

    NUMBA_ENABLE_CUDASIM=1 .venv/bin/python tests/golden/make_golden_cuda.py tests/golden/cudasim.npz

tests/statistical/test_golden_cuda.py runs it at the current commit and compares every array
bit for bit. The simulator runs each GPU thread as Python (about 1e4 path-steps a second), so
the runs are tiny: every built-in noise, the quartic with position coupling, the harmonic
oscillator, a fixed step, and that fixed step in float32. Saved per case: every variable of
``simulate(..., backend="cuda", bias_paths=0)`` but the bias estimate's (issue 19 changed them
on purpose), the output times, and the case's parameters (so an edited case fails the test
rather than being compared with another case's numbers).
"""

from __future__ import annotations

import json
import os
import sys

import numpy as np

_SMALL = dict(paths=64, t_max=2.0, n_times=3, n_batches=4)

#: name -> (simulate keywords, precision)
CASES: dict[str, tuple[dict, str]] = {
    "ou": (dict(noise="ou", D=1.0, tau=1.0, omega=1.0, seed=11, **_SMALL), "float64"),
    "white": (dict(noise="white", D=1.0, omega=1.0, seed=12, **_SMALL), "float64"),
    "dichotomous": (dict(noise="dichotomous", D=1.0, tau=1.0, omega=1.0, seed=13, **_SMALL), "float64"),
    "harmonic_noise": (dict(noise="harmonic", D=1.0, tau=1.0, omega_noise=1.5, omega=1.0, seed=14, **_SMALL),
                       "float64"),
    "quartic_position": (dict(potential="power", power_n=2, coupling="position", noise="ou", D=1.0, tau=1.0,
                              omega=1.0, seed=15, **_SMALL), "float64"),
    "harmonic_osc": (dict(potential="harmonic", noise="white", D=1.0, omega=1.0, seed=16, **_SMALL), "float64"),
    "fixed_step": (dict(noise="ou", D=1.0, tau=1.0, omega=1.0, seed=17, step_c=0.0, h_max=0.05, **_SMALL),
                   "float64"),
    "fixed_step_f32": (dict(noise="ou", D=1.0, tau=1.0, omega=1.0, seed=17, step_c=0.0, h_max=0.05, **_SMALL),
                       "float32"),
}


def main(out_path: str) -> None:
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        raise SystemExit("set NUMBA_ENABLE_CUDASIM=1 before running this script")
    import stochpend

    out: dict[str, np.ndarray] = {}
    for name, (kwargs, precision) in CASES.items():
        ds = stochpend.simulate(**kwargs, backend="cuda", precision=precision, bias_paths=0)
        if ds.attrs["backend"] != "cuda":  # a silent fallback to the CPU would make the fixture a CPU one
            raise SystemExit(f"{name}: ran on {ds.attrs['backend']!r}, not the CUDA simulator")
        out[f"{name}/case"] = np.array(json.dumps([kwargs, precision], sort_keys=True))
        out[f"{name}/time"] = ds["time"].values
        for var in ds.data_vars:
            if "bias" not in str(var):
                out[f"{name}/{var}"] = ds[var].values
    np.savez_compressed(out_path, **out)


if __name__ == "__main__":
    main(sys.argv[1])
