"""The measured tray test: a CSV file of tray centres and caught masses.

Format: a header line naming the columns `x_m` (tray centre across the driving
direction, m, on the axis of `simulate --json`'s `trays.center_m`: x to the right of
the machine, 0 on its track) and `mass_g` (what the tray caught, g), optionally `pass`
(an integer lane index j: pass j drove along x = j W, W the scene's
`pattern.target_swath_m`, the same way as pass 0 for racetrack driving and the
opposite way on odd j for back-and-forth). Without `pass` every row is one pass,
j = 0. Lines starting with `#` and blank lines are skipped. Every problem is one line
naming the file's line number.
"""

from __future__ import annotations

import csv
import io
import math
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import numpy as np

from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError

MAX_FILE_BYTES = 1_000_000  # a tray test is a few hundred rows; this bounds memory and time
MIN_TRAYS = 5  # fewer trays carry no shape to fit
COLUMNS = ("x_m", "mass_g", "pass")
REQUIRED = ("x_m", "mass_g")
_GRID_TOL = 1e-6  # relative to the tray width: centres are typed with a few decimals


@dataclass(frozen=True)
class TrayTest:
    """Rows of a tray test (SI inside): tray centre x (m), caught mass (kg), pass lane index j."""

    x_m: np.ndarray
    mass_kg: np.ndarray
    lane: np.ndarray  # (n,) int
    tray_width_m: float
    source: str

    @property
    def count(self) -> int:
        return int(self.x_m.size)


def read_trays(path: str | Path, tray_width_m: float) -> TrayTest:
    """Parse and check a tray file; trays must sit on the grid i * `tray_width_m` (m)."""
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > MAX_FILE_BYTES:
            raise SpreadgymError(f"--trays: {brief(str(path))} is {size} bytes; allowed: at most {MAX_FILE_BYTES}")
        with open(path, "rb") as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise SpreadgymError(f"--trays: cannot read {brief(str(path))}: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise SpreadgymError(f"--trays: {brief(str(path))} line {line}: not UTF-8 text") from None
    return parse_trays(text, tray_width_m, str(path))


def parse_trays(text: str, tray_width_m: float, source: str = "trays") -> TrayTest:
    """`read_trays` on the file's text (`source` names it in errors)."""
    def fail(line: int, message: str) -> SpreadgymError:
        return SpreadgymError(f"--trays: {brief(source)} line {line}: {message}")

    rows = [(number, line) for number, line in enumerate(text.splitlines(), start=1)
            if line.strip() and not line.lstrip().startswith("#")]
    if not rows:
        raise SpreadgymError(f"--trays: {brief(source)}: no header line (expected columns x_m, mass_g[, pass])")
    header_line, header_text = rows[0]
    header = [name.strip() for name in next(csv.reader(io.StringIO(header_text)))]
    for name in header:
        if name not in COLUMNS:
            raise fail(header_line, f"unknown column {brief(name)}; allowed: {', '.join(COLUMNS)}")
    for name in REQUIRED:
        if name not in header:
            raise fail(header_line, f"missing column {name} (header: {brief(header_text)})")
    if len(set(header)) != len(header):
        raise fail(header_line, "a column is named twice")
    column = {name: header.index(name) for name in header}
    x, mass, lane, seen = [], [], [], {}
    for number, line in rows[1:]:
        cells = [cell.strip() for cell in next(csv.reader(io.StringIO(line)))]
        if len(cells) != len(header):
            raise fail(number, f"{len(cells)} values for {len(header)} columns")
        position = _number(cells[column["x_m"]], "x_m", fail, number)
        grams = _number(cells[column["mass_g"]], "mass_g", fail, number)
        if grams < 0:
            raise fail(number, f"mass_g {cells[column['mass_g']]} is negative; allowed: >= 0")
        j = 0
        if "pass" in column:
            text_j = cells[column["pass"]]
            try:
                j = int(text_j)
            except ValueError:
                raise fail(number, f"pass {brief(text_j)} is not a whole number (the lane index j)") from None
            if abs(j) > 1000:
                raise fail(number, f"pass {j} is out of range; allowed: -1000..1000")
        index = position / tray_width_m
        if abs(index - round(index)) > _GRID_TOL * max(1.0, abs(index)):
            raise fail(number, f"x_m {cells[column['x_m']]} is off the tray grid: centres at multiples of "
                               f"pattern.tray_width_m = {tray_width_m:g} m from the axis (set pattern.tray_width_m "
                               "to the trays' width)")
        key = (j, int(round(index)))
        if key in seen:
            raise fail(number, f"tray x_m = {position:g} m of pass {j} is given twice (also line {seen[key]})")
        seen[key] = number
        x.append(round(index) * tray_width_m)
        mass.append(grams * 1e-3)
        lane.append(j)
    closest = min((b - a for j in set(lane) for a, b in pairwise(sorted(xi for xi, li in zip(x, lane) if li == j))),
                  default=tray_width_m)
    if closest > tray_width_m * (1 + _GRID_TOL):
        raise fail(header_line, f"the closest trays are {closest:g} m apart but pattern.tray_width_m is "
                                f"{tray_width_m:g} m: neighbouring trays touch, so set pattern.tray_width_m to "
                                "the trays' width")
    if len(x) < MIN_TRAYS:
        raise fail(rows[-1][0], f"{len(x)} trays; allowed: at least {MIN_TRAYS}")
    if sum(m > 0 for m in mass) < MIN_TRAYS:
        raise fail(rows[-1][0], f"{sum(m > 0 for m in mass)} trays caught anything; at least {MIN_TRAYS} must")
    return TrayTest(np.asarray(x), np.asarray(mass), np.asarray(lane, dtype=np.int64), float(tray_width_m), source)


def _number(text: str, name: str, fail, line: int) -> float:
    try:
        value = float(text)
    except ValueError:
        raise fail(line, f"{name} {brief(text)} is not a number") from None
    if not math.isfinite(value):
        raise fail(line, f"{name} {brief(text)} is not finite")
    if abs(value) > 1e6:
        raise fail(line, f"{name} {brief(text)} is out of range; allowed: within +-1e6")
    return value


def write_trays(path: str | Path, test: TrayTest, comment: str = "") -> Path:
    """Write `test` in the tray-file format (masses in g; a `pass` column when there are several lanes)."""
    path = Path(path)
    lanes = bool(np.any(test.lane != 0))
    lines = [f"# {line}" for line in comment.splitlines()]
    lines.append("x_m,mass_g" + (",pass" if lanes else ""))
    for x, m, j in zip(test.x_m, test.mass_kg, test.lane):
        lines.append(f"{x:.6g},{m * 1e3:.6g}" + (f",{j}" if lanes else ""))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path
