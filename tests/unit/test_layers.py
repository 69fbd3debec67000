"""The package's import graph has layers and no cycles (issue 33, item 7).

Every ``import`` in src/stochpend counts: at module level and inside functions (the lazy
imports that keep the light commands fast), everything but ``if TYPE_CHECKING:`` blocks. A
module sits in one layer of :data:`LAYERS`, from the foundations up to the command line; an
import may reach its own layer or one below, never one above, and the graph has no cycle.
A new module must be placed here: the test fails on an unplaced one.
"""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[2] / "src" / "stochpend"

#: The layers, lowest first; a module may import from its own layer and those below.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundations: numbers, random streams, files, text, the paper's labels", (
        "_version", "_hostmath", "_notation", "_terminal", "_toml", "_warnings", "_docs",
        "_xarray_nodask", "_files", "_sources", "io", "paper", "mathlib", "fastmath", "rng",
        "parameters", "progress", "_cputarget", "_jitcache", "_jitable", "_calibration")),
    ("model pieces: noises, oscillators, the family's terms, observables, settings", (
        "noises", "noises.base", "noises.white", "noises.ou", "noises.dichotomous",
        "noises.harmonic", "oscillators", "oscillators.base", "oscillators.harmonic",
        "oscillators.pendulum", "oscillators.power", "dynamics", "observables", "passage",
        "models", "plugins", "stats", "initial", "params")),
    ("engine: the step, its loops, the backends' drivers", (
        "integrator", "_backends", "_backends.cpu", "_backends.cuda", "_backends.cuda_probe",
        "_backends.joint", "_backends.layout", "runner")),
    ("run lifecycle: bias, resources, checkpoints, sweeps, the reduced model", (
        "bias", "resources", "lifecycle", "_compile_helper", "simulate", "checkpoint", "sweep",
        "_sweep_sets", "_blocks", "_backends.dask", "reduced", "multilevel")),
    ("results: theory, exponents, figures, plots, the report", (
        "theory", "theory.bfpe", "theory.family", "theory.laws", "theory.scaling", "theory.table",
        "exponents", "plotting", "figures", "figures._common", "figures._family", "figures.cases",
        "figures.exponents", "figures.family_boltzmann", "figures.family_kramers",
        "figures.family_random_frequency", "figures.family_washboard", "figures.fig1",
        "figures.fig2", "figures.fig3", "figures.fig4", "report", "reproduce")),
    ("the public face and the command line", (
        "", "__main__", "cli", "_cli_common", "_cli_reproduce", "_cli_scale", "_cli_target",
        "_cli_theory", "_cli_types")),
)


def _modules() -> dict[str, Path]:
    out = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def _imports(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The package's modules ``name`` imports, eagerly or lazily (TYPE_CHECKING left out)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found: set[str] = set()

    def target(dotted: str) -> str | None:
        if dotted == "stochpend":
            return ""
        if dotted.startswith("stochpend."):
            return dotted[len("stochpend."):]
        return None

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for other in child.orelse:
                    visit(other)
                continue
            if isinstance(child, ast.Import):
                for alias in child.names:
                    t = target(alias.name)
                    if t is not None:
                        found.add(t)
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    up = package.split(".") if package else []
                    up = up[: len(up) - (child.level - 1)]
                    base = ".".join(up + ([child.module] if child.module else []))
                else:
                    t = target(child.module or "")
                    if t is None:
                        continue
                    base = t
                for alias in child.names:
                    sub = f"{base}.{alias.name}" if base else alias.name
                    found.add(sub if sub in modules else base)
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    found.discard(name)
    return found


def _graph() -> dict[str, set[str]]:
    modules = _modules()
    return {name: _imports(name, path, modules) & set(modules) for name, path in modules.items()}


def _layer_of() -> dict[str, int]:
    return {name: i for i, (_, names) in enumerate(LAYERS) for name in names}


def test_every_module_has_a_layer() -> None:
    layer = _layer_of()
    modules = set(_modules())
    assert sorted(modules - set(layer)) == [], "place the new module in a layer of LAYERS"
    assert sorted(set(layer) - modules) == [], "LAYERS names a module that is gone"


def test_no_import_runs_against_the_layers() -> None:
    layer = _layer_of()
    against = sorted(f"{a or 'stochpend'} (layer {layer[a]}) imports {b} (layer {layer[b]})"
                     for a, targets in _graph().items() for b in targets if layer[b] > layer[a])
    assert against == []


def test_no_import_cycle_lazy_imports_included() -> None:
    graph = _graph()
    # Tarjan's strongly connected components: a component of two or more modules is a cycle.
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles: list[list[str]] = []

    def connect(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                connect(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            connect(v)
    assert cycles == []


def test_the_graph_sees_lazy_imports() -> None:
    """The counting itself: a function-level import is an edge (cli imports the simulator lazily),
    and a TYPE_CHECKING import is not."""
    graph = _graph()
    assert "simulate" in graph["cli"] or "simulate" in graph["_cli_common"]
    assert "integrator" in graph["bias"]  # imported inside functions only
    lazy_only = defaultdict(set)
    for name, path in _modules().items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.FunctionDef):
                for inner in ast.walk(node):
                    if isinstance(inner, ast.ImportFrom) and inner.module == "stochpend":
                        lazy_only[name].update(a.name for a in inner.names)
    assert lazy_only, "no lazy import found: the walk over function bodies is broken"
    for name, targets in lazy_only.items():
        assert {t for t in targets if t in graph} <= graph[name] | {""}, name
