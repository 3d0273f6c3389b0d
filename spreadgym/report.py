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


def stamp() -> str:
    """What a printed record carries to say when and by what it was made: 'spreadgym 0.1.0, 2026-11-27 14:05'."""
    from datetime import datetime

    from spreadgym import __version__

    return f"spreadgym {__version__}, {datetime.now().strftime('%Y-%m-%d %H:%M')}"


def machine_lines(scene) -> list[tuple[str, str]]:
    """The machine of a scene in a record's words (label, text): disc, vanes, plates, second disc, trays."""
    disc, vanes = scene.spinner, scene.vanes
    inner = vanes.per_vane("inner_radius_m")
    outer = vanes.outer_radius_m or disc.radius_m
    lines = [("machine", scene.name + (f": {scene.description}" if scene.description else "")),
             ("disc", f"{2000 * disc.radius_m:.0f} mm, {disc.direction}, {1000 * disc.height_m:.0f} mm above ground, "
                      f"{disc.material}" + (f", cone {disc.cone_deg:g}°" if disc.cone_deg else "")),
             ("vanes", f"{vanes.count}, from {1000 * min(inner):.0f} to {1000 * outer:.0f} mm, "
                       f"{vanes.material or disc.material}")]
    if scene.twin is not None:
        lines.append(("second disc", f"{scene.twin.spacing_m:g} m beside the first"))
    for i, plate in enumerate(scene.deflectors):
        lines.append((f"plate {i}", f"{1000 * plate.length_m:.0f} mm at ({plate.x_m:g}, {plate.y_m:g}) m, "
                                    f"{plate.material}"))
    lines.append(("trays", f"{scene.pattern.tray_width_m:g} m wide, CV threshold "
                           f"{scene.pattern.cv_threshold_percent:g} %"))
    return lines


SETTING_LABELS = {"spinner.rpm": "disc speed", "vanes.pitch_deg": "vane pitch", "feed.radius_m": "drop radius",
                  "feed.angle_deg": "drop angle", "pattern.target_swath_m": "working width",
                  "pattern.driving": "driving"}


def setting_label(key: str) -> str:
    """A dialled setting's name in a record's words ('vanes.pitch_deg.2' is 'vane 2 pitch')."""
    parts = key.split(".")
    if parts[0] == "deflectors":
        return f"plate {parts[1]} angle"
    if key.startswith("vanes.pitch_deg."):
        return f"vane {parts[-1]} pitch"
    return SETTING_LABELS.get(key, key)


def setting_text(key: str, value) -> str:
    """A dialled setting's value as an operator dials it: whole rpm, tenths of a degree, millimetres."""
    if key == "spinner.rpm":
        return f"{value:.0f} rpm"
    if key.endswith("_deg") or ".pitch_deg." in key:
        return f"{value:.1f}°"
    if key == "feed.radius_m":
        return f"{1000 * value:.0f} mm"
    return f"{value:g} m" if key.endswith("_m") else str(value)


def setting_lines(scene) -> list[tuple[str, str, str]]:
    """Every setting an operator dials on the scene's machine (scene key, label, value): disc speed, vane pitch
    (one per vane where the scene gives one per vane), drop point, each plate's angle, working width and driving."""
    pitch = scene.vanes.pitch_deg
    pitches = [(f"vanes.pitch_deg.{k}", p) for k, p in enumerate(pitch)] if isinstance(pitch, list) else \
        [("vanes.pitch_deg", pitch)]
    values = [("spinner.rpm", scene.spinner.rpm), *pitches, ("feed.radius_m", scene.feed.radius_m),
              ("feed.angle_deg", scene.feed.angle_deg),
              *[(f"deflectors.{i}.angle_deg", plate.angle_deg) for i, plate in enumerate(scene.deflectors)],
              ("pattern.target_swath_m", scene.pattern.target_swath_m), ("pattern.driving", scene.pattern.driving)]
    return [(key, setting_label(key), setting_text(key, value)) for key, value in values]


def swath_text(metrics: dict) -> str:
    """The effective swath of simulate's JSON in words that do not read as good news when it is not: none where
    no width of two trays or more stays under the threshold (one tray always does: its CV is 0), and a warning
    where the CV at the working width is over the threshold though a wider width dips under it again."""
    swath, width = metrics["effective_swath_m"], metrics["target_swath_m"]
    threshold, cv = metrics["cv_threshold_percent"], metrics["cv_percent_at_target"]
    if swath < 2 * metrics["tray_width_m"] - 1e-9:
        return f"none: no working width of two trays or more stays under {threshold:g} %"
    if cv is None or cv > threshold:
        at = "nothing landed" if cv is None else f"the CV is {cv:.1f} %"
        if swath > width:
            return (f"not at {width:g} m: {at} there, over {threshold:g} % (the CV dips under it again at "
                    f"{swath:g} m, a wider width)")
        return f"{swath:g} m, narrower than the {width:g} m working width ({at} there, over {threshold:g} %)"
    return f"{swath:g} m (CV <= {threshold:g} % up to it)"
