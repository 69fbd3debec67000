"""The soak run (test_soak.py): a checkpointed run of many small chunks, stopped by SIGTERM.

Usage: ``python _soak_run.py CHECKPOINT OUT DURATION_S``. The run is sized to last several
times DURATION_S on one thread, so that it is still running when the test stops it; it saves
a checkpoint every :data:`EVERY_S` seconds and exits with code 143 on SIGTERM (after a last
checkpoint), as ``stochpend simulate --checkpoint`` does.
"""

from __future__ import annotations

import sys

#: Paths per chunk (one batch): a chunk takes a fraction of a second.
CHUNK_PATHS = 100
#: Seconds between two checkpoints.
EVERY_S = 2.0
#: Batches (= chunks) per second of soak: ~20 chunks of ~0.25 s a second of soak, i.e. ~5x
#: more work than the soak lasts on one thread.
CHUNKS_PER_SOAK_SECOND = 20


def config_for(duration_s: float):
    from stochpend.model.settings import SimulationConfig

    n_batches = max(200, int(CHUNKS_PER_SOAK_SECOND * duration_s))
    return SimulationConfig.build(noise="ou", D=1.0, tau=1.0, omega=1.0, paths=CHUNK_PATHS * n_batches,
                                  t_max=1000.0, times=[250.0, 500.0, 750.0, 1000.0], seed=20040401,
                                  n_batches=n_batches)


def main(checkpoint_path: str, out: str, duration_s: float) -> None:
    from stochpend.runs.checkpoint import CheckpointInterrupt, run_checkpointed

    try:
        run_checkpointed(config_for(duration_s), checkpoint_path=checkpoint_path, every_s=EVERY_S, out=out,
                         threads=1, chunk_paths=CHUNK_PATHS)
    except CheckpointInterrupt as exc:
        sys.exit(exc.exit_code)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]))
