"""Locating and reading YAML: the files shipped under configs/ (package data), scene and
config files given by path, and `--set` values.

YAML is data with limits, checked while it is read, so that no file can hang the reader
or fill the memory: a file holds at most `MAX_YAML_BYTES`; collections nest at most
`MAX_YAML_DEPTH` deep; and the document, with every alias counted as the copy it stands
for, has at most `MAX_YAML_NODES` nodes (a "billion laughs" of nested aliases is refused
before anything is built from it). A recursive alias is refused too.
"""

from __future__ import annotations

import re
from importlib import resources
from pathlib import Path
from typing import Any

import yaml

from spreadgym.errors import ConfigError

MAX_YAML_BYTES = 1_000_000  # a scene is about 1.5 kB; the material library under 4 kB
MAX_YAML_DEPTH = 50  # nested lists and mappings; a scene nests 4 deep
MAX_YAML_NODES = 10_000  # scalars, lists and mappings, aliases counted as what they expand to; configs hold <= 255


class YamlLimitError(yaml.MarkedYAMLError):
    """A YAML text beyond one of the limits (depth, expanded size, recursive alias)."""


class NumberLoader(yaml.SafeLoader):
    """YAML 1.1's safe loader, but `1e9` and `2e-4` are numbers (YAML 1.2 and Python agree),
    and the document stays within `MAX_YAML_DEPTH` and `MAX_YAML_NODES`."""

    _depth = 0
    _nodes = 0

    def compose_node(self, parent, index):
        if self._depth >= MAX_YAML_DEPTH:
            raise YamlLimitError(problem=f"nested deeper than {MAX_YAML_DEPTH} levels; allowed: at most "
                                         f"{MAX_YAML_DEPTH}", problem_mark=self.peek_event().start_mark)
        self._nodes += 1
        if self._nodes > MAX_YAML_NODES:  # stop reading at once: a long flat list costs no more than the limit
            raise YamlLimitError(problem=_too_many(), problem_mark=self.peek_event().start_mark)
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def compose_document(self):
        node = super().compose_document()
        _expanded_size(node, 0, {})
        return node

    def construct_mapping(self, node, deep=False):
        """A mapping whose own keys are distinct: a key given twice (the second silently
        winning in plain YAML) is an error at its line; keys a merge (`<<`) brings may be
        overridden, as YAML intends."""
        if isinstance(node, yaml.MappingNode):
            seen = set()
            for key, _ in node.value:
                if isinstance(key, yaml.ScalarNode) and key.tag != "tag:yaml.org,2002:merge":
                    if key.value in seen:
                        raise yaml.constructor.ConstructorError(
                            None, None, f"the key {key.value!r} is given twice in one mapping; give it once",
                            key.start_mark)
                    seen.add(key.value)
        return super().construct_mapping(node, deep)


def _too_many() -> str:
    return f"holds more than {MAX_YAML_NODES} values (aliases counted as copies); allowed: at most {MAX_YAML_NODES}"


def _expanded_size(node: yaml.Node, depth: int, seen: dict) -> int:
    """Nodes below and at `node` with aliases expanded; refuses a document beyond the
    limits (each distinct node is measured once, so a bomb costs its text, not its expansion)."""
    known = seen.get(id(node))
    if known is not None:
        size, below = known
        if size is None:
            raise YamlLimitError(problem="an alias refers to a collection that contains it (a recursive "
                                         "alias); not allowed", problem_mark=node.start_mark)
        if depth + below > MAX_YAML_DEPTH:
            raise YamlLimitError(problem=f"aliases nest deeper than {MAX_YAML_DEPTH} levels; allowed: at most "
                                         f"{MAX_YAML_DEPTH}", problem_mark=node.start_mark)
        return size
    seen[id(node)] = (None, 0)
    if isinstance(node, yaml.SequenceNode):
        children = node.value
    elif isinstance(node, yaml.MappingNode):
        children = [part for pair in node.value for part in pair]
    else:
        children = []
    size, below = 1, 0
    for child in children:
        size += _expanded_size(child, depth + 1, seen)
        below = max(below, 1 + seen[id(child)][1])
        if size > MAX_YAML_NODES:
            raise YamlLimitError(problem=_too_many(), problem_mark=node.start_mark)
    seen[id(node)] = (size, below)
    return size


NumberLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
                  |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
                  |\.[0-9_]+(?:[eE][-+][0-9]+)?
                  |[-+]?\.(?:inf|Inf|INF)
                  |\.(?:nan|NaN|NAN))$""", re.X),
    list("-+0123456789."))


def parse_yaml(text: str) -> Any:
    """Parse YAML text with `NumberLoader` (a text over `MAX_YAML_BYTES` is a YamlLimitError)."""
    if len(text) > MAX_YAML_BYTES:
        raise YamlLimitError(problem=f"{len(text)} characters; allowed: at most {MAX_YAML_BYTES}")
    return yaml.load(text, Loader=NumberLoader)  # noqa: S506 - a SafeLoader subclass


def config_dir() -> Path:
    """Directory of the shipped configs (works for editable installs and wheels)."""
    return Path(str(resources.files("spreadgym.configs")))


def read_yaml(path: Path) -> Any:
    """Parse a YAML file of at most `MAX_YAML_BYTES`; a syntax error or a limit passed
    becomes a ConfigError naming the file."""
    try:
        with open(path, "rb") as handle:
            data = handle.read(MAX_YAML_BYTES + 1)  # never more, whatever the file (or /dev/zero)
        if len(data) > MAX_YAML_BYTES:
            raise ConfigError(str(path), f"larger than {MAX_YAML_BYTES} bytes (1 MB); allowed: at most "
                                         f"{MAX_YAML_BYTES} bytes")
        return parse_yaml(data.decode("utf-8"))
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
        if isinstance(exc, YamlLimitError):
            raise ConfigError(str(path), f"YAML{where} {problem}") from None
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
