"""The one strict base of every config model, its number types and its error message.

Every config section (scenes, environments, training runs) derives from `StrictModel`:
unknown keys are errors, values are frozen, and no float may be NaN or infinite.
Numbers are strict: `true` is not a number and `"200"` is not an integer (YAML and
`--set` parse numbers themselves), while an integer is accepted where a float is due.
`format_validation_error` turns pydantic's first complaint into one `ConfigError` line
naming the dotted key, the bad value and the allowed range; `validate` applies it.
"""

from __future__ import annotations

import re
import reprlib
from typing import Annotated, Any, Optional, TypeVar

import annotated_types
from pydantic import BaseModel, ConfigDict, Strict, ValidationError

from spreadgym.errors import ConfigError

Real = Annotated[float, Strict()]  # a finite number; ints accepted, bools and strings not
Integer = Annotated[int, Strict()]  # an int; bools, floats and strings not


class StrictModel(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


ModelT = TypeVar("ModelT", bound=BaseModel)

_BRIEF = reprlib.Repr()
_BRIEF.maxlevel, _BRIEF.maxlist, _BRIEF.maxtuple, _BRIEF.maxdict = 2, 4, 4, 4
_BRIEF.maxstring, _BRIEF.maxother, _BRIEF.maxlong = 60, 60, 40


def brief(value: Any) -> str:
    """`repr(value)` cut to a few dozen characters (a message never spells out a huge value)."""
    return _BRIEF.repr(value)


def first_line(exc: BaseException) -> str:
    """An exception's message as one short line: its first line, cut as `brief` cuts (its type's name when empty)."""
    lines = str(exc).strip().splitlines()
    return brief(lines[0])[1:-1] if lines else type(exc).__name__


_BOUNDS = {annotated_types.Ge: (">=", "ge"), annotated_types.Gt: (">", "gt"), annotated_types.Le: ("<=", "le"),
           annotated_types.Lt: ("<", "lt")}


def field_range(model: type[BaseModel], loc: tuple) -> Optional[str]:
    """The bounds declared on the field at `loc` (e.g. ">= 0, <= 5000"), or None."""
    current: Any = model
    field = None
    for part in loc:
        if isinstance(part, int) or not (isinstance(current, type) and issubclass(current, BaseModel)):
            continue
        field = current.model_fields.get(str(part))
        if field is None:
            return None
        current = _model_inside(field.annotation)
    if field is None:
        return None
    bounds = []
    for meta in field.metadata:
        for kind, (symbol, attribute) in _BOUNDS.items():
            if isinstance(meta, kind):
                bounds.append(f"{symbol} {getattr(meta, attribute):g}")
    return ", ".join(bounds) or None


def _model_inside(annotation: Any) -> Any:
    """The BaseModel class inside an annotation such as Optional[M] or list[M], if any."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in getattr(annotation, "__args__", ()) or ():
        found = _model_inside(arg)
        if found is not None:
            return found
    return None


_UNION_TAG = re.compile(r"^(float|int|list\[.*\])$")  # how pydantic names the branch of a union in a location


def format_validation_error(exc: ValidationError, model: type[BaseModel], root: str) -> ConfigError:
    """The first problem of `exc` as one line: dotted key, what is wrong, what is allowed.
    Of a field that takes one value or a list (a union), a list's problem is reported
    from the list branch (`vanes.pitch_deg.1: ... finite`), without pydantic's branch tags."""
    errors = exc.errors()
    first = errors[0]
    if isinstance(first.get("input"), list):
        listed = [e for e in errors if any(isinstance(p, str) and p.startswith("list[") for p in e["loc"])]
        first = listed[0] if listed else first
    loc = tuple(p for p in first["loc"] if not (isinstance(p, str) and _UNION_TAG.match(p)))
    key = ".".join(str(p) for p in loc) or root
    message = first["msg"].removeprefix("Value error, ")
    named = re.match(r"^([\w.\[\]]+): (.*)$", message, flags=re.S)
    if named:  # model checks name their key in the message, relative to the model
        inner, message = named.groups()
        key = inner if key == root else f"{key}.{inner}"
    if first["type"] == "missing":
        return ConfigError(key, "missing (required)")
    if first["type"] == "extra_forbidden":
        return ConfigError(key, "unknown key")
    if first["type"] != "value_error":
        message += f" (got {brief(first.get('input'))})"
        allowed = field_range(model, loc)
        if allowed:  # out of range, not finite, or not a number at all ('nan' is a string in YAML)
            message += f"; allowed: {allowed}"
    return ConfigError(key, message)


def validate(model: type[ModelT], raw: Any, root: str) -> ModelT:
    """`model` validated from the mapping `raw`; the first problem is a one-line ConfigError."""
    try:
        return model.model_validate(raw)
    except ValidationError as exc:
        raise format_validation_error(exc, model, root) from None
