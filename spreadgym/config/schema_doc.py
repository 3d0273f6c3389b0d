"""The accepted range of every config key, generated from the schemas (docs/config-keys.md).

`python -m spreadgym.envs.config_doc > docs/config-keys.md` writes the file (scenes and
both environments); a test checks that docs/ holds what the schemas say, so the ranges
are never written twice.
"""

from __future__ import annotations

import re
from typing import Any, Iterator, get_args

from pydantic import BaseModel
from pydantic_core import PydanticUndefined

from spreadgym.config.base import _BOUNDS, _model_inside


def _bounds(metadata: list) -> str:
    parts = []
    for meta in metadata:
        for kind, (symbol, attribute) in _BOUNDS.items():
            if isinstance(meta, kind):
                parts.append(f"{symbol} {getattr(meta, attribute):g}")
    return ", ".join(parts)


def _item_bounds(annotation: Any) -> str:
    """Bounds declared on the items of a tuple/list annotation (e.g. each wind component)."""
    for arg in get_args(annotation):
        metadata = []
        for meta in getattr(arg, "__metadata__", ()) or ():
            metadata += [meta, *getattr(meta, "metadata", [])]  # Field(...) inside Annotated holds its own
        if _bounds(metadata):
            return f"each {_bounds(metadata)}"
        if _item_bounds(arg):
            return _item_bounds(arg)
    return ""


def _type_name(annotation: Any) -> str:
    text = str(annotation).replace("typing.", "")
    text = re.sub(r"Annotated\[float, Strict\(strict=True\), FieldInfo\(.*?\]\)\]", "number", text)
    for long, short in (("Annotated[float, Strict(strict=True)]", "number"),
                        ("Annotated[int, Strict(strict=True)]", "integer"), ("NoneType", "null")):
        text = text.replace(long, short)
    text = text.replace("<class 'float'>", "number").replace("<class 'int'>", "integer")
    text = text.replace("<class 'str'>", "text").replace("<class 'bool'>", "true/false")
    return text


def rows(model: type[BaseModel], prefix: str = "") -> Iterator[tuple[str, str, str, str, str]]:
    """(dotted key, type, default, allowed, description) of every leaf of `model`."""
    for name, field in model.model_fields.items():
        key = f"{prefix}{name}"
        inner = _model_inside(field.annotation)
        if inner is not None:
            marker = "[i]" if "list" in str(field.annotation) else ""
            if "str" in str(field.annotation):  # a name, or the mapping whose keys follow
                yield key, f"text or mapping ({key}.* below)", "required", "", field.description or ""
            yield from rows(inner, f"{key}{marker}.")
            continue
        default = "required" if field.default is PydanticUndefined and field.default_factory is None \
            else repr(field.default if field.default_factory is None else field.default_factory())
        allowed = _bounds(field.metadata) or _item_bounds(field.annotation)
        yield key, _type_name(field.annotation), default, allowed, field.description or ""


def schema_markdown(sections: dict[str, type[BaseModel]]) -> str:
    """One table per schema: key, type, default, allowed range, meaning."""
    out = ["# Config keys and their accepted ranges", "",
           "Generated from the schemas by `python -m spreadgym.envs.config_doc`; do not edit by hand.",
           "Every number must be finite; `true`/`false` are not numbers and quoted text is not a number.",
           "Checks that involve several keys (the rim speed omega R <= 100 m/s, the feed inside the disc,",
           "plates outside it, the target swath a multiple of the tray width) are stated in the errors.",
           "`[i]` is a list index: `--set deflectors[0].x_m=0.3` and `--set deflectors.0.x_m=0.3` are the same.", ""]
    for title, model in sections.items():
        out += [f"## {title}", "", "| key | type | default | allowed | meaning |", "|---|---|---|---|---|"]
        for key, kind, default, allowed, description in rows(model):
            out.append(f"| `{key}` | {kind} | {default} | {allowed} | {description} |".replace("\n", " "))
        out.append("")
    return "\n".join(out)
