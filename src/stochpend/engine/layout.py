"""What a chunk of paths is made of, for every engine and for checkpoints: the arrays an engine
holds (:data:`CHUNK_ARRAYS`) and the dtype of each per-path one (:func:`path_dtypes`), the one
allocation table that the engines allocate from and a checkpoint is checked against.

Below the engines and :mod:`stochpend.engine.runner`, which both import it (the runner drives the
engines; an engine never imports the runner).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CHUNK_ARRAYS", "path_dtypes"]

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
