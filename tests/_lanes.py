"""The SIMD lanes against the one-path loops, for the tests of the family's terms."""

from __future__ import annotations

import numpy as np

import stochpend
from stochpend import bias
from stochpend.engine import cpu


def assert_lanes_equal_one_path(run: dict, config, monkeypatch, *, finite_bias: bool = True) -> None:
    """``simulate(**run)`` in the SIMD lanes equals the one-path loop of the same fast-math KernelSpec,
    bit for bit: the run with the displacement (an accumulator each lane carries) equals the
    run without it in every other number, and the one-path loop with it (``cpu.tracked_kernel``
    replaced by ``cpu.tracked_path_kernel`` through ``monkeypatch``) in every number. So do
    the bias pairs' lanes against the one-pair loop (``bias.estimate`` of ``config``, the same
    run's configuration, with ``cpu.levels_kernel`` replaced by the one-pair kernel).
    ``finite_bias``: every pair estimate is finite too."""
    lanes = stochpend.simulate(**run, bias_paths=64)
    tracked = stochpend.simulate(**run, bias_paths=64, observables=("displacement",))
    with monkeypatch.context() as patch:
        patch.setattr(cpu, "tracked_kernel", cpu.tracked_path_kernel)
        one_path = stochpend.simulate(**run, bias_paths=64, observables=("displacement",))
    assert lanes.attrs["path_steps"] == tracked.attrs["path_steps"] == one_path.attrs["path_steps"]
    for name in lanes.data_vars:
        assert np.array_equal(lanes[name].values, tracked[name].values, equal_nan=True), name
    for name in tracked.data_vars:
        assert np.array_equal(tracked[name].values, one_path[name].values, equal_nan=True), name
    assert np.all(np.isfinite(tracked["mean_displacement"].values))
    a = bias.estimate(config, 64)
    asked = []
    monkeypatch.setattr(cpu, "levels_kernel", lambda spec, levels: asked.append(levels) or cpu._pair_path_kernel(spec))
    b = bias.estimate(config, 64)
    assert asked == [2] and b.path_steps == a.path_steps  # the pairs ran in the one-pair loop
    for name in a.bias:
        assert np.array_equal(a.bias[name][0], b.bias[name][0], equal_nan=True), name
        if finite_bias:
            assert np.all(np.isfinite(a.bias[name][0])), name
