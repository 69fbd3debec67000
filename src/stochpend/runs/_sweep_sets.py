"""The parameter sets of a sweep result, read from the file alone: ``stochpend show`` of a sweep
needs neither Numba nor the sweep machinery (:mod:`stochpend.sweep`, which imports the kernels)."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from typing import Any


def flat_sets(ds: Any) -> Sequence[dict[str, Any]]:
    """The parameter values of each set of a sweep result, in row-major order (for tables)."""
    dims = [d for d in ds.attrs.get("sweep_dims", "").split(",") if d]
    swept = [k for k in ds.attrs.get("sweep_swept", "").split(",") if k]
    out = []
    for index in itertools.product(*(range(ds.sizes[d]) for d in dims)):
        sel = dict(zip(dims, index, strict=True))
        row = {k: ds[k].isel({d: i for d, i in sel.items() if d in ds[k].dims}).item() for k in swept}
        out.append({"index": sel, "params": row})
    return out
