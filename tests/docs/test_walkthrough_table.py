"""tests/docs/WALKTHROUGH.md maps every check of the new-user walk-through (issue 36: R1-R24,
A1-I4, N1-N23, M1-M26) and every defect of hostile-turn4.md to the tests that hold it: each id
has a row, and every test the table names exists, so that the table cannot point at a test
renamed or removed."""

from __future__ import annotations

import ast
import re
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]
TABLE = (TESTS / "docs" / "WALKTHROUGH.md").read_text()

IDS = ([f"R{i}" for i in range(1, 25)] + ["A1", "A2", "B1", "B2", "C1", "C2", "C3", "C4", "C5", "C6", "D1", "D2",
       "D3", "E1", "F1", "F2", "G1", "G2", "G3", "G4", "G5", "H1", "H2", "H3", "H4", "I1", "I2", "I3", "I4"]
       + [f"N{i}" for i in range(1, 24)] + [f"M{i}" for i in range(1, 27)])

#: The cases hostile-turn4.md marked DEFECT or SECURITY.
HOSTILE = ["B01", "F09b", "S28", "NEW03", "NEW06", "NEW07", "NEW08", "NEW12", "NEW20", "NEW23", "CFG5", "NEW24",
           "NEW25", "NC09", "NEW27", "NEW30c", "NEW31a", "NEW32", "NEW35", "NEW40", "NEW41", "NEW65", "NEW50", "NEW60"]


def _row_ids() -> set[str]:
    ids: set[str] = set()
    for line in TABLE.splitlines():
        if not line.startswith("| ") or line.startswith("| id") or line.startswith("| case"):
            continue
        cell = line.split("|")[1].strip()
        for part in cell.split(","):
            part = part.strip()
            m = re.fullmatch(r"([A-Z])(\d+)[–-]([A-Z])(\d+)", part)
            if m and m.group(1) == m.group(3):
                ids.update(f"{m.group(1)}{k}" for k in range(int(m.group(2)), int(m.group(4)) + 1))
            else:
                ids.add(part.split(" ")[0])
    return ids


def test_every_check_has_a_row():
    assert [i for i in IDS if i not in _row_ids()] == []
    assert len(IDS) == 102


def test_every_hostile_defect_has_a_row_saying_how_it_fails_on_c9b0e83():
    rows = {line.split("|")[1].strip().split(" ")[0]: line for line in TABLE.split("## hostile-turn4.md")[1].splitlines()
            if line.startswith("| ") and not line.startswith("| case")}
    assert sorted(rows) == sorted(HOSTILE)
    assert all(line.rstrip(" |").split("|")[-1].strip().startswith("fails") for line in rows.values())


def test_every_test_the_table_names_exists():
    named = re.findall(r"`([a-z_]+/test_\w+\.py)((?:::\w+)?)`", TABLE)
    # '`::name`' after a file: the same file as the last one named in that cell
    assert len(named) > 80
    missing = []
    for line in TABLE.splitlines():
        current = None
        for path, name in re.findall(r"`(?:([a-z_]+/test_\w+\.py))?(?:::(\w+))?`", line):
            if path:
                current = TESTS / path
                if not current.exists():
                    missing.append(path)
                    continue
            if name and current is not None:
                tree = ast.parse(current.read_text())
                names = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
                if name not in names:
                    missing.append(f"{current.relative_to(TESTS)}::{name}")
    assert missing == []
