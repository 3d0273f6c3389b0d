"""Dotted-key overrides (`--set spinner.rpm=800`): the one way scenes, environment
configs and training runs are changed key by key, checked against their schema."""

from __future__ import annotations

import copy
import re
import types
from typing import Any, Iterable, Mapping, Optional, Union, get_args, get_origin

import yaml
from pydantic import BaseModel

from spreadgym.config.base import brief
from spreadgym.config.resources import parse_yaml
from spreadgym.errors import ConfigError


def parse_assignment(text: str) -> tuple[str, Any]:
    """Split 'a.b=VALUE' and parse VALUE as YAML (so `deflectors=[]` gives a list)."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError("--set", f"expected KEY=VALUE, got {brief(text)}")
    try:
        value = parse_yaml(raw) if raw.strip() else None
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise ConfigError(key, f"value {brief(raw)} is not valid YAML: {problem}") from exc
    return key, value


def apply_overrides(config: Mapping[str, Any], assignments: Mapping[str, Any], schema: type[BaseModel]) -> dict:
    """Return a deep copy of `config` with each dotted key set, following `schema`.

    Every part of a dotted key must be a field of the schema model at that depth (or an
    index into a list of models), so a typo is an error naming the key and the allowed
    keys, never a silently ignored value. Below a free mapping (`dict[str, Any]`) the
    rest of the key is one entry (`scene_overrides.spinner.rpm` sets the entry
    "spinner.rpm"). A field that is not a section (a number, or a flag such as
    `normalize: false`) is set as a whole; a section the config leaves out is created.
    The values are checked afterwards, when the result is validated against the schema.
    """
    return set_in_place(copy.deepcopy(dict(config)), assignments, schema)


def set_in_place(tree: dict, assignments: Mapping[str, Any], schema: type[BaseModel]) -> dict:
    """`apply_overrides` on `tree` itself (a tree the caller owns, e.g. a fresh
    `model_dump()`), without the copy; returns `tree`."""
    for dotted, value in assignments.items():
        if not isinstance(dotted, str) or not dotted:
            raise ConfigError(str(dotted), "keys must be non-empty strings")
        _set(tree, key_parts(dotted), value, schema)
    return tree


INDEX = re.compile(r"\[(\d+)\]")


def key_parts(dotted: str) -> list[str]:
    """The parts of a dotted key; an index may also be written as the key reference writes
    it (`deflectors[0].x_m` is `deflectors.0.x_m`)."""
    return INDEX.sub(r".\1", dotted).split(".")


def _set(tree: dict, parts: list[str], value: Any, schema: type[BaseModel]) -> None:
    node: Any = tree
    annotation: Any = schema
    for depth, part in enumerate(parts):
        where = ".".join(parts[: depth + 1])
        last = depth == len(parts) - 1
        model = _model_in(annotation)
        if isinstance(node, list):
            if not node:
                raise ConfigError(where, "the list is empty here; set the whole list instead")
            if not part.isdigit() or int(part) >= len(node):
                raise ConfigError(where, f"list index must be 0..{len(node) - 1}")
            key: Any = int(part)
            annotation = _item_annotation(annotation)
        elif model is not None:
            if part not in model.model_fields:
                raise ConfigError(where, f"unknown key; known keys here: {', '.join(sorted(model.model_fields))}")
            key = part
            annotation = model.model_fields[part].annotation
        elif _is_free_mapping(annotation):  # the rest of the key is one entry
            node[".".join(parts[depth:])] = value
            return
        else:
            raise ConfigError(".".join(parts[:depth]), "is not a section; set it as a whole")
        if last:
            node[key] = value
            return
        child = node.get(key) if isinstance(node, dict) else node[key]
        if child is None and isinstance(node, dict) and (
                _model_in(annotation) is not None or _is_free_mapping(annotation)):
            child = node[key] = {}  # a section the config leaves out or sets to null (e.g. `twin`)
        if not isinstance(child, (dict, list)):
            raise ConfigError(where, "is not a section; set it as a whole")
        node = child


def _model_in(annotation: Any) -> Optional[type[BaseModel]]:
    """The model class of a field annotated M or Optional[M] / Union[bool, M] (not list[M])."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    if get_origin(annotation) in (Union, types.UnionType):
        for arg in get_args(annotation):
            if isinstance(arg, type) and issubclass(arg, BaseModel):
                return arg
    return None


def _item_annotation(annotation: Any) -> Any:
    """The item type of list[X] / tuple[X, ...] (Any when unknown)."""
    args = [a for a in get_args(annotation) if a is not Ellipsis]
    return args[0] if args else Any


def _is_free_mapping(annotation: Any) -> bool:
    return annotation is dict or get_origin(annotation) in (dict, Mapping)


def parse_assignments(texts: Iterable[str]) -> dict[str, Any]:
    """Parse several KEY=VALUE texts; later ones win."""
    return dict(parse_assignment(t) for t in texts)
