"""The package's import graph has layers (issue 33, item 7); test_imports.py holds that it has
no cycles, over the same graph.

Every import in src/stochpend counts (tests/unit/test_imports.py's graph: at module level,
inside functions, importlib's with a literal name; ``if TYPE_CHECKING:`` blocks left out). A
module sits in one layer of :data:`LAYERS`, from the foundations up to the command line; an
import may reach its own layer or one below, never one above. A new module must be placed here:
the test fails on an unplaced one.
"""

from __future__ import annotations

from tests.unit.test_imports import import_graph

#: The layers, lowest first; a module may import from its own layer and those below.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("foundations: numbers, random streams, files, text, the paper's labels", (
        "_version", "_hostmath", "_notation", "_terminal", "_toml", "_warnings", "_docs",
        "_xarray_nodask", "_files", "_sources", "io", "_plain", "paper", "mathlib", "fastmath", "rng",
        "parameters", "progress", "_cputarget", "_jitcache", "_jitable", "_calibration")),
    ("model pieces: noises, oscillators, the family's terms, observables, settings", (
        "noises", "noises.base", "noises.white", "noises.ou", "noises.dichotomous",
        "noises.harmonic", "oscillators", "oscillators.base", "oscillators.harmonic",
        "oscillators.pendulum", "oscillators.power", "terms", "terms.base", "terms.damping",
        "terms.torque", "terms.drive", "terms.parametric", "dynamics", "observables", "passage",
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
        "", "__main__", "cli", "_cli_checkpoint", "_cli_common", "_cli_reproduce", "_cli_scale", "_cli_target",
        "_cli_theory", "_cli_types")),
)


def _short(module: str) -> str:
    return module[len("stochpend."):] if module.startswith("stochpend.") else ""


def _graph() -> dict[str, set[str]]:
    """tests/unit/test_imports.py's graph (every executed import, lazy ones and importlib's
    included), with the package's prefix taken off: "" is ``stochpend`` itself."""
    return {_short(a): {_short(b) for b in targets} for a, targets in import_graph().items()}


def _layer_of() -> dict[str, int]:
    return {name: i for i, (_, names) in enumerate(LAYERS) for name in names}


def test_every_module_has_a_layer() -> None:
    layer = _layer_of()
    modules = set(_graph())
    assert sorted(modules - set(layer)) == [], "place the new module in a layer of LAYERS"
    assert sorted(set(layer) - modules) == [], "LAYERS names a module that is gone"


def test_no_import_runs_against_the_layers() -> None:
    layer = _layer_of()
    against = sorted(f"{a or 'stochpend'} (layer {layer[a]}) imports {b} (layer {layer[b]})"
                     for a, targets in _graph().items() for b in targets if layer[b] > layer[a])
    assert against == []


def test_a_lazy_import_against_the_layers_is_seen() -> None:
    """The check can fail: a function-level import of the lifecycle from the random streams (the
    kind of climb the issue counted) is an edge against the layers."""
    layer = _layer_of()
    graph = _graph()
    graph["rng"] = graph["rng"] | {"simulate"}
    assert [b for b in graph["rng"] if layer[b] > layer["rng"]] == ["simulate"]
    assert "runner" in graph["bias"]  # bias imports the engine's host loop inside functions only
