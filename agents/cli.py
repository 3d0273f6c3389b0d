"""The `spreadgym` console script.

It lives in the top layer because it mounts the subcommands of all three layers.
Subcommand modules are imported lazily so `spreadgym materials` does not load torch.
Bad input (a SpreadgymError or an argparse error) exits with status 2 and no traceback.
A closed stdout (`spreadgym compare | head`) ends the command quietly with status 141
(128 + SIGPIPE, what a shell reports for a tool killed by the broken pipe).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from types import ModuleType

from spreadgym.agents.commands import AGENT_COMMANDS
from spreadgym.commands import CORE_COMMANDS
from spreadgym.errors import SpreadgymError


EXIT_BROKEN_PIPE = 141


def _load(module_names: tuple[str, ...]) -> list[ModuleType]:
    return [importlib.import_module(name) for name in module_names]


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
        code = int(commands[args.command].run(args) or 0)
        sys.stdout.flush()  # a closed pipe shows up here, not at interpreter exit
        return code
    except BrokenPipeError:
        # Whoever read stdout stopped reading: not an error of the command. Point stdout
        # at /dev/null so the flush at exit does not raise again.
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)
        except (AttributeError, OSError, ValueError):  # stdout without a file descriptor
            pass
        return EXIT_BROKEN_PIPE
    except SpreadgymError as exc:
        print(f"spreadgym {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
