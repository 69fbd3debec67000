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


class _ParserError(ValueError):
    """A parser's refusal in the shape :func:`usage_message` reads from Pydantic's
    ``ValidationError`` (``errors()``: type, input, ctx.error, msg)."""

    def __init__(self, value: Any, error: ValueError) -> None:
        super().__init__(f"Value error, {error}")
        self._errors = [{"type": "value_error", "input": value, "ctx": {"error": error},
                         "msg": f"Value error, {error}"}]

    def errors(self) -> list[dict[str, Any]]:
        return self._errors


def _coerce_leaf(annotation: Any, parser: Any, value: Any) -> Any:
    """A value as Typer's Pydantic adapter would give it, for the cases this handles exactly (a
    parser, text, a float given as a float); raises LookupError for any other case."""
    if parser is not None:
        try:
            return parser(value)
        except ValueError as exc:  # Pydantic wraps a parser's ValueError, and so does this
            raise _ParserError(value, exc) from None
    if annotation is str and isinstance(value, str):
        return value
    if annotation is float and type(value) is float:
        return value
    raise LookupError(annotation)


def fast_coercion(param: Any) -> None:
    """Convert this option's values without Pydantic where the result is certain to be the same.

    Typer (0.29) converts every value, defaults included, through a Pydantic ``TypeAdapter``
    built on first use: importing Pydantic and building the adapters cost about 0.15 s of a
    command's start (``show``: 0.12 of 1.1 s under cProfile). This gives the parameter a
    conversion (``_runtime_param``, Typer's lazy slot) that applies the option's own parser,
    passes text and a default float through, and hands anything else to Typer's adapter as
    before (built then, on first need). Refusals keep Pydantic's shape (:class:`_ParserError`),
    so :func:`usage_message` prints them as before.
    """
    descriptor: Any = getattr(param, "type_descriptor", None)
    if descriptor is None or getattr(param, "_runtime_param", 0) is not None or descriptor.is_file:
        return
    try:
        from typer._click.exceptions import BadParameter
        from typer._coercion import RuntimeParam, build_runtime_param
    except ImportError:  # another Typer: its own conversion
        return
    info = descriptor.parameter_info
    annotation = descriptor.annotation
    if descriptor.is_tuple or info.min is not None or info.max is not None or info.clamp:
        return
    item = None
    if descriptor.is_list:
        args: tuple[Any, ...] = getattr(annotation, "__args__", ())
        if len(args) != 1 or info.parser is not None:
            return
        item = args[0]

    class Fast(RuntimeParam):
        full: Any = None

        def _coerce_value(self, value: Any, param: Any, ctx: Any) -> Any:
            try:
                if item is not None:
                    values = value if isinstance(value, list | tuple) else [value]
                    return [_coerce_leaf(item, None, v) for v in values]
                return _coerce_leaf(annotation, info.parser, value)
            except _ParserError as exc:
                raise BadParameter(str(exc), ctx=ctx, param=param) from exc
            except LookupError:
                pass
            if self.full is None:
                object.__setattr__(self, "full", build_runtime_param(descriptor))
            return self.full._coerce_value(value, param, ctx)

    param._runtime_param = Fast(parameter_info=info, annotation=annotation)
