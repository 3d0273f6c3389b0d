"""`spreadgym demo`: the README's main job (provisional: simulate the paper spinner)."""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "demo"
HELP = "the main job: the paper's spinner, its spread pattern and pictures"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--out", type=Path, default=Path("out/demo"), help="folder for tables and pictures")


def run(args: argparse.Namespace) -> int:
    from spreadgym.commands import simulate

    return simulate.run(argparse.Namespace(scene="paper", overrides=[], model="auto", json=False, plot=args.out))
