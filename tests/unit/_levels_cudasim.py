"""The coupled levels' cases (test_levels.py), and their run in Numba's CUDA simulator.

Usage: ``NUMBA_ENABLE_CUDASIM=1 python _levels_cudasim.py OUT.npz``: every case of :data:`CASES`
at every number of members of :data:`LEVELS`, advanced by the CUDA backend's ``levels_kernel``
(one path per thread) from :func:`initial_state` to each time of :data:`TIMES` in launches of
:data:`MAX_STEPS` steps; every array of the state saved as ``"<case>/<levels>/<position>"``.
The simulator must be switched on before Numba is imported, so it runs in its own process.
"""

from __future__ import annotations

import functools
import os
import sys
from typing import Any

import numpy as np

#: Each case a configuration (``SimulationConfig.build``): one path's KernelSpec with adaptive steps
#: (no family terms), the family's time-dependent terms with the additive white noise and fixed
#: steps, the additive channel with the OU noise (additive_tau > 0) and with a harmonic noise,
#: adaptive steps.
CASES: dict[str, dict[str, Any]] = {
    "ou": dict(noise="ou", D=1.0, tau=1.0, omega=1.0, h_max=0.1, step_c=0.25),
    "family": dict(noise="white", D=0.5, omega=1.0, h_max=0.1, step_c=0.0,
                   dyn_params=dict(gamma=0.5, additive_D=0.4, torque=0.1, drive_amplitude=0.3,
                                   drive_frequency=1.3, parametric_amplitude=0.2)),
    "additive_ou": dict(noise="white", D=0.3, omega=1.0, h_max=0.1, step_c=0.25,
                        dyn_params=dict(gamma=0.5, additive_D=0.4, additive_tau=1.0)),
    "channel": dict(noise="white", D=0.5, omega=1.0, h_max=0.1, step_c=0.25, additive_noise="harmonic",
                    dyn_params=dict(gamma=0.3, additive_D=0.4, additive_tau=0.5)),
}
LEVELS = (2, 3, 4)
#: Members carrying per-path accumulators (:func:`accumulators`), each its own.
TRACKED_LEVELS = (2, 3)
#: Output times (the second resumes where the first landed) and the steps of one call.
TIMES = (0.75, 2.0)
MAX_STEPS = 7
PATHS = 6
SEED = 2024
#: The first global path, as the bias estimate's pairs have it (a uint64 from 2**63).
PATH0 = np.uint64(2**63 + 17)


def config(name: str):
    from stochpend.model.settings import SimulationConfig

    return SimulationConfig.build(**CASES[name], paths=64, t_max=TIMES[-1], n_times=2, seed=SEED)


def initial_state(cfg, levels: int, n: int = PATHS) -> tuple[np.ndarray, ...]:
    """The state of ``levels`` members (``integrator.level_positions``) at t = 0: every member
    at the same spread of (x, Omega), the noises at 0, then the additive channel's arrays."""
    from stochpend.model import dynamics

    x = np.linspace(-2.5, 2.5, n)
    Omega = np.linspace(-1.0, 1.5, n)
    members = [a.copy() for _ in range(levels) for a in (x, Omega)]
    zeros = [np.zeros(n) for _ in range(4)]  # xi, xi_aux, t, t_comp
    extra = [np.zeros(n) for _ in dynamics.additive_arrays(cfg)]
    return (*members, *zeros, np.zeros(n, dtype=np.uint64), np.zeros(n, dtype=np.uint8), *extra)


@functools.cache
def accumulators() -> tuple[Any, ...]:
    """Two time averages (the whole run; a window from the first output time) of a function of
    the state, the noise and the time, and a running sum (the noise's integral): what each
    member tracks in the tracked cases. The same objects on every call: the CPU's kernel
    builders are cached on them (a user's accumulators compile in memory, once per tuple), so
    the tests of one process that track them share each (KernelSpec, levels) kernel instead of
    compiling it again (eight kernels, about 48 s of a suite's CPU, measured)."""
    from stochpend.observables import RunningSum, TimeAverage

    def f(x, Omega, xi, t):
        return Omega * Omega + xi * x + 0.25 * t

    return (TimeAverage("lv_all", f, window=(0.0, TIMES[-1])),
            TimeAverage("lv_late", f, window=(TIMES[0], TIMES[-1])),
            RunningSum("lv_int", lambda x0, O0, xi0, x1, O1, xi1, t0, t1: 0.5 * (t1 - t0) * (xi0 + xi1)))


def tracked_state(cfg, levels: int, accs: tuple[Any, ...]) -> tuple[np.ndarray, ...]:
    """:func:`initial_state` with every member's accumulators' slots from their start, after
    ``status`` (``layout.state_arrays(levels, tracked=True)``)."""
    from stochpend.model import observables

    start = initial_state(cfg, levels)
    at = 2 * levels + 6  # after the members and xi, xi_aux, t, t_comp, k, status
    return (*start[:at], np.tile(observables.track_initial(accs), (levels, PATHS)), *start[at:])


def main(out_path: str) -> None:
    if os.environ.get("NUMBA_ENABLE_CUDASIM") != "1":
        raise SystemExit("set NUMBA_ENABLE_CUDASIM=1 before running this script")
    from numba import cuda

    from stochpend.engine import cuda as backend
    from stochpend.engine import integrator
    from stochpend.numerics import rng

    out: dict[str, np.ndarray] = {}
    accs = accumulators()
    for name in CASES:
        cfg = config(name)
        spec = integrator.KernelSpec.of(cfg)
        key0, key1 = rng.seed_to_key(cfg.seed)
        runs = [(str(levels), backend.levels_kernel(spec, levels), initial_state(cfg, levels)) for levels in LEVELS]
        runs += [(f"tracked{levels}", backend.tracked_levels_kernel(spec, accs, levels),
                  tracked_state(cfg, levels, accs)) for levels in TRACKED_LEVELS]
        for levels, kernel, start in runs:
            state = tuple(cuda.to_device(a) for a in start)
            flag = cuda.to_device(np.zeros(1, dtype=np.int32))
            for t_target in TIMES:
                while True:
                    flag.copy_to_device(np.zeros(1, dtype=np.int32))
                    kernel[1, PATHS](state, t_target, MAX_STEPS, key0, key1, PATH0,
                                     spec.noise.record(cfg), integrator.step_record(cfg), flag)
                    if int(flag.copy_to_host()[0]) == 0:
                        break
            for j, a in enumerate(state):
                out[f"{name}/{levels}/{j}"] = a.copy_to_host()
    np.savez(out_path, **out)


if __name__ == "__main__":
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
    main(sys.argv[1])
