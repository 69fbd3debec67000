"""What a chunk of paths is made of, for every engine and for checkpoints: the arrays an engine
holds (:data:`CHUNK_ARRAYS`) and the dtype of each per-path one (:func:`path_dtypes`), the one
allocation table that the engines allocate from and a checkpoint is checked against; and the
kernels' state tuple, by name (:func:`state_arrays`): the engines build it from these names
and the kernels read it at the positions generated from them (:func:`state_positions`).

Below the engines and :mod:`stochpend.engine.runner`, which both import it (the runner drives the
engines; an engine never imports the runner).
"""

from __future__ import annotations

import numpy as np

__all__ = ["AFTER_MEMBERS", "CHUNK_ARRAYS", "member_arrays", "path_dtypes", "state_arrays", "state_positions"]

#: The per-chunk arrays of a RunState (what an engine holds). ``tracks``: the per-path
#: accumulators' slots, (n_slots, n_paths) float64 (``stochpend.observables``; none: empty).
#: ``xi_a``: the additive Ornstein-Uhlenbeck noise's value per path (``additive_tau`` > 0,
#: ``stochpend.model.dynamics``; any other run: empty); with the generic channel (``additive_noise``),
#: its noise's value ``xi_a`` and second variable ``aux_a`` (any other run: empty).
CHUNK_ARRAYS = ("x", "Omega", "xi", "t", "k", "status", "t_comp", "xi_aux", "chunk_sums",
                "chunk_hist", "tracks", "xi_a", "aux_a")


def path_dtypes(backend: str, precision: str) -> dict[str, np.dtype]:
    """The dtype of each per-path array of a chunk, as the ``backend``'s engine holds it (and a
    checkpoint must store it): the state (x, Omega, xi) in the run's precision (float32 exists
    on the CUDA backend only); times and the noise's second variable in float64; the step
    counter ``k`` uint64; ``status`` uint8; the additive channel's ``xi_a`` and ``aux_a`` (only
    for a run with it: see :data:`CHUNK_ARRAYS`) in float64."""
    real = np.dtype(np.float32 if backend == "cuda" and precision == "float32" else np.float64)
    f64 = np.dtype(np.float64)
    return {"x": real, "Omega": real, "xi": real, "xi_aux": f64, "t": f64, "t_comp": f64,
            "k": np.dtype(np.uint64), "status": np.dtype(np.uint8), "xi_a": f64,
            "aux_a": f64}


#: The kernels' per-path state after the members' (x, Omega) pairs, in order: the parametric
#: noise (xi, its second variable xi_aux), the clock (t, t_comp: its compensation), the draw
#: counter k and the status.
AFTER_MEMBERS = ("xi", "xi_aux", "t", "t_comp", "k", "status")


def member_arrays(levels: int) -> tuple[str, ...]:
    """The names of the coupled members' (x, Omega) arrays: member 0 (the coarsest, step h; a
    run's only member) ``x, Omega``, member m (step h/2**m) ``x<m>, Omega<m>``."""
    return ("x", "Omega", *(f"{name}{m}" for m in range(1, levels) for name in ("x", "Omega")))


def state_arrays(levels: int = 1, tracked: bool = False, channel: bool = False) -> tuple[str, ...]:
    """The kernels' state tuple, by name, in the order the engines pass it: the ``levels``
    members' arrays (:func:`member_arrays`), :data:`AFTER_MEMBERS`, then the per-path
    accumulators' slots ``tracks`` (``tracked``: a run with accumulators) and the additive
    channel's ``xi_a, aux_a`` (``channel``: a run with a coloured additive noise)."""
    return (*member_arrays(levels), *AFTER_MEMBERS, *(("tracks",) if tracked else ()),
            *(("xi_a", "aux_a") if channel else ()))


def state_positions(levels: int = 1, tracked: bool = False, channel: bool = False) -> dict[str, int]:
    """Where the kernels read each array of :func:`state_arrays` in the state tuple."""
    return {name: i for i, name in enumerate(state_arrays(levels, tracked, channel))}
