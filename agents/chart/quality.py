"""Whether a chart is one an operator can follow and trust (issue 31's targets), read off
finished charts, and the `make bench` entry that runs them.

* Robust: the share of cells whose verified p90 CV is at most `P90_RATIO` times their
  verified nominal CV, and the cells whose nominal CV is at most `NOMINAL_OK_PERCENT` but
  whose p90 exceeds `P90_CAP_PERCENT`.
* Steady rows: a reversal is an interior width of a row where a setting turns (it rose
  from the narrower width and falls to the wider one, or the other way round); its size
  is the smaller of the two steps. Reversals larger than `RPM_REVERSAL` (relative to the
  setting at the turning width) in the disc speed, or `PITCH_REVERSAL_DEG` in a pitch,
  count against the target.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Callable, Optional

P90_RATIO = 1.5
NOMINAL_OK_PERCENT = 10.0
P90_CAP_PERCENT = 15.0
RPM_REVERSAL = 0.05
PITCH_REVERSAL_DEG = 3.0


def reversals(values: list[float]) -> list[tuple[int, float]]:
    """(index, size) of every turn in `values` (ordered by width): the smaller step either side."""
    out = []
    for i in range(1, len(values) - 1):
        before, after = values[i] - values[i - 1], values[i + 1] - values[i]
        if before * after < 0:
            out.append((i, min(abs(before), abs(after))))
    return out


def row_reversals(rows: list[dict], fertilizer: str) -> dict:
    """The rpm and pitch reversals over the targets' sizes along one fertilizer's row."""
    mine = sorted((r for r in rows if r["fertilizer"] == fertilizer), key=lambda r: r["width_m"])
    rpm = [r["rpm"] for r in mine]
    pitches = [k for k in (mine[0] if mine else {}) if k.endswith("pitch_deg")]
    big_rpm = [(mine[i]["width_m"], size / rpm[i]) for i, size in reversals(rpm) if size > RPM_REVERSAL * rpm[i]]
    big_pitch = [(mine[i]["width_m"], size) for k in pitches for i, size in reversals([r[k] for r in mine])
                 if size > PITCH_REVERSAL_DEG]
    return {"rpm": big_rpm, "pitch": big_pitch}


def chart_quality(payload: dict) -> dict:
    """The targets' figures of one finished chart (chart.json's payload)."""
    rows = [r for r in payload["rows"] if r["cv_percent"] is not None]
    ratio_ok = [r for r in rows if r["cv_p90_percent"] <= P90_RATIO * r["cv_percent"]]
    capped = [r for r in rows if r["cv_percent"] <= NOMINAL_OK_PERCENT]
    over_cap = [(r["fertilizer"], r["width_m"]) for r in capped if r["cv_p90_percent"] > P90_CAP_PERCENT]
    steady = {f: row_reversals(payload["rows"], f) for f in dict.fromkeys(r["fertilizer"] for r in payload["rows"])}
    return {"cells": len(payload["rows"]), "p90_within_ratio_share": len(ratio_ok) / max(1, len(rows)),
            "nominal_ok_cells": len(capped), "p90_over_cap": over_cap,
            "mean_cv_percent": sum(r["cv_percent"] for r in rows) / max(1, len(rows)),
            "mean_cv_p90_percent": sum(r["cv_p90_percent"] for r in rows) / max(1, len(rows)),
            "rpm_reversals": sum(len(s["rpm"]) for s in steady.values()),
            "pitch_reversals": sum(len(s["pitch"]) for s in steady.values()), "reversals": steady}


QUALITY_CHARTS = (  # as measured in docs/charts.md (small); the full charts are 3:6:0.5 and 4:12:1
    ("paper", "3:6:1", "cmaes", None),
    ("field", "4:12:4", "cmaes", None),
    ("paper", "3:6:1", "policy", None),  # the policy shipped for the paper scene (configs/policies/paper/)
)
QUALITY_OPTIONS = dict(fertilizers="all", budget=48, granules=1024)


def chart_quality_rows(charts=QUALITY_CHARTS, options: Optional[dict] = None, workers: Optional[int] = None,
                       progress: Optional[Callable[[str], None]] = None) -> list[dict]:
    """One row per (scene, widths, method, policy) of `charts`: the chart run into a fresh
    folder on the embedded Ray, its wall time and `chart_quality`."""
    from spreadgym.agents.chart.runner import chart

    rows = []
    for scene, widths, method, policy in charts:
        with tempfile.TemporaryDirectory() as folder:
            started = time.perf_counter()
            result = chart(scene, out=Path(folder) / "chart", widths=widths, method=method, policy=policy,
                           workers=workers, progress=False, **{**QUALITY_OPTIONS, **(options or {})})
            wall = time.perf_counter() - started
        quality = chart_quality(result.payload)
        rows.append({"scene": scene, "widths": widths, "method": method, "wall_s": wall,
                     **{k: v for k, v in quality.items() if k != "reversals"}})
        if progress:
            progress(f"chart-quality: {scene} {widths} {method}: p90 within {P90_RATIO}x on "
                     f"{quality['p90_within_ratio_share']:.0%}, {quality['rpm_reversals']} rpm and "
                     f"{quality['pitch_reversals']} pitch reversals, {wall:.0f} s")
    return rows
