"""The package's folders are its layers (issue 33, item 7); test_imports.py holds that it has
no cycles, over the same graph.

Every import in src/stochpend counts (tests/unit/test_imports.py's graph: at module level,
inside functions, importlib's with a literal name; ``if TYPE_CHECKING:`` blocks left out). A
module's layer is the sub-package it sits in (:data:`LAYERS`, from the foundations up to the
command line); an import may reach its own layer or one below, never one above. Only the
public face lives outside a folder: the package itself, ``__main__``, the version and the
public module paths users import (``stochpend.bias`` is :mod:`stochpend.runs.bias`).
"""

from __future__ import annotations

from tests.unit.test_imports import import_graph

#: The layers, lowest first: each a folder of the package (the last also the package's own
#: top-level files); a module may import from its own layer and those below.
LAYERS: tuple[tuple[str, str], ...] = (
    ("text", "text for people: the paper's equation numbers, notation, terminal, warnings"),
    ("files", "results files, atomic writes, configuration files"),
    ("numerics", "kernels' math, random streams, compilation and its caches, the code digest"),
    ("model", "noises, oscillators, the family's terms, observables, settings, sums"),
    ("engine", "the step, its loops, the host loop, the backends' drivers"),
    ("runs", "a run's life: lifecycle, bias, accuracy target, resources, checkpoints, sweeps"),
    ("theory", "the paper's closed forms, the B.F.P.E., growth-law fits"),
    ("paper", "the paper's figures, their reproduction, the report, plotting"),
    ("cli", "the command line"),
)

#: Files at the package's top: its version (read by every layer, imports nothing) and the
#: public face (the package, ``python -m stochpend``, the public module paths).
TOP_LEVEL = {"_version": 0}
PUBLIC_FACE = {"", "__main__", "_alias", "bias", "exponents", "io", "models", "noises",
               "observables", "oscillators", "plotting", "plugins", "sweep", "terms"}


def _short(module: str) -> str:
    return module[len("stochpend."):] if module.startswith("stochpend.") else ""


def _graph() -> dict[str, set[str]]:
    """tests/unit/test_imports.py's graph (every executed import, lazy ones and importlib's
    included), with the package's prefix taken off: "" is ``stochpend`` itself."""
    return {_short(a): {_short(b) for b in targets} for a, targets in import_graph().items()}


def _layer(module: str) -> int:
    """The layer of a module: its folder's; the public face sits above the command line."""
    folder = module.split(".")[0]
    for i, (name, _) in enumerate(LAYERS):
        if folder == name:
            return i
    if module in TOP_LEVEL:
        return TOP_LEVEL[module]
    if module in PUBLIC_FACE:
        return len(LAYERS)
    raise AssertionError(f"stochpend.{module} sits in no layer: put it in a folder of LAYERS")


def test_every_module_sits_in_a_layer_folder() -> None:
    modules = set(_graph())
    assert sorted(m for m in modules if "." not in m and m not in TOP_LEVEL.keys() | PUBLIC_FACE
                  and m not in {name for name, _ in LAYERS}) == []
    assert {m.split(".")[0] for m in modules if "." in m} == {name for name, _ in LAYERS}
    assert sorted((TOP_LEVEL.keys() | PUBLIC_FACE) - modules) == [], "a listed top-level file is gone"


def test_no_import_runs_against_the_layers() -> None:
    against = sorted(f"{a or 'stochpend'} (layer {_layer(a)}) imports {b} (layer {_layer(b)})"
                     for a, targets in _graph().items() for b in targets if _layer(b) > _layer(a))
    assert against == []


def test_the_public_paths_are_the_layered_modules() -> None:
    """``stochpend.bias`` and the other paths users import are the modules the package uses,
    one object each, and a public package's submodules are the real ones (one registry)."""
    import importlib

    import stochpend
    from stochpend.model import noises as real_noises
    from stochpend.model.noises import ou
    from stochpend.runs import bias

    assert importlib.import_module("stochpend.bias") is bias is stochpend.bias
    assert importlib.import_module("stochpend.noises") is real_noises
    assert importlib.import_module("stochpend.noises.ou") is ou
    for name in PUBLIC_FACE - {"", "__main__", "_alias"}:
        module = importlib.import_module(f"stochpend.{name}")
        assert module.__name__.count(".") >= 2, (name, module.__name__)


def test_a_lazy_import_against_the_layers_is_seen() -> None:
    """The check can fail: a function-level import of the lifecycle from the random streams (the
    kind of climb the issue counted) is an edge against the layers."""
    graph = _graph()
    graph["numerics.rng"] = graph["numerics.rng"] | {"runs.simulate"}
    assert [b for b in graph["numerics.rng"] if _layer(b) > _layer("numerics.rng")] == ["runs.simulate"]
    assert "engine.runner" in graph["runs.bias"]  # bias imports the engine's host loop inside functions only
