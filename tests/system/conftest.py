"""tests/system: the program in real processes -- killed by signals, on a full disk, hostile
files, a Dask cluster, a headless browser, gcc-built references, fresh kernel caches. Every test
here carries the ``system`` marker (``pytest -m system`` runs them alone, ``-m "not system"``
the in-process tests); they are part of the default suite."""

from __future__ import annotations

from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if HERE in Path(str(item.path)).resolve().parents:
            item.add_marker(pytest.mark.system)
