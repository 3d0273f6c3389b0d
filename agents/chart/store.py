"""A chart folder that resumes: the manifest of what the chart is, one file per finished cell.

DIR/manifest.json holds the `ChartSpec` (scene, fertilizers, widths, driving, budget,
granules, seed, models); DIR/cells/<key>.json holds one finished cell. Every file is
written whole or not at all (a temporary file renamed over the target), so an
interrupted chart leaves only finished cells. A folder whose manifest differs from the
spec being run is refused, naming what changed, rather than mixing two charts.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Optional

from spreadgym.agents.chart.spec import Cell, ChartSpec
from spreadgym.errors import SpreadgymError
from spreadgym.report import print_json

MANIFEST = "manifest.json"
CELLS = "cells"


def write_atomic(path: Path, content: str | bytes) -> Path:
    """Write `content` (text as UTF-8, or bytes) to `path` whole: a temporary file beside
    it, renamed over it."""
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.name}.partial")
    data = content.encode("utf-8") if isinstance(content, str) else content
    with open(partial, "wb") as handle:
        handle.write(data)
        handle.flush()
        os.fsync(handle.fileno())
    os.replace(partial, path)
    return path


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
        if stored.get(key) != wanted.get(key):
            if key == "scene":
                changed.append("the scene")
            else:
                changed.append(f"{key} {stored.get(key)!r} -> {wanted.get(key)!r}")
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

    def open(self) -> None:
        """Claim the folder for this spec: write the manifest, or check the one there."""
        wanted = _plain(self.spec.manifest())
        path = self.out / MANIFEST
        if path.exists():
            try:
                stored = json.loads(path.read_text(encoding="utf-8"))
            except (OSError, ValueError) as exc:
                raise SpreadgymError(f"--out {self.out}: {MANIFEST} is unreadable ({exc}); "
                                     "use another folder or remove it") from None
            changed = _changes(stored, wanted) if isinstance(stored, dict) else ["the manifest"]
            if changed:
                raise SpreadgymError(f"--out {self.out} holds a chart of other settings ({'; '.join(changed)}); "
                                     "rerun with the same scene and flags to resume, or use another --out")
            return
        if self.cells_dir.is_dir() and any(self.cells_dir.glob("*.json")):
            raise SpreadgymError(f"--out {self.out}: cells/ has results but no {MANIFEST}; use another folder")
        write_atomic(path, json_text(wanted))

    def finished(self) -> dict[str, dict]:
        """key -> stored cell, for every cell of the spec that has a complete file."""
        done = {}
        for cell in self.spec.cells:
            record = self.load(cell)
            if record is not None:
                done[cell.key] = record
        return done

    def load(self, cell: Cell) -> Optional[dict]:
        path = self.cell_path(cell)
        if not path.is_file():
            return None
        try:
            record = json.loads(path.read_text(encoding="utf-8"))
        except ValueError:
            return None  # not ours to trust: the cell is run again and the file replaced
        return record if isinstance(record, dict) and "row" in record else None

    def save(self, cell: Cell, record: dict) -> Path:
        return write_atomic(self.cell_path(cell), json_text(record))
