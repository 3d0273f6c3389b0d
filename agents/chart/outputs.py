"""What a finished chart writes: chart.csv, chart.json, chart.md (laid out like a printed
spreading chart), chart.png, chart.html (the one page an operator prints) and one
pattern picture per cell (cells/<key>.png)."""

from __future__ import annotations

import csv
import html
import io
import json
import math
from pathlib import Path
from types import SimpleNamespace
from typing import Optional

import numpy as np

from spreadgym.agents.chart.spec import Cell, ChartSpec
from spreadgym.agents.chart.store import CHART_FILES, HEAD, TAIL, ChartStore, json_text
from spreadgym.agents.chart.sweep import reversal_prices
from spreadgym.out_folder import write_atomic
from spreadgym.report import machine_lines, setting_lines, stamp

REVERSAL_MARK = "↕"  # a cell where a setting turns by more than the steady-rows target allows (quality.py)


def columns(rows: list[dict]) -> list[str]:
    """The CSV columns: cell, the settings (units in their names), the results."""
    settings = [k for k in rows[0] if k not in HEAD and k not in TAIL] if rows else []
    return HEAD + settings + TAIL


def widest_widths(spec: ChartSpec, rows: list[dict]) -> dict[str, Optional[float]]:
    """Per fertilizer, the widest width whose verified CV meets the scene's threshold."""
    threshold = spec.base_scene().pattern.cv_threshold_percent
    out: dict[str, Optional[float]] = {}
    for fertilizer in spec.fertilizers:
        ok = [r["width_m"] for r in rows if r["fertilizer"] == fertilizer
              and r["cv_percent"] is not None and r["cv_percent"] <= threshold]
        out[fertilizer] = max(ok) if ok else None
    return out


def chart_payload(spec: ChartSpec, records: list[dict], notes: list[str]) -> dict:
    rows = [r["row"] for r in records]
    return {"scene": spec.scene["name"], "spec": spec.manifest(), "columns": columns(rows), "rows": rows,
            "cv_threshold_percent": spec.base_scene().pattern.cv_threshold_percent,
            "widest_width_m": widest_widths(spec, rows),
            "cells": [{"fertilizer": r["row"]["fertilizer"], "width_m": r["row"]["width_m"],
                       **{k: v for k, v in r["detail"].items() if k not in ("trays", "cv_curve")}} for r in records],
            "reversals": reversal_prices(spec, records), "notes": notes}


def fixed_settings(spec: ChartSpec) -> list[tuple[str, str]]:
    """The settings the chart keeps at the scene's values (label, value): every dialled setting
    (`report.setting_lines`) that no chart axis sets, the width and driving aside (the rows and the title)."""
    scene = spec.base_scene()
    searched = {a.key for a in spec.space(scene).axes}
    return [(label, value) for key, label, value in setting_lines(scene)
            if key.rsplit(".", 1)[0] not in searched and key not in searched
            and key not in ("pattern.target_swath_m", "pattern.driving")]


def record_lines(spec: ChartSpec) -> list[tuple[str, str]]:
    """What a printed chart says about its machine, its fixed settings and its making (label, text)."""
    fixed = "; ".join(f"{label} {value}" for label, value in fixed_settings(spec)) or "none"
    return machine_lines(spec.base_scene()) + [("fixed settings", fixed), ("made by", stamp())]


def reversal_text(spec: ChartSpec, reversal: dict) -> str:
    """One remaining reversal in words: where, which settings turn and how, and its price."""
    turns = "; ".join(f"{_heading(name).split(' (')[0]} " + " → ".join(_dial({name: v}, name) for v in values)
                      + f" {_heading(name).split(' (')[1][:-1]}"
                      for name, values in zip(reversal["settings"], reversal["values"]))
    aim = f"p{quantile_text(spec)} CV" if spec.objective == "robust" else "CV"
    price = ("no scored setting removes it" if reversal["price_pp"] is None else
             f"a steady setting costs +{reversal['price_pp']:.2f} pp of the {aim} "
             f"(the cheapest scored one, at {reversal['priced_at_width_m']:g} m)")
    return f"{reversal['fertilizer']} {reversal['width_m']:g} m: {turns}; {price}"


def write_chart(store: ChartStore, records: list[dict], notes: list[str]) -> tuple[list[Path], dict]:
    """chart.csv, chart.json, chart.md and chart.png in the store's folder, each made in full
    before the first is written; (files, chart.json's payload)."""
    spec = store.spec
    payload = chart_payload(spec, records, notes)
    rows, cols = payload["rows"], payload["columns"]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=cols, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row.get(k) is None else row[k]) for k in cols})
    contents = (buffer.getvalue(), json_text(payload), markdown(spec, payload),
                chart_figure(spec, rows, payload["cv_threshold_percent"]), printable(spec, payload))
    return [write_atomic(store.out / name, content) for name, content in zip(CHART_FILES, contents)], payload


def _fmt(value, digits: int = 3) -> str:
    if value is None:
        return "-"
    return f"{value:.{digits}g}" if isinstance(value, float) else str(value)


def settings_text(row: dict, names: list[str]) -> str:
    parts = []
    for name in names:
        value = row[name]
        if name == "rpm":
            parts.append(f"{value:.0f} rpm")
        elif name.endswith("_deg"):
            parts.append(f"{name[:-4].replace('_', ' ')} {value:.1f}°")
        else:
            parts.append(f"{name.rsplit('_', 1)[0].replace('_', ' ')} {value:.3g} m")
    return ", ".join(parts)


def markdown(spec: ChartSpec, payload: dict) -> str:
    """Widths down, fertilizers across; each cell the settings and the verified CV ± SE."""
    rows, threshold = payload["rows"], payload["cv_threshold_percent"]
    names = [c for c in payload["columns"] if c not in HEAD and c not in TAIL]
    by_cell = {(r["fertilizer"], r["width_m"]): r for r in rows}
    turning = {(v["fertilizer"], v["width_m"]) for v in payload.get("reversals", [])}
    lines = [f"# Spreading chart: scene {spec.scene['name']}, {spec.driving} driving", "",
             *[f"- {label}: {text}" for label, text in record_lines(spec)], "",
             f"{method_text(spec)}, verified with the {spec.verify_model} model "
             f"({spec.verify_runs} runs of {spec.granules} granules pooled). CV at the working width "
             f"± its standard error, and p{quantile_text(spec)}: the CV {quantile_text(spec)} % of batches stay "
             f"under ({spec.variability['verify_draws']} batches of the variability model, one run each); "
             f"cells above the {threshold:g} % threshold are marked ✗.", "",
             "| width | " + " | ".join(spec.fertilizers) + " |",
             "|---|" + "---|" * len(spec.fertilizers)]
    for width in spec.widths_m:
        cells = []
        for fertilizer in spec.fertilizers:
            r = by_cell.get((fertilizer, width))
            if r is None:
                cells.append("-")
                continue
            cv = "no CV" if r["cv_percent"] is None else (
                f"CV {r['cv_percent']:.1f} ± {_fmt(r['cv_standard_error_percent'], 2)} %, "
                f"p{quantile_text(spec)} {r['cv_p90_percent']:.1f} %")
            mark = "" if r["cv_percent"] is not None and r["cv_percent"] <= threshold else " ✗"
            if (fertilizer, width) in turning:
                mark += f" {REVERSAL_MARK}"
            cells.append(f"{settings_text(r, names)}<br>{cv}{mark}")
        lines.append(f"| {width:g} m | " + " | ".join(cells) + " |")
    lines += ["", f"Widest width at CV ≤ {threshold:g} %: " + "; ".join(
        f"{f} {'none of these' if w is None else f'{w:g} m'}" for f, w in payload["widest_width_m"].items()) + "."]
    lines += reversal_lines(spec, payload)
    lines += [f"- {note}" for note in payload["notes"]]
    return "\n".join(lines) + "\n"


def reversal_lines(spec: ChartSpec, payload: dict) -> list[str]:
    """chart.md's account of the rows' remaining reversals (the steady-rows target's), each with its price."""
    found = payload.get("reversals", [])
    if not found:
        return ["", "Steady rows: no setting turns by more than 5 % of the disc speed or 3° of pitch between "
                    "neighbouring widths."]
    return ["", f"{REVERSAL_MARK} Settings that turn between neighbouring widths by more than 5 % of the disc "
                "speed or 3° of pitch (do not interpolate across these widths):", ""] + [
        f"- {reversal_text(spec, v)}" for v in found]


def quantile_text(spec: ChartSpec) -> str:
    return f"{100 * spec.variability['quantile']:g}"


def method_text(spec: ChartSpec, tie_sets: bool = True) -> str:
    """How the settings were found, in a sentence's words (`tie_sets` False: a chart made before steady rows, each
    cell searched on its own)."""
    aim = (f"the p{quantile_text(spec)} CV over {spec.variability['draws']} batches of the variability model"
           if spec.objective == "robust" else "the nominal CV")
    search = (f"CMA-ES on the {spec.search_model} model ({spec.budget} candidates of {spec.granules} granules "
              f"per cell, aiming at {aim})")
    if spec.method == "policy":
        return "Settings proposed by a trained policy (no search)"
    tolerance = ("" if spec.steady_tolerance_pp == 0.0 else
                 f" plus {spec.steady_tolerance_pp:g} pp (--steady-tolerance-pp)")
    prefer = ("the lowest disc speed, then the smallest change from the neighbouring widths"
              if spec.tie_preference == "lowest-rpm" else "the smallest change from the neighbouring widths")
    steady = (f"; steady rows: among the settings within two standard errors of each cell's best{tolerance}, "
              f"{prefer}" if tie_sets else "; each cell searched on its own (a chart made before steady rows)")
    if spec.method == "policy+search":
        return f"Settings found by {search}, started at a trained policy's proposal{steady}"
    return f"Settings found by {search}{steady}"


PRINT_CSS = """
body { font-family: Helvetica, Arial, sans-serif; margin: 1.2cm; color: #111; }
h1 { font-size: 16pt; margin: 0 0 4pt 0; }
h2 { font-size: 12pt; margin: 12pt 0 4pt 0; }
p { font-size: 8.5pt; margin: 2pt 0; }
table { border-collapse: collapse; width: 100%; font-size: 9.5pt; }
th, td { border: 1px solid #777; padding: 2pt 5pt; text-align: right; }
th { background: #e8e8e8; }
td.width, th.width { text-align: left; font-weight: bold; }
tr.over td { color: #a00; }
tr.turn td.width::after { content: " \\2195"; }
dl { font-size: 8.5pt; margin: 4pt 0; display: grid; grid-template-columns: max-content auto; gap: 0 8pt; }
dt { font-weight: bold; } dd { margin: 0; }
@page { size: A4 portrait; margin: 1cm; }
@media print { body { margin: 0; } h2 { break-after: avoid; } table { break-inside: avoid; } }
"""


def _dial(row: dict, name: str) -> str:
    value = row[name]
    if name == "rpm":
        return f"{value:.0f}"
    if name.endswith("_deg"):
        return f"{value:.1f}"
    return f"{1000 * value:.0f}" if name.endswith("_m") else f"{value:.3g}"


def _heading(name: str) -> str:
    """A setting's column or axis name in the chart's words: 'disc speed (rpm)', 'vane pitch (°)', 'feed radius
    (mm)'."""
    if name == "rpm":
        return "disc speed (rpm)"
    if name == "pitch_deg":
        return "vane pitch (°)"
    if name.endswith("_deg"):
        return f"{name[:-4].replace('_', ' ')} (°)"
    return f"{name[:-2].replace('_', ' ')} (mm)"


def printable(spec: ChartSpec, payload: dict) -> str:
    """chart.html: one printable page, a table per fertilizer, a row per width with the
    settings to dial and the expected CV band (nominal ± SE and the p90); no network."""
    rows, threshold = payload["rows"], payload["cv_threshold_percent"]
    names = [c for c in payload["columns"] if c not in HEAD and c not in TAIL]
    q = quantile_text(spec)
    esc = html.escape
    robust = all(r.get("cv_p90_percent") is not None for r in rows)  # a chart before robust cells has no p90
    parts = ["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">',
             f"<title>Spreading chart: {esc(spec.scene['name'])}</title><style>{PRINT_CSS}</style></head><body>",
             f"<h1>Spreading chart: {esc(spec.scene['name'])}, {esc(spec.driving)} driving</h1>",
             f"<p>{esc(method_text(spec, any(c.get('tie_set') for c in payload['cells'])))}. Expected CV at the "
             "working width: nominal ± standard error "
             f"({esc(spec.verify_model)} model, {spec.verify_runs} runs of {spec.granules} granules)"
             + (f", and the CV {q} % of batches stay under (p{q}: fertilizer friction, restitution, size and "
                "density, disc speed and vane pitch varied as the variability model says)" if robust else
                " (a chart made before robust cells: no p90)")
             + f". Rows in red exceed the {threshold:g} % threshold.</p>",
             "<dl>" + "".join(f"<dt>{esc(label)}</dt><dd>{esc(text)}</dd>" for label, text in record_lines(spec))
             + "</dl>"]
    turning = {(v["fertilizer"], v["width_m"]) for v in payload.get("reversals", [])}
    for fertilizer in spec.fertilizers:
        mine = sorted((r for r in rows if r["fertilizer"] == fertilizer), key=lambda r: r["width_m"])
        widest = payload["widest_width_m"].get(fertilizer)
        parts.append(f"<h2>{esc(fertilizer)}" + ("" if widest is None else f" (up to {widest:g} m)") + "</h2>")
        parts.append('<table><tr><th class="width">width (m)</th>'
                     + "".join(f"<th>{esc(_heading(n))}</th>" for n in names)
                     + "<th>CV (%)</th>" + (f"<th>p{q} CV (%)</th>" if robust else "") + "</tr>")
        for r in mine:
            cv = r["cv_percent"]
            over = cv is None or cv > threshold
            band = "-" if cv is None else f"{cv:.1f} ± {_fmt(r['cv_standard_error_percent'], 2)}"
            kinds = " ".join(k for k, on in (("over", over), ("turn", (fertilizer, r["width_m"]) in turning)) if on)
            tr = f'<tr class="{kinds}">' if kinds else "<tr>"
            parts.append(f'{tr}<td class="width">{r["width_m"]:g}</td>'
                         + "".join(f"<td>{_dial(r, n)}</td>" for n in names)
                         + f"<td>{band}</td>" + (f"<td>{r['cv_p90_percent']:.1f}</td>" if robust else "") + "</tr>")
        parts.append("</table>")
    parts += [f"<p>{esc(line)}</p>" for line in reversal_lines(spec, payload) if line]
    parts += [f"<p>{esc(note)}</p>" for note in payload["notes"]]
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def rewrite_printable(folder: Path) -> Path:
    """chart.html of a finished chart folder made again from its chart.json (a chart made before chart.html or its
    records existed: docs/charts/)."""
    payload = json.loads((Path(folder) / "chart.json").read_text(encoding="utf-8"))
    spec = ChartSpec.from_manifest(payload["spec"])
    records = [{"row": row, "detail": cell} for row, cell in zip(payload["rows"], payload["cells"])]
    payload = {**payload, "reversals": reversal_prices(spec, records)}
    return write_atomic(Path(folder) / "chart.html", printable(spec, payload))


def _figure(figsize):
    """A figure laid out by hand (constrained layout costs a second per picture)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=figsize, dpi=100)
    FigureCanvasAgg(fig)
    return fig


def chart_figure(spec: ChartSpec, rows: list[dict], threshold: float) -> bytes:
    """CV at width per fertilizer (± 2 SE), and each setting against width, as PNG bytes (`chart_axes`)."""
    fig = chart_axes(spec, rows, threshold)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def chart_axes(spec: ChartSpec, rows: list[dict], threshold: float):
    """chart.png's figure: its setting axes named in the chart's words ('disc speed (rpm)', 'vane pitch (°)')."""
    names = [c for c in columns(rows) if c not in HEAD and c not in TAIL]
    panels = 1 + len(names)
    ncols = min(3, panels)
    nrows = int(math.ceil(panels / ncols))
    fig = _figure((4.2 * ncols, 3.3 * nrows))
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.14 / nrows, top=1 - 0.2 / nrows, wspace=0.3, hspace=0.45)
    for fertilizer in spec.fertilizers:
        mine = sorted((r for r in rows if r["fertilizer"] == fertilizer), key=lambda r: r["width_m"])
        widths = np.array([r["width_m"] for r in mine])
        cv = np.array([np.nan if r["cv_percent"] is None else r["cv_percent"] for r in mine])
        se = np.array([np.nan if r["cv_standard_error_percent"] is None else r["cv_standard_error_percent"]
                       for r in mine])
        axes[0].errorbar(widths, cv, yerr=2.0 * se, marker="o", ms=4, capsize=3, label=fertilizer)
        for ax, name in zip(axes[1:], names):
            ax.plot(widths, [1000 * r[name] if name.endswith("_m") else r[name] for r in mine], marker="o", ms=4,
                    label=fertilizer)  # lengths in mm, as _heading names them
    axes[0].axhline(threshold, color="#c0392b", ls="--", lw=1, label=f"{threshold:g} % threshold")
    axes[0].set_ylabel("verified CV at width (%)")
    axes[0].set_title("CV at the working width (± 2 SE)")
    axes[0].legend(fontsize=7)
    for ax, name in zip(axes[1:], names):
        ax.set_ylabel(_heading(name))
        ax.set_title(_heading(name).split(" (")[0])
    for ax in axes[:panels]:
        ax.set_xlabel("working width (m)")
        ax.grid(True, color="#e5e5e5")
    for ax in axes[panels:]:
        ax.set_visible(False)
    fig.suptitle(f"Spreading chart: scene {spec.scene['name']}, {spec.driving}")
    return fig


def cell_picture(spec: ChartSpec, cell: Cell, record: dict) -> bytes:
    """The verified pattern of one cell as PNG bytes: single pass and overlapped, and CV
    against width. Drawn where the cell ran (a Ray worker), so the driver only writes it."""
    from spreadgym.spread.pattern import Trays
    from spreadgym.viz.plots import cv_vs_bout_width, transverse_pattern

    row, detail = record["row"], record["detail"]
    scene = spec.cell_scene(cell)
    trays = Trays(np.array(detail["trays"]["center_m"]), np.array(detail["trays"]["mass_kg"]),
                  scene.pattern.tray_width_m)
    curve = detail["cv_curve"]
    metrics = SimpleNamespace(
        cv_percent_at_target=row["cv_percent"], effective_swath_m=row["effective_swath_m"],
        cv_threshold_percent=scene.pattern.cv_threshold_percent, target_swath_m=cell.width_m, cv_ci_percent=None,
        curve_bout_width_m=curve["bout_width_m"],
        curve_cv_percent=[np.nan if v is None else v for v in curve["cv_percent"]])
    result = SimpleNamespace(trays=trays, scene=scene, metrics=metrics)
    fig = _figure((11.0, 3.8))
    left, right = fig.subplots(1, 2)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.13, top=0.84, wspace=0.18)
    transverse_pattern(left, result)
    cv_vs_bout_width(right, result)
    names = [k for k in row if k not in HEAD and k not in TAIL]
    fig.suptitle(f"{cell.fertilizer} at {cell.width_m:g} m: {settings_text(row, names)} "
                 f"({detail['verification']['model']}, {detail['verification']['granules']} granules)", fontsize=10)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    return buffer.getvalue()


def cell_figure(store: ChartStore, cell: Cell, record: dict, picture: Optional[bytes] = None) -> Path:
    """Write the cell's pattern picture (`picture`, or drawn here when not given)."""
    return write_atomic(store.cell_path(cell, ".png"), picture or cell_picture(store.spec, cell, record))
