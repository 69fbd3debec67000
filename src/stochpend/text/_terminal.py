"""Text from files made safe for a terminal.

Anything read from a file (NetCDF attributes, a checkpoint's header, a sweep's description, a
file name) may hold escape sequences that move the cursor, retitle the window or hide text, and
Rich markup (``[/]``, ``[draft]``) that Rich would interpret or choke on. Every such text passes
through :func:`plain` before it is printed, and through :func:`markup` before it enters a string
that Rich renders as markup.
"""

from __future__ import annotations

import unicodedata

__all__ = ["SHORT", "markup", "plain", "short"]

#: Text from a file longer than this many characters is shortened for the terminal (a 20 MB
#: attribute printed 256 426 lines into a table's title); file names stay whole below it.
SHORT = 500


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


def short(text: object, limit: int = SHORT) -> str:
    """``text`` cut to its first ``limit`` characters, with its length stated, when longer."""
    s = text if isinstance(text, str) else str(text)
    if len(s) <= limit:
        return s
    return f"{s[:limit]}... ({len(s)} characters in all, shortened)"


def markup(text: object, limit: int = SHORT) -> str:
    """:func:`plain` of :func:`short` (``limit`` characters at most), then Rich's markup
    escaped, for text inserted into a Rich markup string."""
    from rich.markup import escape

    return escape(plain(short(text, limit)))
