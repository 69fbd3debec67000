"""Docstrings from one source: the defaults a reader sees in ``help()`` are the signature's.

:func:`documented` rewrites a public function's numpydoc docstring once, at import:

* every parameter heading (``paths : int``) gets the signature's default appended
  (``paths : int, default 10000``), so that the text cannot contradict the code (issue 36: the
  docstring gave a bias-pair default the code had long left); a default given as ``None``
  stands for something the entry's text must say in words;
* the paper's equation labels (``Eq. `eqOU```) become its printed numbers ("Eq. (18)"), as the
  command line's help and the report cite them (:func:`stochpend.paper.with_numbers`), except in
  parameter names and ````literal```` spans, where a word that is also a label (``bfpe``) is code.

:func:`undocumented` lists the signature's parameters that the docstring does not describe
(a test keeps it empty).
"""

from __future__ import annotations

import inspect
import re
from collections.abc import Callable
from typing import Any, TypeVar

F = TypeVar("F", bound=Callable[..., Any])

#: A parameter heading in a numpydoc "Parameters" section: 4 spaces, names, optionally " : type".
_HEADING = re.compile(r"^    (?P<names>\*{0,2}[A-Za-z_]\w*(?:, \*{0,2}[A-Za-z_]\w*)*)(?P<rest> : .*)?$")


def _section(lines: list[str], title: str) -> tuple[int, int]:
    """(first line, end) of the numpydoc section ``title`` (empty range if absent)."""
    for i, line in enumerate(lines[:-1]):
        if line.strip() == title and set(lines[i + 1].strip()) == {"-"}:
            end = i + 2
            while end < len(lines) and not (end + 1 < len(lines) and lines[end].strip()
                                             and set(lines[end + 1].strip()) == {"-"}):
                end += 1
            return i + 2, end
    return 0, 0


def _shown(value: Any) -> str:
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return repr(value)
    if isinstance(value, tuple) and not value:
        return "none"
    return repr(value)


def headings(fn: Callable[..., Any]) -> dict[str, str]:
    """Parameter name -> its heading line (unindented), from ``fn``'s docstring as it is now."""
    lines = inspect.cleandoc(fn.__doc__ or "").splitlines()
    start, end = _section(lines, "Parameters")
    out = {}
    for line in lines[start:end]:
        m = _HEADING.match("    " + line)
        if m:
            for name in m.group("names").split(", "):
                out[name.lstrip("*")] = line.strip()
    return out


def undocumented(fn: Callable[..., Any]) -> list[str]:
    """The parameters of ``fn``'s signature that its docstring's Parameters section lacks."""
    documented_names = set(headings(fn))
    return [name for name in inspect.signature(fn).parameters if name not in documented_names]


_LITERAL = re.compile(r"(``[^`]*``)")


def numbered(text: str) -> str:
    """``text`` with the paper's labels as equation numbers, outside ````literal```` spans."""
    from stochpend.text.equations import with_numbers

    return "".join(part if part.startswith("``") else with_numbers(part) for part in _LITERAL.split(text))


def documented(fn: F) -> F:
    """Append each parameter's default to its heading and cite equations by number (module
    docstring)."""
    doc = inspect.cleandoc(fn.__doc__ or "")
    if not doc:
        return fn
    signature = inspect.signature(fn)
    lines = doc.splitlines()
    lines = [lines[0], *("    " + ln if ln else ln for ln in lines[1:])]  # back to the body's indentation
    start, end = _section(lines, "Parameters")
    heading_lines = {i for i in range(start, end) if _HEADING.match(lines[i])}
    lines = [line if i in heading_lines else numbered(line) for i, line in enumerate(lines)]
    for i in sorted(heading_lines):
        m = _HEADING.match(lines[i])
        if not m:
            continue
        defaults = []
        names = [n.lstrip("*") for n in m.group("names").split(", ")]
        for name in names:
            p = signature.parameters.get(name)
            if p is None or p.default is inspect.Parameter.empty or p.default is None:
                continue
            defaults.append(_shown(p.default) if len(names) == 1 else f"{name}={_shown(p.default)}")
        if defaults:
            rest = m.group("rest") or " :"
            rest = re.sub(r",? optional$", "", rest)
            joiner = "" if rest == " :" else ","
            lines[i] = f"    {m.group('names')}{rest}{joiner} default{'s' if len(defaults) > 1 else ''} {', '.join(defaults)}"
    fn.__doc__ = "\n".join(lines)
    return fn
