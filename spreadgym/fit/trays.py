"""The measured tray test: a CSV file of tray centres and caught masses.

Format: a header line naming the columns `x` (tray centre across the driving direction,
on the axis of `simulate --json`'s `trays.center_m`: x to the right of the machine, 0 on
its track) and `mass` (what the tray caught), each with its unit, written `x_m`,
`x [m]` or `x (m)` (x in m, cm or mm; mass in g, kg or mg); optionally `pass` (an
integer lane index j: pass j drove along x = j W, W the scene's
`pattern.target_swath_m`, the same way as pass 0 for racetrack driving and the opposite
way on odd j for back-and-forth). Without `pass` every row is one pass, j = 0.

Separators: `,`, `;` or a tab, as the header uses them; with `;` or a tab a decimal
comma is read as a point (spreadsheet exports of continental Europe). Lines starting
with `#` and blank lines are skipped.

Trays may lie on any layout, regular or not, with gaps between them (a kit of a few
spaced trays): each tray catches what lands within half a `pattern.tray_width_m` of its
centre, so the trays of one pass must be at least that width apart. The likelihood
uses only the trays present.

Bounded before anything is computed: the file (1 MB, a regular file: no pipe or device,
which could block or never end), a line (10 000 characters), the trays (4 000, each
within 200 m of the machine). Every problem is one line naming the file's line number.
"""

from __future__ import annotations

import csv
import math
import os
import re
import stat
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError

MAX_FILE_BYTES = 1_000_000  # a tray test is a few hundred rows; this bounds memory and time
MAX_LINE_CHARS = 10_000  # a row is three numbers; a longer line is not a tray row
MAX_TRAYS = 4_000  # a row of 0.5 m trays 2 km long: beyond any test, and every per-tray structure stays small
MAX_REACH_M = 200.0  # no spreader throws further (a 50 m working width reaches about 30 m)
MIN_TRAYS = 5  # fewer trays carry no shape to fit
MIN_MASS_G = 1e-6  # a microgram: no balance weighs less; a positive catch below it is a typing slip
MAX_MASS_G = 1e6
MAX_LANE = 1000
SEPARATORS = (",", ";", "\t")
UNITS = {"x": {"m": 1.0, "cm": 0.01, "mm": 0.001}, "mass": {"g": 1.0, "kg": 1000.0, "mg": 0.001}}  # to m and g
COLUMNS = ("x", "mass", "pass")
_HEADER = re.compile(r"(?P<name>[a-z]+)(?:_(?P<unit>[a-z]+)|\s*\[\s*(?P<bracket>[a-z]+)\s*\]"
                     r"|\s*\(\s*(?P<paren>[a-z]+)\s*\))?")
_SPACING_TOL = 1e-6  # relative to the tray width: centres are typed with a few decimals


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
    """Parse and check a tray file of trays `tray_width_m` wide (m)."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)  # a named pipe must not block the open
    except OSError as exc:
        raise SpreadgymError(f"--trays: cannot read {brief(str(path))}: {exc.strerror or exc}") from None
    try:
        info = os.fstat(fd)
        if not stat.S_ISREG(info.st_mode):
            raise SpreadgymError(f"--trays: {brief(str(path))} is not a regular file (a folder, pipe or device); "
                                 "give a CSV file")
        if info.st_size > MAX_FILE_BYTES:
            raise SpreadgymError(f"--trays: {brief(str(path))} is {info.st_size} bytes; "
                                 f"allowed: at most {MAX_FILE_BYTES}")
        with os.fdopen(fd, "rb", closefd=False) as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        raise SpreadgymError(f"--trays: cannot read {brief(str(path))}: {exc.strerror or exc}") from None
    finally:
        os.close(fd)
    if len(raw) > MAX_FILE_BYTES:  # it grew while it was read
        raise SpreadgymError(f"--trays: {brief(str(path))} is over {MAX_FILE_BYTES} bytes; "
                             f"allowed: at most {MAX_FILE_BYTES}")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        line = raw[: exc.start].count(b"\n") + 1
        raise SpreadgymError(f"--trays: {brief(str(path))} line {line}: not UTF-8 text") from None
    return parse_trays(text, tray_width_m, str(path))


def parse_trays(text: str, tray_width_m: float, source: str = "trays") -> TrayTest:
    """`read_trays` on the file's text (`source` names it in errors); a leading byte-order
    mark (spreadsheets' "CSV UTF-8") is dropped, as reading the file as utf-8-sig drops it."""
    def fail(line: int, message: str) -> SpreadgymError:
        return SpreadgymError(f"--trays: {brief(source)} line {line}: {message}")

    text = text.removeprefix("\ufeff")
    rows = []
    for number, line in enumerate(text.splitlines(), start=1):
        if len(line) > MAX_LINE_CHARS:
            raise fail(number, f"longer than {MAX_LINE_CHARS} characters; allowed: at most {MAX_LINE_CHARS}")
        if "\0" in line:
            raise fail(number, "holds a NUL character: not a text file")
        if line.strip() and not line.lstrip().startswith("#"):
            rows.append((number, line))
            if len(rows) > MAX_TRAYS + 1:
                raise fail(number, f"more than {MAX_TRAYS} trays; allowed: at most {MAX_TRAYS}")
    if not rows:
        raise SpreadgymError(f"--trays: {brief(source)}: no header line (expected columns x_m, mass_g[, pass])")
    header_line, header_text = rows[0]
    separator = next((s for s in SEPARATORS[1:] if s in header_text), ",")
    names = _cells(header_text, separator, header_line, fail)
    column, scale = _header(names, header_line, fail)
    label = {name: names[index] for name, index in column.items()}  # as typed, for the messages
    x, mass, lane, seen = [], [], [], {}
    for number, line in rows[1:]:
        cells = _cells(line, separator, number, fail)
        if len(cells) != len(column):
            raise fail(number, f"{len(cells)} values for {len(column)} columns")
        position = _number(cells[column["x"]], label["x"], separator, fail, number) * scale["x"]
        grams = _number(cells[column["mass"]], label["mass"], separator, fail, number) * scale["mass"]
        if abs(position) > MAX_REACH_M:
            raise fail(number, f"{label['x']} {cells[column['x']]} is {abs(position):g} m from the machine; allowed: "
                               f"within {MAX_REACH_M:g} m (no spreader throws further)")
        if grams < 0:
            raise fail(number, f"{label['mass']} {cells[column['mass']]} is negative; allowed: >= 0")
        if 0 < grams < MIN_MASS_G or grams > MAX_MASS_G:
            raise fail(number, f"{label['mass']} {cells[column['mass']]} is out of range; allowed: 0 (an empty "
                               f"tray) or {MIN_MASS_G:g} to {MAX_MASS_G:g} g")
        j = _lane(cells[column["pass"]], fail, number) if "pass" in column else 0
        key = (j, position)
        if key in seen:
            raise fail(number, f"tray x = {position:g} m of pass {j} is given twice (also line {seen[key]})")
        seen[key] = number
        x.append(position)
        mass.append(grams * 1e-3)
        lane.append(j)
    if len(x) < MIN_TRAYS:
        raise fail(rows[-1][0], f"{len(x)} trays; allowed: at least {MIN_TRAYS}")
    if sum(m > 0 for m in mass) < MIN_TRAYS:
        raise fail(rows[-1][0], f"{sum(m > 0 for m in mass)} trays caught anything; at least {MIN_TRAYS} must")
    test = TrayTest(np.asarray(x, float), np.asarray(mass, float), np.asarray(lane, dtype=np.int64),
                    float(tray_width_m), source)
    _check_spacing(test, [number for number, _ in rows[1:]], fail)
    return test


def _cells(line: str, separator: str, number: int, fail) -> list[str]:
    try:
        return [cell.strip() for cell in next(csv.reader([line], delimiter=separator))]
    except csv.Error as exc:
        raise fail(number, f"not a CSV row ({exc})") from None


def _header(names: list[str], line: int, fail) -> tuple[dict[str, int], dict[str, float]]:
    """Column index and unit factor (to m and g) of each named column."""
    column, scale = {}, {}
    for index, text in enumerate(names):
        match = _HEADER.fullmatch(text.strip().lower())
        name = match["name"] if match else None
        if name not in COLUMNS:
            raise fail(line, f"unknown column {brief(text)}; allowed: x, mass (each with its unit, e.g. x_m, "
                             "mass_g, x [m], mass (g)) and pass")
        unit = match["unit"] or match["bracket"] or match["paren"]
        if name == "pass":
            if unit is not None:
                raise fail(line, f"column {brief(text)}: pass is a lane number and takes no unit")
        elif unit is None:
            raise fail(line, f"column {brief(text)} has no unit; write {name}_{'m' if name == 'x' else 'g'} or "
                             f"{name} [{'m' if name == 'x' else 'g'}] ({name} in {', '.join(UNITS[name])})")
        elif unit not in UNITS[name]:
            raise fail(line, f"column {brief(text)}: unknown unit {brief(unit)}; allowed: {', '.join(UNITS[name])}")
        if name in column:
            raise fail(line, f"column {name} is named twice")
        column[name] = index
        scale[name] = UNITS[name][unit] if name in UNITS else 1.0
    for name in ("x", "mass"):
        if name not in column:
            raise fail(line, f"missing column {name} (header: {brief(', '.join(names))}; expected x_m, mass_g[, pass])")
    return column, scale


def _number(text: str, name: str, separator: str, fail, line: int) -> float:
    typed = text.replace(",", ".", 1) if separator != "," and text.count(",") == 1 and "." not in text else text
    try:
        if "_" in typed:  # Python's float() reads 1_0 as 10: a spreadsheet's cell never means that
            raise ValueError
        value = float(typed)
    except ValueError:
        raise fail(line, f"{name} {brief(text)} is not a number") from None
    if not math.isfinite(value):
        raise fail(line, f"{name} {brief(text)} is not finite")
    return value


def _lane(text: str, fail, line: int) -> int:
    try:
        if "_" in text:  # as in `_number`
            raise ValueError
        j = int(text)
    except ValueError:
        raise fail(line, f"pass {brief(text)} is not a whole number (the lane index j)") from None
    if abs(j) > MAX_LANE:
        raise fail(line, f"pass {j} is out of range; allowed: -{MAX_LANE}..{MAX_LANE}")
    return j


def _check_spacing(test: TrayTest, lines: list[int], fail) -> None:
    """Trays of one pass may not overlap: their centres at least a tray width apart."""
    order = np.lexsort((test.x_m, test.lane))
    x, lane = test.x_m[order], test.lane[order]
    close = (lane[1:] == lane[:-1]) & (np.diff(x) < test.tray_width_m * (1 - _SPACING_TOL))
    if close.any():
        k = int(np.argmax(close))
        a, b = order[k], order[k + 1]
        raise fail(max(lines[a], lines[b]), f"trays at x = {test.x_m[a]:g} and {test.x_m[b]:g} m of pass "
                                            f"{test.lane[a]} overlap: their centres are closer than "
                                            f"pattern.tray_width_m = {test.tray_width_m:g} m (set it to the "
                                            "trays' width; spaced trays may leave gaps)")


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
