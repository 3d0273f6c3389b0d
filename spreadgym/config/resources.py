"""Locating and reading the YAML files shipped under configs/ (package data)."""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from spreadgym.errors import ConfigError


class NumberLoader(yaml.SafeLoader):
    """YAML 1.1's safe loader, but `1e9` and `2e-4` are numbers (YAML 1.2 and Python agree)."""


NumberLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |\.[0-9_]+(?:[eE][-+][0-9]+)?
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def parse_yaml(text) -> Any:
    """Parse YAML text or a stream with `NumberLoader`."""
    return yaml.load(text, Loader=NumberLoader)  # noqa: S506 - a SafeLoader subclass


def config_dir() -> Path:
    """Directory of the shipped configs (works for editable installs and wheels)."""
    return Path(str(resources.files("spreadgym.configs")))


def read_yaml(path: Path) -> Any:
    """Parse a YAML file; a syntax error becomes a ConfigError naming the file."""
    try:
        with open(path, encoding="utf-8") as handle:
            return parse_yaml(handle)
    except FileNotFoundError as exc:
        raise ConfigError(str(path), "file not found") from exc
    except IsADirectoryError as exc:
        raise ConfigError(str(path), "is a folder, not a YAML file") from exc
    except UnicodeDecodeError as exc:
        raise ConfigError(str(path), f"not UTF-8 text (byte {exc.start})") from exc
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or type(exc).__name__
        raise ConfigError(str(path), f"not valid YAML{where}: {problem}") from exc


def resolve_named(kind: str, name_or_path: str) -> Path:
    """Find configs/<kind>/<name>.yaml, or accept a path to a YAML file.

    A shipped name wins over a folder of the same name in the working directory."""
    candidate = Path(name_or_path)
    shipped = config_dir() / kind / f"{name_or_path}.yaml"
    if candidate.suffix in (".yaml", ".yml") or candidate.is_file():
        if candidate.is_dir():
            raise ConfigError(kind, f"{name_or_path!r} is a folder; give a YAML file or a shipped name")
        if not candidate.is_file():
            raise ConfigError(kind, f"no such file {name_or_path!r}")
        return candidate
    if shipped.is_file():
        return shipped
    if candidate.is_dir():
        raise ConfigError(kind, f"{name_or_path!r} is a folder; give a YAML file or a shipped name")
    names = ", ".join(available(kind))
    raise ConfigError(kind, f"unknown name {name_or_path!r}; available: {names}")


def available(kind: str) -> list[str]:
    """Names of the shipped configs of one kind (scenes, envs, agents)."""
    return sorted(p.stem for p in (config_dir() / kind).glob("*.yaml"))
