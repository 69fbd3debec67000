"""Option parsing for the command line: integers in scientific notation, and usage errors
(bad option values, unknown options, missing arguments) as the project's one line.

No Rich and no import of :mod:`stochpend.cli`, so that every command module can use it.
"""

from __future__ import annotations

import sys
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

__all__ = ["INTEGER_ACCEPTED", "file_name", "integer", "usage_message"]

INTEGER_ACCEPTED = "an integer, e.g. 10000, 1e4 or 2.5e3 (scientific notation for whole numbers)"


def integer(value: Any) -> int:
    """Parser of the integer options: ``'10000'``, ``'-3'``, ``'1e15'``, ``'2.5e3'`` -> int.

    Scientific notation is read exactly (as a decimal, not a float) and accepted when the
    number is whole: ``'1e15'`` is 10**15, ``'1e15.5'`` and ``'2.5'`` are refused. Raises
    ``ValueError(INTEGER_ACCEPTED)``; the command line names the option and the value.
    """
    if isinstance(value, bool):
        raise ValueError(INTEGER_ACCEPTED)
    if isinstance(value, int):
        return value
    text = str(value).strip()
    try:
        return int(text, 10)
    except ValueError:
        pass
    try:
        d = Decimal(text)
    except (InvalidOperation, ValueError):
        raise ValueError(INTEGER_ACCEPTED) from None
    # adjusted(): the decimal exponent; beyond 10**1000 the int itself would be the problem
    if not d.is_finite() or d.adjusted() > 1000 or d != d.to_integral_value():
        raise ValueError(INTEGER_ACCEPTED)
    return int(d)


def file_name(value: Any) -> Path:
    """Parser of the file and folder options: ``''`` is refused (``Path('')`` is ``'.'``, the
    current folder, and the refusal then talked about '.')."""
    if isinstance(value, Path):
        return value
    if str(value) == "":
        raise ValueError("the name is empty; give a file name")
    return Path(value)


#: What a value of each kind must be, by Pydantic error type (Typer validates with Pydantic).
_ACCEPTED_BY_ERROR = {
    "int_parsing": "an integer",
    "int_type": "an integer",
    "int_from_float": "an integer",
    "float_parsing": "a number, e.g. 1, 0.5, 1e-3, nan or inf",
    "float_type": "a number, e.g. 1, 0.5, 1e-3, nan or inf",
    "bool_parsing": "true or false",
    "bool_type": "true or false",
}


def usage_message(exc: Any) -> str:
    """One line for a Click/Typer usage error, in the project's form where a value was bad:
    ``--paths '1e15.5' is not accepted: an integer, ...``."""
    param = getattr(exc, "param", None)
    name = getattr(param, "name", None)
    cause = getattr(exc, "__cause__", None)
    errors: list[Any] = []
    if cause is not None and hasattr(cause, "errors"):
        try:
            errors = list(cause.errors())
        except Exception:  # not a Pydantic ValidationError after all
            errors = []
    if name and errors and "input" in errors[0]:
        err = errors[0]
        if err.get("type") == "value_error" and "error" in err.get("ctx", {}):
            accepted = str(err["ctx"]["error"])
        else:
            accepted = _ACCEPTED_BY_ERROR.get(err.get("type", ""), str(err.get("msg", "")))
        value = err["input"]
        shown = repr(value) if len(repr(value)) <= 80 else repr(value)[:76] + " ..."
        longs = [o for o in getattr(param, "opts", ()) if o.startswith("--")]
        named = f"{longs[0]} " if longs else f"{name}="  # an option by its flag, an argument by name
        ctx = getattr(exc, "ctx", None)
        source, keys = (getattr(ctx, "meta", None) or {}).get("stochpend.config_file", ("", set()))
        if name in keys and ctx is not None and (ctx.params or {}).get(name) is None \
                and f"{longs[0] if longs else ''}" not in sys.argv:  # the value came from --config FILE
            named = f"{source}: {name}="
        return " ".join(f"{named}{shown} is not accepted: {accepted}".split())
    try:
        message = exc.format_message()
    except Exception:
        message = str(exc)
    message = " ".join(str(message).split()).rstrip(".") or type(exc).__name__
    ctx = getattr(exc, "ctx", None)
    command = getattr(ctx, "command_path", None)
    if command:
        message += f" (see '{command} --help')"
    return message[:1].lower() + message[1:]
