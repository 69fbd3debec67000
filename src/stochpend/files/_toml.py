"""Reading a TOML file the user names (a sweep, a simulate configuration): one place with one
set of limits, so that every refusal is one ``ValueError`` line naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

__all__ = ["MAX_TOML_BYTES", "read_toml"]

#: A configuration or sweep file is text a person writes: beyond this it is refused unread.
MAX_TOML_BYTES = 1 << 20


def read_toml(path: str | Path, name: str) -> tuple[str, dict[str, Any]]:
    """(text, parsed) of the TOML file ``path``; ``name`` is the parameter the refusals name
    (``sweep``, ``--config``). Only a regular file of at most :data:`MAX_TOML_BYTES` is read
    (a FIFO would hang, a device never end)."""
    p = Path(path)
    if not p.is_file():
        why = "it is a directory" if p.is_dir() else "no such file" if not p.exists() else "not a regular file"
        raise ValueError(f"{name}={str(p)!r} is not accepted: {why}")
    size = p.stat().st_size
    if size > MAX_TOML_BYTES:
        raise ValueError(f"{name}={str(p)!r} is not accepted: it is {size} bytes, more than the "
                         f"{MAX_TOML_BYTES} a TOML file of this tool may have")
    try:
        text = p.read_text(encoding="utf-8")
        return text, tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise ValueError(f"{name}={str(p)!r} is not accepted: not UTF-8 text ({exc})") from None
    except (ValueError, RecursionError) as exc:  # TOMLDecodeError; an integer of 5000 digits
        why = "nested too deeply" if isinstance(exc, RecursionError) else " ".join(str(exc).split())
        raise ValueError(f"{name}={str(p)!r} is not accepted: invalid TOML ({why})") from None
