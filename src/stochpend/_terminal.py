"""Text from files made safe for a terminal.

Anything read from a file (NetCDF attributes, a checkpoint's header, a sweep's description, a
file name) may hold escape sequences that move the cursor, retitle the window or hide text, and
Rich markup (``[/]``, ``[draft]``) that Rich would interpret or choke on. Every such text passes
through :func:`plain` before it is printed, and through :func:`markup` before it enters a string
that Rich renders as markup.
"""

from __future__ import annotations

import unicodedata

__all__ = ["markup", "plain"]


def _escape_char(ch: str) -> str:
    code = ord(ch)
    if code < 0x100:
        return f"\\x{code:02x}"
    if code < 0x10000:
        return f"\\u{code:04x}"
    return f"\\U{code:08x}"


def plain(text: object) -> str:
    """``text`` with every control or format character (C0, DEL, C1, bidirectional overrides,
    lone surrogates) written as a visible escape (``\\x1b``, ``\\u202e``): printable, one line."""
    s = text if isinstance(text, str) else str(text)
    out = []
    for ch in s:
        cat = unicodedata.category(ch)
        if cat in ("Cc", "Cf", "Cs", "Co", "Cn") and ch != " ":
            out.append(_escape_char(ch))
        else:
            out.append(ch)
    return "".join(out)


def markup(text: object) -> str:
    """:func:`plain`, then Rich's markup escaped, for text inserted into a Rich markup string."""
    from rich.markup import escape

    return escape(plain(text))
