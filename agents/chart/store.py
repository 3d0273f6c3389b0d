"""A chart folder that resumes: the manifest of what the chart is, one file per finished cell.

DIR/manifest.json holds the `ChartSpec` (scene, fertilizers, widths, driving, budget,
granules, seed, models); DIR/cells/<key>.json holds one finished cell. Every file is
written whole or not at all (`spreadgym.out_folder.write_atomic`), so an
interrupted chart leaves only finished cells. A folder whose manifest differs from the
spec being run is refused, naming what changed, rather than mixing two charts.

A cell file is reused only when it is the record of its cell (`record_problem`: the
schema, the cell's fertilizer, width and driving, finite values in their ranges, the
settings matching their unit vector); any other file there is recomputed and replaced.
Before any work, `probe` refuses a folder where a file due after the work could not be
written, so no computed cell is lost to a folder that cannot take it, and one that
holds another command's outputs (the output-folder rule of every command,
`spreadgym.out_folder`; the manifest marks a chart folder written before stamps).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, Optional, Sequence

from spreadgym.agents.chart.spec import MANIFEST_DEFAULTS, Cell, ChartSpec
from spreadgym.agents.chart.sweep import points_of
from spreadgym.config.base import brief
from spreadgym.errors import SpreadgymError
from spreadgym.out_folder import OutFolder, folder_problem, write_atomic
from spreadgym.report import print_json

MANIFEST = "manifest.json"
CELLS = "cells"
CHART_FILES = ("chart.csv", "chart.json", "chart.md", "chart.png", "chart.html")
HEAD = ["fertilizer", "width_m", "driving"]  # a row: the cell, its settings (units in their names), the results
TAIL = ["cv_percent", "cv_standard_error_percent", "cv_p90_percent", "cv_p90_standard_error_percent",
        "effective_swath_m", "cv_search_percent", "simulations", "wall_s"]
DETAIL = {"key", "unit_settings", "search_unit_settings", "objective", "method", "cv_search_standard_error_percent",
          "search_evaluations", "rescores", "ties", "tie_set", "sweep", "search_agrees_within_2se", "meets_threshold",
          "verification", "verification_p90", "trays", "cv_curve"}
PNG_START, PNG_END = b"\x89PNG\r\n\x1a\n", b"IEND\xaeB`\x82"


def json_text(payload) -> str:
    import io

    buffer = io.StringIO()
    print_json(payload, buffer)
    return buffer.getvalue()


def _plain(payload):
    """`payload` as it reads back from JSON (tuples become lists)."""
    return json.loads(json_text(payload))


def _changes(stored: dict, wanted: dict) -> list[str]:
    changed = []
    for key in sorted(set(stored) | set(wanted)):
        before, after = (m.get(key, MANIFEST_DEFAULTS.get(key)) for m in (stored, wanted))
        if before != after:
            if key == "scene":
                changed.append("the scene")
            else:
                changed.append(f"{key} {brief(before)} -> {brief(after)}")
    return changed


class ChartStore:
    """The folder of one chart."""

    def __init__(self, out: Path, spec: ChartSpec):
        self.out = Path(out)
        self.spec = spec

    @property
    def cells_dir(self) -> Path:
        return self.out / CELLS

    def cell_path(self, cell: Cell, suffix: str = ".json") -> Path:
        return self.cells_dir / f"{cell.key}{suffix}"

    def folder(self, force: bool = False, inputs: Sequence[Path] = ()) -> OutFolder:
        """The chart folder as an output folder (`spreadgym.out_folder`): the chart's files
        and every cell's record and picture, resumed (kept when interrupted)."""
        files = [MANIFEST, *CHART_FILES,
                 *(f"{CELLS}/{cell.key}{suffix}" for cell in self.spec.cells for suffix in (".json", ".png"))]
        return OutFolder(self.out, "chart", files, inputs, force, replaces_own=True, keeps_partial=True,
                         marker=MANIFEST)

    def probe(self, force: bool = False, inputs: Sequence[Path] = ()) -> None:
        """Refuse, writing nothing, a folder where a file of the chart could not be written
        (the folders, or the nearest one that exists, must take a file, and no file of the
        chart may be a folder), that holds another command's outputs (unless `force`), or
        where an input would be written over."""
        self.folder(force, inputs).check()
        if self.cells_dir.exists():
            problem = folder_problem(self.cells_dir)
            if problem:
                raise SpreadgymError(f"--out {self.out}: {CELLS} {problem}")

    def check_manifest(self) -> None:
        """Refuse, writing nothing, a folder that holds another chart (or cells without a manifest)."""
        wanted = _plain(self.spec.manifest())
        path = self.out / MANIFEST
        if path.exists():
            try:
                stored = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise SpreadgymError(f"--out {self.out}: {MANIFEST} is unreadable ({brief(str(exc))[1:-1]}); "
                                     "use another folder or remove it") from None
            changed = _changes(stored, wanted) if isinstance(stored, dict) else ["the manifest"]
            if changed:
                raise SpreadgymError(f"--out {self.out} holds a chart of other settings ({'; '.join(changed)}); "
                                     "rerun with the same scene and flags to resume, or use another --out")
        elif self.cells_dir.is_dir() and any(self.cells_dir.glob("*.json")):
            raise SpreadgymError(f"--out {self.out}: cells/ has results but no {MANIFEST}; use another folder")

    def open(self) -> None:
        """Claim the folder for this spec (after `check_manifest`): write the manifest if missing."""
        if not (self.out / MANIFEST).exists():
            write_atomic(self.out / MANIFEST, json_text(_plain(self.spec.manifest())))

    def finished(self) -> tuple[dict[str, dict], dict[str, str]]:
        """(key -> stored cell for every cell of the spec whose file is its record, key -> why
        the file there is not, for the cells whose file is run again and replaced)."""
        done, rejected = {}, {}
        for cell in self.spec.cells:
            record, problem = self.load(cell)
            if record is not None:
                done[cell.key] = record
            elif problem is not None:
                rejected[cell.key] = problem
        return done, rejected

    def load(self, cell: Cell) -> tuple[Optional[dict], Optional[str]]:
        """(the cell's stored record, None), or (None, why the file there is not its record),
        or (None, None) where there is no file."""
        path = self.cell_path(cell)
        if not path.is_file():
            return None, None
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            return None, f"unreadable ({type(exc).__name__})"
        problem = record_problem(self.spec, cell, record)
        return (record, None) if problem is None else (None, problem)

    def picture_ok(self, cell: Cell) -> bool:
        """Whether the cell's picture is a whole PNG file (else it is drawn again)."""
        path = self.cell_path(cell, ".png")
        try:
            with open(path, "rb") as handle:
                start = handle.read(len(PNG_START))
                handle.seek(max(0, path.stat().st_size - len(PNG_END)))
                return start == PNG_START and handle.read() == PNG_END
        except OSError:
            return False

    def save(self, cell: Cell, record: dict) -> Path:
        return write_atomic(self.cell_path(cell), json_text(record))


def _real(value: Any, low: float = -math.inf, high: float = math.inf) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
            and low <= value <= high)


def _reals(values: Any, low: float = -math.inf) -> bool:
    return isinstance(values, list) and all(_real(v, low) for v in values)


def _tie_problem(detail: dict, size: int) -> Optional[str]:
    """Why the record's tie set and sweep block are not whole, or None."""
    tie, swept = detail["tie_set"], detail["sweep"]
    points = tie.get("points") if isinstance(tie, dict) else None
    if not (isinstance(points, list) and points and all(
            isinstance(p, dict) and _reals(p.get("unit_settings")) and len(p["unit_settings"]) == size
            and all(-1.0 <= u <= 1.0 for u in p["unit_settings"]) for p in points)):
        return "its tie set is not recorded"
    if not all(isinstance(tie.get(k), int) and 0 <= tie[k] < len(points) for k in ("best", "search_pick")):
        return "its tie set's best or search pick is not one of its points"
    if detail["search_unit_settings"] != points[tie["search_pick"]]["unit_settings"]:
        return "its search pick is not in its tie set"
    at = swept.get("pick") if isinstance(swept, dict) else tie["search_pick"]
    candidates = ((swept.get("repair") or {}).get("candidates", []) if isinstance(swept, dict) else [])
    if not (isinstance(candidates, list) and all(
            isinstance(c, dict) and isinstance(c.get("tied"), bool) and _reals(c.get("unit_settings"))
            and len(c["unit_settings"]) == size and all(-1.0 <= u <= 1.0 for u in c["unit_settings"])
            for c in candidates)):
        return "its repair's candidates are not recorded"
    points = points_of(tie, candidates)
    if swept is not None and not (isinstance(at, int) and 0 <= at < len(points)):
        return "its sweep is not recorded"
    if detail["unit_settings"] != points[at]["unit_settings"]:
        return "its settings are not its pick's"
    return None


def record_problem(spec: ChartSpec, cell: Cell, record: Any) -> Optional[str]:
    """Why `record` is not a finished record of `cell` in `spec`, or None when it is."""
    if not (isinstance(record, dict) and set(record) == {"row", "detail"} and isinstance(record["row"], dict)
            and isinstance(record["detail"], dict)):
        return "not a cell record ({row, detail})"
    row, detail = record["row"], record["detail"]
    space = spec.space(spec.cell_scene(cell))
    if list(row) != HEAD + space.names + TAIL or set(detail) != DETAIL:
        return "its columns are not the chart's"
    if (row["fertilizer"], row["width_m"], row["driving"], detail["key"]) != (
            cell.fertilizer, cell.width_m, spec.driving, cell.key):
        return "it is another cell's"
    unit = detail["unit_settings"]
    if not (_reals(unit) and len(unit) == space.size and all(-1.0 <= u <= 1.0 for u in unit)):
        return "its unit settings are not in the box"
    if space.values(unit) != {name: row[name] for name in space.names}:
        return "its settings do not match its unit settings"
    problem = _tie_problem(detail, space.size)
    if problem:
        return problem
    optional = ("cv_percent", "cv_standard_error_percent", "cv_p90_standard_error_percent", "cv_search_percent")
    if not all(row[k] is None or _real(row[k], 0.0) for k in optional):
        return "a CV is not a finite number >= 0"
    if not all(_real(row[k], 0.0) for k in ("cv_p90_percent", "effective_swath_m", "wall_s")):
        return "a result is not a finite number >= 0"
    if (detail["objective"], detail["method"]) != (spec.objective, spec.method):
        return "its objective or method is not the spec's"
    if not (isinstance(row["simulations"], int)
            and spec.verify_simulations <= row["simulations"] <= spec.max_simulations):
        return "its simulation count is not the spec's"
    trays, curve = detail["trays"], detail["cv_curve"]
    if not (isinstance(trays, dict) and _reals(trays.get("center_m")) and _reals(trays.get("mass_kg"), 0.0)
            and len(trays["center_m"]) == len(trays["mass_kg"]) > 0):
        return "its trays are not finite"
    if not (isinstance(curve, dict) and _reals(curve.get("bout_width_m"), 0.0)
            and isinstance(curve.get("cv_percent"), list)
            and all(v is None or _real(v, 0.0) for v in curve["cv_percent"])
            and len(curve["bout_width_m"]) == len(curve["cv_percent"])):
        return "its CV curve is not finite"
    verification = detail["verification"]
    if not (isinstance(verification, dict) and isinstance(verification.get("model"), str)
            and isinstance(verification.get("granules"), int)):
        return "its verification is not recorded"
    p90 = detail["verification_p90"]
    if not (isinstance(p90, dict) and _reals(p90.get("cv_draws_percent"), 0.0)
            and len(p90["cv_draws_percent"]) == spec.variability["verify_draws"]
            and p90.get("cv_percent") == row["cv_p90_percent"]):
        return "its p90 verification is not recorded"
    return None
