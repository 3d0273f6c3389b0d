"""Argument types for every command: numbers in range and output folders that can be
written, checked when the command line is parsed, before any work starts.

Each raises argparse.ArgumentTypeError, which argparse reports as one line naming the
flag, with exit status 2.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path
from typing import Callable, Optional

from spreadgym.threads import MAX_THREADS


def integer(low: int, high: Optional[int] = None) -> Callable[[str], int]:
    """An int in [low, high] (no upper bound if high is None)."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not an integer") from None
        if value < low or (high is not None and value > high):
            span = f">= {low}" if high is None else f"in [{low}, {high}]"
            raise argparse.ArgumentTypeError(f"{value} is out of range; allowed: {span}")
        return value
    return parse


def real(low: float, high: float, low_open: bool = False) -> Callable[[str], float]:
    """A finite float in [low, high] ((low, high] if low_open)."""
    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
        below = value <= low if low_open else value < low
        if not math.isfinite(value) or below or value > high:
            span = f"{'(' if low_open else '['}{low:g}, {high:g}]"
            raise argparse.ArgumentTypeError(f"{text} is out of range; allowed: {span}")
        return value
    return parse


def output_folder(text: str) -> Path:
    """A folder that can be written (`spreadgym.out_folder.folder_problem`), checked
    without creating anything: the command makes it when it writes, so a refused or
    failed run leaves no empty folder behind."""
    from spreadgym.out_folder import folder_problem

    problem = folder_problem(Path(text))
    if problem:
        raise argparse.ArgumentTypeError(f"{text}: {problem}")
    return Path(text)


def force_flag(parser: argparse.ArgumentParser) -> None:
    """`--force`: write into an --out folder that holds other outputs (never over an input)."""
    parser.add_argument("--force", action="store_true",
                        help="write into --out even where it holds another command's outputs or files of the same "
                             "names (inputs are never written over)")


SEED = integer(0, 2**32 - 1)
COUNT = integer(1)
GRANULES = integer(1, 1_000_000)
THREADS = integer(1, MAX_THREADS)  # --threads of every command


def materials_file(text: str) -> Path:
    """`--materials FILE`: a user's materials file (the library's layout), read and checked
    here so a bad one is one line before any work starts."""
    from spreadgym.config.materials import load_library
    from spreadgym.errors import SpreadgymError

    try:
        load_library(extra=Path(text))
    except SpreadgymError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--materials: ")) from None
    return Path(text)


def add_materials_flag(parser: argparse.ArgumentParser) -> None:
    """The `--materials FILE` flag of every command that reads a scene."""
    parser.add_argument("--materials", type=materials_file, metavar="FILE",
                        help="your materials file (configs/materials.yaml's layout) merged over the library: its "
                             "fertilizers can be named in the scene or with --set fertilizer=NAME")


def add_device(parser: argparse.ArgumentParser) -> None:
    """`--device cpu|cuda`: where the compiled spinner runs (spreadgym.device)."""
    parser.add_argument("--device", choices=("cpu", "cuda"),
                        help="where the compiled spinner runs: cpu, or cuda "
                             "(an NVIDIA GPU; `pip install spreadgym[cuda]`) (default: SPREADGYM_DEVICE, else cpu)")
