"""The `spreadgym` console script.

It lives in the top layer because it mounts the subcommands of all three layers.
Subcommand modules are imported lazily so `spreadgym materials` does not load torch.
Bad input (a SpreadgymError or an argparse error) exits with status 2 and no traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from types import ModuleType

from spreadgym.agents.commands import AGENT_COMMANDS
from spreadgym.commands import CORE_COMMANDS
from spreadgym.errors import SpreadgymError


def _load(module_names: tuple[str, ...]) -> list[ModuleType]:
    modules = []
    for name in module_names:
        try:
            modules.append(importlib.import_module(name))
        except ModuleNotFoundError as exc:
            if exc.name != name:  # a real missing dependency, not a not-yet-written command
                raise
    return modules


def build_parser() -> tuple[argparse.ArgumentParser, dict[str, ModuleType]]:
    parser = argparse.ArgumentParser(
        prog="spreadgym",
        description="Simulate centrifugal fertilizer spreaders, score spread patterns, design spinners.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    commands = {}
    for module in _load(CORE_COMMANDS) + _load(AGENT_COMMANDS):
        command_parser = sub.add_parser(module.NAME, help=module.HELP, description=module.HELP)
        module.add_arguments(command_parser)
        commands[module.NAME] = module
    return parser, commands


def main(argv: list[str] | None = None) -> int:
    parser, commands = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(commands[args.command].run(args) or 0)
    except SpreadgymError as exc:
        print(f"spreadgym {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
