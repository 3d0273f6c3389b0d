"""The `spreadgym` console script: parse the command name, import its module, run it.

Bad input (a SpreadgymError or an argparse error) exits with status 2 and no traceback,
after one line on stderr naming the command, the flag or key and what is allowed.
A closed stdout (`spreadgym compare | head`) ends the command quietly with status 141
(128 + SIGPIPE, what a shell reports for a tool killed by the broken pipe).
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys
from types import ModuleType
from typing import Optional, Sequence

from spreadgym.cli import COMMANDS
from spreadgym.errors import SpreadgymError

EXIT_BAD_INPUT = 2
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141


def _requested(argv: Sequence[str]) -> Optional[str]:
    """The command named on the command line (the first word that is not an option)."""
    return next((word for word in argv if not word.startswith("-")), None)


class OneLineParser(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line ("spreadgym simulate: error:
    argument --precision: ...") instead of the whole usage block before it (`--help`
    shows that). Sub-command parsers are made of the same class."""

    def error(self, message: str):
        self.exit(EXIT_BAD_INPUT, f"{self.prog}: error: {message}\n")


def build_parser(argv: Sequence[str] = ()) -> tuple[argparse.ArgumentParser, Optional[ModuleType]]:
    """The parser, with the arguments of the requested command only (its module imported)."""
    parser = OneLineParser(
        prog="spreadgym",
        description="Simulate centrifugal fertilizer spreaders, score spread patterns, design spinners.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    wanted = _requested(argv)
    module = None
    for name, (module_name, help_text) in COMMANDS.items():
        command_parser = sub.add_parser(name, help=help_text, description=help_text)
        if name == wanted:
            module = importlib.import_module(module_name)
            module.add_arguments(command_parser)
    return parser, module


def main(argv: Optional[list[str]] = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    parser, module = build_parser(argv)
    try:
        args = parser.parse_args(argv)
    except SystemExit as ended:  # a usage error (already printed, one line: OneLineParser) or --help
        return int(ended.code or 0)
    try:
        code = int(module.run(args) or 0)
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
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
