"""Pieces from outside the package: a noise, an oscillator or an observable that a module
registers when it is imported.

Only the person running stochpend chooses what code runs: a plugin is loaded by :func:`load`,
which the command line calls for each ``--plugin NAME`` it is given (and a Python user calls, or
simply imports the module). NAME is an installed entry point of the group ``stochpend.plugins``
(a package declares ``[project.entry-points."stochpend.plugins"] name = "module"``) or a module's
dotted name. Files never load code: a checkpoint, a sweep file or a configuration records the
names of the pieces it uses, and a process that has not loaded them refuses it in one line
that says so. Sweep workers load the plugins their client was given (:func:`loaded`).
"""

from __future__ import annotations

import importlib
import re
from importlib import metadata

__all__ = ["GROUP", "load", "loaded"]

GROUP = "stochpend.plugins"
_DOTTED = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z_][A-Za-z0-9_]*)*")
_LOADED: list[str] = []


def load(name: str) -> None:
    """Import the plugin ``name`` (an entry point of :data:`GROUP`, else a module), once per
    process. A one-line ValueError naming it when there is none or its import fails."""
    if name in _LOADED:
        return
    if not isinstance(name, str) or not _DOTTED.fullmatch(name):
        raise ValueError(f"plugin={name!r} is not accepted: an installed stochpend plugin or a module's dotted name")
    try:
        points = [ep for ep in metadata.entry_points(group=GROUP) if ep.name == name]
        if points:
            points[0].load()
        else:
            importlib.import_module(name)
    except ModuleNotFoundError as error:
        raise ValueError(f"plugin={name!r} is not accepted: no installed stochpend plugin or module of that name "
                         f"({error})") from None
    except Exception as error:  # the plugin's own failure, told in one line
        text = " ".join(str(error).split())[:200]
        raise ValueError(f"plugin={name!r} is not accepted: importing it raised {type(error).__name__}: {text}") from None
    _LOADED.append(name)


def loaded() -> tuple[str, ...]:
    """The plugins this process loaded, in order (what a sweep's workers load too)."""
    return tuple(_LOADED)
