"""A simulation's record worth printing (`spreadgym simulate --report FILE`): the scene, the machine, the
fertilizer, every setting, the CV at the working width with its standard error, the effective swath, the
pattern and the CV curve, the date and the version; HTML (one file, pictures inside, nothing loaded from the
network) or PDF (one A4 page), by the file's suffix."""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

from spreadgym.errors import SpreadgymError
from spreadgym.out_folder import folder_problem
from spreadgym.report import machine_lines, setting_lines, stamp, swath_text, with_error

REPORT_SUFFIXES = (".html", ".pdf")


def record_lines(scene, metrics: dict) -> list[tuple[str, str]]:
    """(label, text) of the record: the scene's machine, the fertilizer, every setting, the results, the run."""
    cv, se = metrics["cv_percent_at_target"], metrics["cv_standard_error_percent"]
    at = "nothing landed" if cv is None else with_error(cv, se, "%")
    lines = [*machine_lines(scene), ("fertilizer", scene.fertilizer_name)]
    lines += [(label, value) for _key, label, value in setting_lines(scene)]
    lines += [(f"CV at {metrics['target_swath_m']:g} m", at + f" ({metrics['driving']})"),
              ("effective swath", swath_text(metrics)),
              ("runs", f"{metrics['runs']} of {metrics['granules']} granules, {metrics['model']} model; standard "
                       f"error {metrics['precision_percent']:g} pp asked, "
                       + ("reached" if metrics["precision_met"] else "not reached")),
              ("made by", stamp())]
    return lines


def _figure(result):
    """The pattern and the CV curve side by side (the pictures of `simulate --plot`)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from spreadgym.viz.plots import cv_vs_bout_width, transverse_pattern

    fig = Figure(figsize=(8.3, 3.4), dpi=110)
    FigureCanvasAgg(fig)
    left, right = fig.subplots(1, 2)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.15, top=0.88, wspace=0.28)
    transverse_pattern(left, result, legend=True)
    cv_vs_bout_width(right, result)
    return fig


def report_html(scene, metrics: dict, result) -> str:
    """The record as one HTML page (print CSS; the picture inside as a data URI)."""
    buffer = io.BytesIO()
    _figure(result).savefig(buffer, format="png")
    picture = base64.b64encode(buffer.getvalue()).decode("ascii")
    rows = "".join(f"<tr><th>{html.escape(label)}</th><td>{html.escape(text)}</td></tr>"
                   for label, text in record_lines(scene, metrics))
    return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
            f"<title>spreadgym record: {html.escape(scene.name)}</title><style>"
            "body{font-family:Helvetica,Arial,sans-serif;margin:1.2cm;color:#111}"
            "table{border-collapse:collapse;font-size:10pt}th,td{border:1px solid #999;padding:2pt 6pt;"
            "text-align:left}th{background:#eee}img{max-width:100%}@page{size:A4;margin:1cm}"
            "@media print{body{margin:0}}</style></head><body>"
            f"<h1>Spread pattern: {html.escape(scene.name)}, {html.escape(scene.fertilizer_name)}</h1>"
            f"<table>{rows}</table><p><img alt=\"the pattern and the CV curve\" "
            f"src=\"data:image/png;base64,{picture}\"></p></body></html>\n")


def report_pdf(scene, metrics: dict, result) -> bytes:
    """The record as one A4 PDF page: the lines, then the pattern and the CV curve."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8.27, 11.69), dpi=100)
    FigureCanvasAgg(fig)
    fig.text(0.07, 0.95, f"Spread pattern: {scene.name}, {scene.fertilizer_name}", fontsize=15, weight="bold")
    y = 0.91
    for label, text in record_lines(scene, metrics):
        fig.text(0.07, y, label, fontsize=9.5, weight="bold")
        fig.text(0.30, y, text, fontsize=9.5, wrap=True)
        y -= 0.022
    left = fig.add_axes((0.09, 0.08, 0.38, y - 0.14))
    right = fig.add_axes((0.58, 0.08, 0.38, y - 0.14))
    from spreadgym.viz.plots import cv_vs_bout_width, transverse_pattern

    transverse_pattern(left, result, legend=True)
    cv_vs_bout_width(right, result)
    buffer = io.BytesIO()
    fig.savefig(buffer, format="pdf")
    return buffer.getvalue()


def check_report_path(path: Path, inputs: list[Path]) -> Path:
    """`--report FILE`: an .html or .pdf file in a folder that exists, not an input of the run."""
    if path.suffix.lower() not in REPORT_SUFFIXES:
        raise SpreadgymError(f"--report {path}: give a file ending in {' or '.join(REPORT_SUFFIXES)}")
    if not path.parent.resolve().is_dir():
        raise SpreadgymError(f"--report {path}: the folder {path.parent} does not exist")
    if path.is_dir():
        raise SpreadgymError(f"--report {path}: a folder, not a file")
    problem = folder_problem(path.parent)  # before the run: a report it cannot write would waste it
    if problem is not None:
        raise SpreadgymError(f"--report {path}: {problem}")
    if any(p.exists() and p.resolve() == path.resolve() for p in inputs):
        raise SpreadgymError(f"--report {path}: would replace an input of the run; give another file")
    return path


def write_report(path: Path, scene, metrics: dict, result) -> Path:
    """Write the record to `path` (HTML or PDF by its suffix), whole or not at all (a temporary file renamed)."""
    content = report_pdf(scene, metrics, result) if path.suffix.lower() == ".pdf" else \
        report_html(scene, metrics, result).encode("utf-8")
    partial = path.with_name(f".{path.name}.partial")
    partial.write_bytes(content)
    partial.replace(path)
    return path
