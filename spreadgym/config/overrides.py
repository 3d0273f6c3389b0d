"""Dotted-key overrides (`--set spinner.rpm=800`) applied to nested config dicts."""

from __future__ import annotations

import copy
from typing import Any, Iterable, Mapping

import yaml

from spreadgym.config.resources import parse_yaml
from spreadgym.errors import ConfigError


def parse_assignment(text: str) -> tuple[str, Any]:
    """Split 'a.b=VALUE' and parse VALUE as YAML (so `deflectors=[]` gives a list)."""
    key, sep, raw = text.partition("=")
    key = key.strip()
    if not sep or not key:
        raise ConfigError("--set", f"expected KEY=VALUE, got {text!r}")
    try:
        value = parse_yaml(raw) if raw.strip() else None
    except yaml.YAMLError as exc:
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise ConfigError(key, f"value {raw!r} is not valid YAML: {problem}") from exc
    return key, value


def apply_overrides(config: Mapping[str, Any], assignments: Mapping[str, Any]) -> dict:
    """Return a deep copy of `config` with each dotted key set.

    Only keys that exist in `config` may be set, so a typo is an error that names it
    rather than a silently ignored value.
    """
    result = copy.deepcopy(dict(config))
    for dotted, value in assignments.items():
        node = result
        parts = dotted.split(".")
        for depth, part in enumerate(parts):
            where = ".".join(parts[: depth + 1])
            if isinstance(node, list):
                if not node:
                    raise ConfigError(where, "the list is empty here; set the whole list instead")
                if not part.isdigit() or int(part) >= len(node):
                    raise ConfigError(where, f"list index must be 0..{len(node) - 1}")
                part = int(part)
            elif not isinstance(node, dict) or part not in node:
                known = ", ".join(sorted(node)) if isinstance(node, dict) else "none"
                raise ConfigError(where, f"unknown key; known keys here: {known}")
            if depth == len(parts) - 1:
                node[part] = value
            else:
                node = node[part]
    return result


def parse_assignments(texts: Iterable[str]) -> dict[str, Any]:
    """Parse several KEY=VALUE texts; later ones win."""
    return dict(parse_assignment(t) for t in texts)
