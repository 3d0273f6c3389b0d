"""Whether a chart is one an operator can follow and trust (issue 31's targets), read off
finished charts, and the `make bench` entry that runs them.

* Robust: the share of cells whose verified p90 CV is at most the larger of `P90_RATIO`
  times their verified nominal CV and the nominal plus `P90_MARGIN_PP` (issue 45: at
  nominal CVs of 1-2 % real batches move a cell by 1-2 pp, so a ratio alone cannot hold),
  and the cells whose nominal CV is at most `NOMINAL_OK_PERCENT` but whose p90 exceeds
  `P90_CAP_PERCENT`.
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
P90_MARGIN_PP = 2.0
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


def over_target(key: str, size: float, value: float) -> bool:
    """Whether a reversal of `size` in setting `key` (turning at `value`) is over the
    targets' size: RPM_REVERSAL of the disc speed there, PITCH_REVERSAL_DEG in a pitch."""
    return size > (RPM_REVERSAL * value if key == "rpm" else PITCH_REVERSAL_DEG)


def row_reversals(rows: list[dict], fertilizer: str) -> dict:
    """The rpm and pitch reversals over the targets' sizes along one fertilizer's row."""
    mine = sorted((r for r in rows if r["fertilizer"] == fertilizer), key=lambda r: r["width_m"])
    rpm = [r["rpm"] for r in mine]
    pitches = [k for k in (mine[0] if mine else {}) if k.endswith("pitch_deg")]
    big_rpm = [(mine[i]["width_m"], size / rpm[i]) for i, size in reversals(rpm) if over_target("rpm", size, rpm[i])]
    big_pitch = [(mine[i]["width_m"], size) for k in pitches for i, size in reversals([r[k] for r in mine])
                 if over_target(k, size, mine[i][k])]
    return {"rpm": big_rpm, "pitch": big_pitch}


def p90_within_target(cv_percent: float, p90_percent: float) -> bool:
    """The robustness target: p90 <= max(P90_RATIO x nominal, nominal + P90_MARGIN_PP)."""
    return p90_percent <= max(P90_RATIO * cv_percent, cv_percent + P90_MARGIN_PP)


def chart_quality(payload: dict) -> dict:
    """The targets' figures of one finished chart (chart.json's payload)."""
    rows = [r for r in payload["rows"] if r["cv_percent"] is not None]
    ratio_ok = [r for r in rows if p90_within_target(r["cv_percent"], r["cv_p90_percent"])]
    capped = [r for r in rows if r["cv_percent"] <= NOMINAL_OK_PERCENT]
    over_cap = [(r["fertilizer"], r["width_m"]) for r in capped if r["cv_p90_percent"] > P90_CAP_PERCENT]
    steady = {f: row_reversals(payload["rows"], f) for f in dict.fromkeys(r["fertilizer"] for r in payload["rows"])}
    return {"cells": len(payload["rows"]), "p90_within_target_share": len(ratio_ok) / max(1, len(rows)),
            "nominal_ok_cells": len(capped), "p90_over_cap": over_cap,
            "mean_cv_percent": sum(r["cv_percent"] for r in rows) / max(1, len(rows)),
            "mean_cv_p90_percent": sum(r["cv_p90_percent"] for r in rows) / max(1, len(rows)),
            "rpm_reversals": sum(len(s["rpm"]) for s in steady.values()),
            "pitch_reversals": sum(len(s["pitch"]) for s in steady.values()), "reversals": steady}


def search_pick_rows(payload: dict) -> list[dict]:
    """The chart's rows as the chain left them, before the row sweep: each cell at its search pick, with
    that point's settings and verified figures (the row's own where the sweep kept the pick, else the
    `sweep.search_pick_verified` recorded when it moved the cell)."""
    from spreadgym.agents.chart.spec import Cell, ChartSpec

    spec = ChartSpec.from_manifest(payload["spec"])
    out = []
    for row, cell in zip(payload["rows"], payload["cells"]):
        block = cell["sweep"] or {}
        if not block.get("moved"):
            out.append(dict(row))
            continue
        space = spec.space(spec.cell_scene(Cell(row["fertilizer"], row["width_m"])))
        out.append({**row, **space.values(cell["search_unit_settings"]), **block["search_pick_verified"]})
    return out


def _paired(after: list[float], before: list[float]) -> dict:
    """Mean paired difference after - before, its standard error over the cells and its range."""
    import numpy as np

    d = np.subtract(after, before)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else None
    return {"mean": float(d.mean()), "standard_error": se, "min": float(d.min()), "max": float(d.max())}


def sweep_effect(payload: dict) -> dict:
    """What the row sweep and its repair did to a finished chart: the cells it moved, the reversals over the
    targets' sizes before (at the search picks) and after, the repair's candidates (scored, tied) and
    simulations, and the paired cost in verified nominal CV and p90 (after - before, percentage points,
    over every cell and over the moved ones)."""
    before_rows = search_pick_rows(payload)
    before = chart_quality({**payload, "rows": before_rows})
    after = chart_quality(payload)
    moved = [i for i, c in enumerate(payload["cells"]) if (c["sweep"] or {}).get("moved")]
    rows = payload["rows"]
    out = {"cells": len(rows), "moved": [(rows[i]["fertilizer"], rows[i]["width_m"]) for i in moved],
           "rpm_reversals": (before["rpm_reversals"], after["rpm_reversals"]),
           "pitch_reversals": (before["pitch_reversals"], after["pitch_reversals"]),
           "mean_cv_percent": (before["mean_cv_percent"], after["mean_cv_percent"]),
           "mean_cv_p90_percent": (before["mean_cv_p90_percent"], after["mean_cv_p90_percent"]),
           "reversals": (before["reversals"], after["reversals"])}
    repairs = [(c["sweep"] or {}).get("repair") or {} for c in payload["cells"]]
    out["repair"] = {"candidates": sum(len(r.get("candidates", [])) for r in repairs),
                     "tied": sum(c["tied"] for r in repairs for c in r.get("candidates", [])),
                     "simulations": sum(r.get("simulations", 0) for r in repairs)}
    for key in ("cv_percent", "cv_p90_percent"):
        out[f"{key}_cost"] = _paired([r[key] for r in rows], [r[key] for r in before_rows])
        if moved:
            out[f"{key}_cost_moved"] = _paired([rows[i][key] for i in moved], [before_rows[i][key] for i in moved])
    return out


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
            progress(f"chart-quality: {scene} {widths} {method}: p90 within max({P90_RATIO}x, +{P90_MARGIN_PP:g} pp) "
                     f"on {quality['p90_within_target_share']:.0%}, {quality['rpm_reversals']} rpm and "
                     f"{quality['pitch_reversals']} pitch reversals, {wall:.0f} s")
    return rows
