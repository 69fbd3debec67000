"""benchmarks/path_start.py runs and reports what it says (a smoke test of the script, not a
measurement): at tiny sizes its rows, its fit and its three pieces are printed. No timing is
asserted: at these sizes the machine's noise decides any comparison (a benchmark's claims are
its runs', benchmarks/RESULTS_ACCURACY.md)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from benchmarks import path_start  # noqa: E402


def test_the_script_prints_its_rows_fit_and_pieces(capsys):
    path_start.main(["--paths", "20000", "--steps", "1,50", "--repeats", "1", "--chunks", "1",
                     "--chunk-paths", "20000"])
    out = capsys.readouterr().out
    rows = re.findall(r"^\| (\d+) \| ([0-9.]+) \|$", out, flags=re.M)
    assert [int(s) for s, _ in rows] == [1, 50]
    assert re.search(r"^fit: -?[0-9.]+ ns a step, -?[0-9.]+ ns a path's start and statistics", out, flags=re.M), out
    pieces = dict(re.findall(r"(start|advance|accumulate) ([0-9.]+)", out))
    assert set(pieces) == {"start", "advance", "accumulate"} and all(float(v) > 0 for v in pieces.values())
