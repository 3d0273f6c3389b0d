"""Printing results for people (aligned tables) and for programs (JSON)."""

from __future__ import annotations

import json
import math
import sys
from typing import Any, Optional, Sequence


def _jsonable(value: Any) -> Any:
    """Convert numpy scalars/arrays to plain Python; NaN is refused, not printed."""
    if hasattr(value, "tolist"):
        value = value.tolist()
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        raise ValueError(f"refusing to write a non-finite number ({value}) to JSON")
    return value


def print_json(payload: Any, stream=None) -> None:
    """Write `payload` as indented JSON on stdout."""
    json.dump(_jsonable(payload), stream or sys.stdout, indent=2)
    (stream or sys.stdout).write("\n")


def format_table(rows: Sequence[Sequence[Any]], header: Sequence[str]) -> str:
    """Left-aligned text table; floats get 4 significant digits."""

    def cell(value: Any) -> str:
        if value is None:
            return "-"
        if isinstance(value, float):
            return f"{value:.4g}"
        return str(value)

    text = [list(map(str, header))] + [[cell(v) for v in row] for row in rows]
    widths = [max(len(r[i]) for r in text) for i in range(len(header))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in text]
    lines.insert(1, "  ".join("-" * w for w in widths))
    return "\n".join(lines)


def decimals_supported(error: float) -> int:
    """Decimals that a standard error supports: its first significant digit's place (the
    error rounded to one significant digit first, so 0.096 reads as 0.1)."""
    if not (math.isfinite(error) and error > 0):
        return 1
    rounded = float(f"{error:.0e}")
    return max(0, -math.floor(math.log10(rounded)))


def with_error(value: float, error: Optional[float], unit: str = "") -> str:
    """'7.4 +- 0.2 %': the value with no more digits than its standard error supports
    (one decimal where no error is known)."""
    places = decimals_supported(error) if error is not None else 1
    shown = f"{value:.{places}f}" + (f" +- {error:.{places}f}" if error is not None else "")
    return f"{shown} {unit}".rstrip()
