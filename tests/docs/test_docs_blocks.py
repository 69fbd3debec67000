"""Every code block of docs/*.md is exercised, under a policy stated per block (issue 20).

Policies (``POLICY`` below names one for every block; a new block without one fails
``test_every_block_has_a_policy``):

* ``cli-parse`` -- command lines (a ``$``/``host$`` prompt and output lines are stripped): the
  command and every option the line names must exist (``stochpend CMD --help`` lists them);
  nothing runs. For lines with placeholders (``DIR``, ``...``), a GPU, 10^6+ paths, a cluster
  or a crash to resume from.
* ``bench-parse`` -- ``python benchmarks/X.py --opt``: the script's ``--help`` lists each option.
* ``python-scaled`` -- run as written with the ensemble scaled down (``REPLACE``), in a
  temporary directory.
* ``python-parse`` -- parsed, and every ``stochpend`` name it imports or uses exists (for a
  GPU, a SLURM cluster, 10^7 paths).
* ``toml-run`` -- a sweep file: validated whole, then run scaled down (paths, t_max) in this
  process; the result has the sets the text says.
* ``errors-as-shown`` -- the error lines a document shows are what the tool prints for the
  files that cause them (the text before "..." must match).
* ``transcript`` -- a shell session (``^C``, ``echo $?``): the interrupt and its exit code are
  run for real in tests/system/test_faults.py; here its command lines are parsed.
"""

from __future__ import annotations

import ast
import importlib
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from typer.testing import CliRunner

ROOT = Path(__file__).resolve().parents[2]
DOCS = sorted((ROOT / "docs").glob("*.md"))

#: (file name, block index in that file) -> policy
POLICY = {
    ("gpu.md", 0): "cli-parse",
    ("gpu.md", 1): "python-parse",
    ("gpu.md", 2): "bench-parse",
    ("gpu.md", 3): "bench-parse",
    ("gpu.md", 4): "cli-parse",
    ("models.md", 0): "python-scaled",
    ("models.md", 1): "python-parse",
    ("models.md", 2): "python-scaled",
    ("models.md", 3): "python-scaled",
    ("family.md", 0): "python-scaled",
    ("family.md", 1): "python-scaled",
    ("family.md", 2): "python-scaled",
    ("reproduction.md", 0): "cli-parse",
    ("scale-out.md", 0): "cli-parse",
    ("scale-out.md", 1): "toml-run",
    ("scale-out.md", 2): "toml-run",
    ("scale-out.md", 3): "errors-as-shown",
    ("scale-out.md", 4): "python-scaled",
    ("scale-out.md", 5): "cli-parse",
    ("scale-out.md", 6): "python-parse",
    ("scale-out.md", 7): "transcript",
}

#: Scaling of the blocks that run: (old, new) text replacements.
REPLACE = {
    ("models.md", 0): [("paths=4000", "paths=200"), ("t_max=100.0", "t_max=5.0")],
    ("models.md", 2): [("paths=4000", "paths=200"), ("t_max=100.0", "t_max=5.0")],
    ("models.md", 3): [("paths=4000", "paths=200"), ("t_max=100.0", "t_max=5.0"), ("window=(0.0, 100.0)", "window=(0.0, 5.0)")],
    ("family.md", 0): [("paths=40_000", "paths=400"), ("t_max=40.0, times=(20.0, 40.0)", "t_max=4.0, times=(2.0, 4.0)")],
    ("family.md", 1): [("paths=4000", "paths=400")],
    ("family.md", 2): [("paths=40_000", "paths=400"), ("t_max=40.0, times=(20.0, 40.0)", "t_max=4.0, times=(2.0, 4.0)")],
    # fig2.toml is the first TOML block, scaled; 'local' runs a real two-process LocalCluster;
    # the CUDA line is parsed only (a GPU, or the simulator at 1e-4 of the speed).
    ("scale-out.md", 4): [("workers=8", "workers=2"),
                          ('ds = sweep("fig2.toml", backend="cuda", precision="float32")',
                           'assert callable(sweep)')],
}


def _blocks(path: Path) -> list[tuple[str, str]]:
    return re.findall(r"^```(\w*)\n(.*?)^```", path.read_text(encoding="utf-8"), flags=re.S | re.M)


def _cases() -> list[tuple[str, int, str, str]]:
    return [(p.name, i, lang, code) for p in DOCS for i, (lang, code) in enumerate(_blocks(p))]


def test_every_block_has_a_policy():
    found = {(name, i) for name, i, _, _ in _cases()}
    assert found == set(POLICY), (sorted(found - set(POLICY)), sorted(set(POLICY) - found))


def _command_lines(code: str) -> list[list[str]]:
    """The stochpend command lines of a block, as argument lists (prompts, comments, output
    lines and the alternatives' brackets and bars removed)."""
    lines = []
    for raw in code.splitlines():
        line = re.sub(r"^\s*[\w.-]*\$\s*", "", raw).split("  #")[0].strip()
        if not line.startswith("stochpend "):
            continue
        words = shlex.split(line.replace("[", " ").replace("]", " ").replace("|", " "))
        lines.append(words[1:])
    return lines


def _check_options_exist(args: list[str]) -> None:
    from stochpend.cli import app

    command = args[0] if args and not args[0].startswith("-") else None
    result = CliRunner().invoke(app, ([command] if command else []) + ["--help"])
    assert result.exit_code == 0, (args, result.output)
    helptext = " ".join(result.output.split())
    for option in (w.split("=")[0] for w in args if w.startswith("--")):
        assert option in helptext, (args, option)


def _policy_cases(policy: str) -> list[tuple[str, int, str]]:
    return [(name, i, code) for name, i, _, code in _cases() if POLICY.get((name, i)) == policy]


@pytest.mark.parametrize("name,index,code", _policy_cases("cli-parse") + _policy_cases("transcript"),
                         ids=lambda v: str(v)[:20])
def test_command_lines_name_existing_commands_and_options(name, index, code):
    lines = _command_lines(code)
    assert lines, (name, index)
    for args in lines:
        _check_options_exist(args)


@pytest.mark.parametrize("name,index,code", _policy_cases("bench-parse"), ids=lambda v: str(v)[:20])
def test_benchmark_lines_name_existing_options(name, index, code):
    for raw in code.splitlines():
        words = shlex.split(raw.split("  #")[0])
        assert words[0] == "python" and words[1].startswith("benchmarks/"), raw
        script = ROOT / words[1]
        assert script.is_file(), raw
        helptext = subprocess.run([sys.executable, str(script), "--help"], capture_output=True, text=True,
                                  cwd=ROOT, timeout=120).stdout
        for option in (w for w in words[2:] if w.startswith("--")):
            assert option in helptext, (raw, option)


def _stochpend_names(tree: ast.AST) -> list[tuple[str, str]]:
    """(module, name) pairs a block imports from stochpend or reads off an imported module."""
    pairs, aliases = [], {}
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("stochpend"):
            for a in node.names:
                pairs.append((node.module, a.name))
                aliases[a.asname or a.name] = f"{node.module}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name.startswith("stochpend"):
                    aliases[a.asname or a.name] = a.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases:
            pairs.append((aliases[node.value.id], node.attr))
    return pairs


@pytest.mark.parametrize("name,index,code", _policy_cases("python-parse"), ids=lambda v: str(v)[:20])
def test_python_blocks_that_cannot_run_here_name_what_exists(name, index, code):
    tree = ast.parse(code)
    pairs = _stochpend_names(tree)
    assert pairs or "stochpend" not in code, (name, index)
    for module, attr in pairs:
        try:
            owner = importlib.import_module(module)
        except ModuleNotFoundError:  # module.attr where module is itself a name of a package
            parent, _, child = module.rpartition(".")
            owner = getattr(importlib.import_module(parent), child)
        if not hasattr(owner, attr):
            importlib.import_module(f"{module}.{attr}")  # a submodule


@pytest.fixture
def fig2_toml(tmp_path: Path) -> Path:
    """scale-out.md's fig2.toml, scaled down: 9 sets of 24 paths to t = 2."""
    code = _blocks(ROOT / "docs" / "scale-out.md")[1][1]
    scaled = code.replace("paths = 2000", "paths = 24").replace("t_max = 500.0", "t_max = 2.0") \
                 .replace("n_times = 40", "n_times = 3")
    path = tmp_path / "fig2.toml"
    path.write_text(scaled, encoding="utf-8")
    return path


@pytest.mark.parametrize("index", [i for (n, i), p in POLICY.items() if n == "scale-out.md" and p == "toml-run"])
def test_sweep_files_of_the_docs_run_scaled(tmp_path, index):
    from stochpend.sweep import load_spec, sweep

    code = _blocks(ROOT / "docs" / "scale-out.md")[index][1]
    scaled = re.sub(r"paths = \d+", "paths = 24", code)
    scaled = re.sub(r"t_max = [\d.]+", "t_max = 2.0", scaled)
    scaled = re.sub(r"n_times = \d+", "n_times = 3", scaled)
    if "n_times" not in scaled:
        scaled = scaled.replace("[base]\n", "[base]\nn_times = 3\n", 1)
    path = tmp_path / "s.toml"
    path.write_text(scaled, encoding="utf-8")
    spec = load_spec(path)
    ds = sweep(path)
    expected = 9 if "[grid]" in code else code.count("[[case]]")
    assert spec.n_sets == expected and ds["mean_E"].size == expected * ds.sizes["time"]
    assert bool(ds["mean_E"].notnull().all())


def test_error_lines_shown_in_the_docs_are_what_the_tool_prints(fig2_toml):
    from stochpend.cli import app

    shown = _blocks(ROOT / "docs" / "scale-out.md")[3][1].splitlines()
    text = fig2_toml.read_text(encoding="utf-8")
    edits = [text.replace("tau = [", "taux = ["), text.replace("D = [1, 10, 100]", "D = [1, -10, 100]"),
             text.replace("seed = 1", "seed = [1, 2]")]
    for line, edited in zip(shown, edits, strict=True):
        fig2_toml.write_text(edited, encoding="utf-8")
        result = CliRunner().invoke(app, ["sweep", str(fig2_toml), "--out", str(fig2_toml.with_suffix(".nc"))])
        assert result.exit_code == 2, result.output
        printed = " ".join(result.output.split())
        assert printed.startswith(line.split("...")[0].rstrip(" ,")), (line, printed)


def test_python_blocks_run_scaled(tmp_path, monkeypatch, fig2_toml):
    """models.md's double well; scale-out.md's sweep calls (fig2.toml scaled, a real
    two-process LocalCluster)."""
    monkeypatch.chdir(fig2_toml.parent)
    for name, index, code in _policy_cases("python-scaled"):
        for old, new in REPLACE.get((name, index), []):
            assert old in code, (name, index, old)
            code = code.replace(old, new)
        namespace: dict = {}
        exec(compile(code, f"docs/{name}", "exec"), namespace)
        if name == "scale-out.md":
            ds = namespace["ds"]
            assert ds["mean_E"].size == 9 * ds.sizes["time"]
