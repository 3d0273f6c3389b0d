"""Locating and reading the YAML files shipped under configs/ (package data)."""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from spreadgym.errors import ConfigError


def config_dir() -> Path:
    """Directory of the shipped configs (works for editable installs and wheels)."""
    return Path(str(resources.files("spreadgym.configs")))


def read_yaml(path: Path) -> Any:
    """Parse a YAML file; a syntax error becomes a ConfigError naming the file."""
    try:
        with open(path, encoding="utf-8") as handle:
            return yaml.safe_load(handle)
    except FileNotFoundError as exc:
        raise ConfigError(str(path), "file not found") from exc
    except yaml.YAMLError as exc:
        raise ConfigError(str(path), f"not valid YAML ({exc})") from exc


def resolve_named(kind: str, name_or_path: str) -> Path:
    """Find configs/<kind>/<name>.yaml, or accept a path to a YAML file."""
    candidate = Path(name_or_path)
    if candidate.suffix in (".yaml", ".yml") or candidate.exists():
        if not candidate.is_file():
            raise ConfigError(kind, f"no such file {name_or_path!r}")
        return candidate
    shipped = config_dir() / kind / f"{name_or_path}.yaml"
    if not shipped.is_file():
        names = ", ".join(available(kind))
        raise ConfigError(kind, f"unknown name {name_or_path!r}; available: {names}")
    return shipped


def available(kind: str) -> list[str]:
    """Names of the shipped configs of one kind (scenes, envs, agents)."""
    return sorted(p.stem for p in (config_dir() / kind).glob("*.yaml"))
